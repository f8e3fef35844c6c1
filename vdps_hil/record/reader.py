"""MCAP recording reader: messages in ``t_ns`` order across topics, raw CAN as python-can
messages, raw serial chunks, bus samples, metadata; broken files read as far as they go.

Ordering. MCAP's own readers order by ``log_time`` (wall clock), which is not the
measurement time: wall clocks step, and a live logger stamps wall time at arrival. We order
by ``publish_time = t_ns`` instead, with a k-way merge over channels: within one topic the
writer appends in non-decreasing ``t_ns``, so the next message overall is the smallest head
among the channels. The file is read once, chunk by chunk in file order; a message is
emitted as soon as every selected channel that still has unread messages (per-channel counts
from the statistics record, or from the scan of a truncated file) has one buffered, so memory
stays bounded by how far apart the channels were written. Ties go to file order.

Broken files. A file that is not MCAP (bad magic, empty, unreadable) raises
:class:`RecordingError` with one line. A file without a valid summary (cut off by a crash or
a full disk, still being written, or a summary failing its CRC) is scanned record by record:
every complete chunk is read (chunk CRCs checked), the first incomplete record ends the scan,
and ``reader.truncated`` / ``reader.problems`` say so. A corrupt chunk inside an otherwise good file is skipped and noted in ``problems``;
everything around it is read.

Keeping the estimator off ground truth: select topics by prefix, e.g.
``iter_messages(prefixes=("/raw/",))`` never touches ``/truth/`` chunks.
"""

from __future__ import annotations

import base64
import heapq
import io
import json
import os
import struct
import zlib
from collections import deque
from dataclasses import dataclass
from typing import IO, Iterable, Iterator, NamedTuple

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Metadata, Schema

from vdps_hil.record import schemas as S

__all__ = ["RecordingError", "RecordingReader", "TopicInfo", "RawRecord"]

_MAGIC = b"\x89MCAP0\r\n"
_HDR = struct.Struct("<BQ")
_MSG = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time
_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary_start, summary_offset_start, crc


class RecordingError(Exception):
    """A recording that cannot be read at all (one-line message)."""


class TopicInfo(NamedTuple):
    schema: str
    count: int


class RawRecord(NamedTuple):
    """One message as stored: topic, ``t_ns`` (publish_time), ``log_time_ns``, per-channel
    ``sequence`` and the encoded JSON bytes."""

    topic: str
    t_ns: int
    log_time_ns: int
    sequence: int
    data: bytes


@dataclass(frozen=True)
class _ChannelInfo:
    topic: str
    schema: str
    encoding: str
    metadata: dict


@dataclass(frozen=True)
class _Block:
    """A unit of reading: a chunk record, or a message record outside chunks."""

    offset: int
    opcode: int
    channels: frozenset | None  # channel ids inside, None = unknown


def _body_stream(body: bytes) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(body))


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


class RecordingReader:
    """Read a recording written by :class:`~vdps_hil.record.writer.RecordingWriter` (or any
    MCAP with JSON channels).

    Attributes: ``truncated`` (no valid summary: read by scanning), ``problems`` (one-line
    notes about anything skipped), ``rejected`` (messages that could not be decoded).
    """

    def __init__(self, path: str | os.PathLike | IO[bytes]):
        self.problems: list[str] = []
        self.rejected = 0
        self.truncated = False
        if hasattr(path, "read"):
            self._f, self._owns = path, False
            self.path = getattr(path, "name", "<stream>")
        else:
            self.path = os.fspath(path)
            try:
                self._f, self._owns = open(self.path, "rb"), True
            except OSError as e:
                raise RecordingError(f"cannot open {self.path}: {e.strerror or e}") from None
        try:
            self._f.seek(0, io.SEEK_END)
            self._size = self._f.tell()
            self._f.seek(0)
            magic = self._f.read(len(_MAGIC))
        except OSError as e:
            self.close()
            raise RecordingError(f"cannot read {self.path}: {e.strerror or e}") from None
        if magic != _MAGIC:
            self.close()
            what = "empty file" if self._size == 0 else "bad magic"
            raise RecordingError(f"{self.path} is not an MCAP recording ({what})")
        self._schemas: dict[int, tuple[str, str]] = {}
        self._channels: dict[int, _ChannelInfo] = {}
        self._counts: dict[int, int] = {}
        self._blocks: list[_Block] = []
        self._metadata: list[tuple[str, dict]] = []
        self._dctx = zstandard.ZstdDecompressor()
        self._indexing = False
        if not self._load_summary():
            self.truncated = self._indexing = True
            try:
                self._scan()
            finally:
                self._indexing = False

    # --- index ----------------------------------------------------------------------------------

    def _load_summary(self) -> bool:
        """Index from the summary section; False when there is no usable summary."""
        footer_pos = self._size - len(_MAGIC) - _FOOTER.size
        if footer_pos < len(_MAGIC):
            return False
        self._f.seek(footer_pos)
        tail = self._f.read(_FOOTER.size + len(_MAGIC))
        if tail[-len(_MAGIC):] != _MAGIC:
            return False  # no closing magic: cut off, or still being written
        op, length, summary_start, _, summary_crc = _FOOTER.unpack(tail[:_FOOTER.size])
        if op != Opcode.FOOTER or length != _FOOTER.size - _HDR.size:
            self.problems.append("damaged footer: scanned the file")
            return False
        if not len(_MAGIC) <= summary_start < footer_pos:
            return False  # no summary section (or a damaged pointer to it)
        if summary_crc:
            self._f.seek(summary_start)
            covered = self._f.read(footer_pos + _FOOTER.size - 4 - summary_start)
            if zlib.crc32(covered) != summary_crc:
                self.problems.append("summary CRC mismatch: scanned the file instead")
                return False
        try:
            self._f.seek(0)
            summary = SeekingReader(self._f).get_summary()
        except Exception:  # noqa: BLE001 - any failure means: no usable summary, scan instead
            return False
        if summary is None or summary.statistics is None:
            return False
        stats = summary.statistics
        if stats.message_count and not summary.chunk_indexes:
            return False  # messages outside chunks: only a scan finds them
        try:
            for sid, sc in summary.schemas.items():
                self._schemas[sid] = (sc.name, sc.encoding)
            for cid, ch in summary.channels.items():
                self._add_channel(ch)
            self._counts = {int(k): int(v) for k, v in stats.channel_message_counts.items()}
            for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
                chans = frozenset(ci.message_index_offsets) or None
                self._blocks.append(_Block(ci.chunk_start_offset, Opcode.CHUNK, chans))
            for mi in summary.metadata_indexes:
                rec = self._read_record_at(mi.offset)
                if rec is not None and rec[0] == Opcode.METADATA:
                    m = Metadata.read(_body_stream(rec[1]))
                    self._metadata.append((m.name, dict(m.metadata)))
        except Exception as e:  # noqa: BLE001 - inconsistent summary: fall back to a scan
            self.problems.append(f"summary unusable ({_one_line(e)}); scanned the file")
            self._schemas.clear(), self._channels.clear(), self._counts.clear()
            self._blocks.clear(), self._metadata.clear()
            return False
        return True

    def _read_record_at(self, offset: int) -> tuple[int, bytes] | None:
        """(opcode, body) of the record at ``offset``; None when the file ends inside it."""
        self._f.seek(offset)
        head = self._f.read(_HDR.size)
        if len(head) < _HDR.size:
            return None
        op, length = _HDR.unpack(head)
        if offset + _HDR.size + length > self._size:
            return None
        body = self._f.read(length)
        return (op, body) if len(body) == length else None

    def _add_channel(self, ch: Channel) -> None:
        name = self._schemas.get(ch.schema_id, ("", ""))[0]
        self._channels[ch.id] = _ChannelInfo(ch.topic, name, ch.message_encoding,
                                             dict(ch.metadata))

    def _scan(self) -> None:
        """Index a file without summary by walking its records from the start."""
        pos = len(_MAGIC)
        while True:
            if pos + _HDR.size > self._size:
                self.problems.append(f"file ends at byte {self._size} without a footer "
                                     "(truncated): read every complete record before it")
                return
            self._f.seek(pos)
            op, length = _HDR.unpack(self._f.read(_HDR.size))
            end = pos + _HDR.size + length
            if end > self._size:
                self.problems.append(f"file ends inside a record (opcode 0x{op:02x}) at byte "
                                     f"{pos} (truncated): read every complete record before it")
                return
            if op in (Opcode.DATA_END, Opcode.FOOTER):
                self.problems.append("summary or footer missing or damaged: scanned the data "
                                     "section, which is complete")
                return
            try:
                if op == Opcode.CHUNK:
                    counts: dict[int, int] = {}
                    for rec in self._chunk_records(pos):
                        if rec[0] == Opcode.MESSAGE:
                            counts[rec[1]] = counts.get(rec[1], 0) + 1
                    for cid, n in counts.items():
                        self._counts[cid] = self._counts.get(cid, 0) + n
                    self._blocks.append(_Block(pos, op, frozenset(counts)))
                elif op in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA, Opcode.MESSAGE):
                    body = self._f.read(length)
                    if op == Opcode.MESSAGE:
                        cid = _MSG.unpack_from(body, 0)[0]
                        self._counts[cid] = self._counts.get(cid, 0) + 1
                        self._blocks.append(_Block(pos, op, frozenset((cid,))))
                    else:
                        self._meta_record(op, body)
            except Exception as e:  # noqa: BLE001 - a damaged record: note it, keep scanning
                self.problems.append(f"record at byte {pos} (opcode 0x{op:02x}) unreadable, "
                                     f"skipped: {_one_line(e)}")
            pos = end

    def _meta_record(self, op: int, body: bytes) -> None:
        if op == Opcode.SCHEMA:
            sc = Schema.read(_body_stream(body))
            self._schemas[sc.id] = (sc.name, sc.encoding)
        elif op == Opcode.CHANNEL:
            self._add_channel(Channel.read(_body_stream(body)))
        elif op == Opcode.METADATA:
            m = Metadata.read(_body_stream(body))
            self._metadata.append((m.name, dict(m.metadata)))

    def _chunk_records(self, offset: int, cids: set[int] | None = None) -> list[tuple]:
        """Records inside the chunk at ``offset``: ``(MESSAGE, cid, seq, log_t, pub_t, data)``
        tuples of the channels ``cids`` (None: all); schema and channel records are indexed on
        the way (scan mode)."""
        rec = self._read_record_at(offset)
        if rec is None or rec[0] != Opcode.CHUNK:
            raise ValueError(f"no chunk record at byte {offset}")
        chunk = Chunk.read(_body_stream(rec[1]))
        if chunk.compression == "zstd":
            data = self._dctx.decompress(chunk.data, max_output_size=chunk.uncompressed_size)
        elif chunk.compression == "":
            data = chunk.data
        elif chunk.compression == "lz4":
            try:
                import lz4.frame  # optional; our writer never uses lz4
            except ImportError:
                raise ValueError("lz4-compressed chunk and the lz4 package is missing") \
                    from None
            data = lz4.frame.decompress(chunk.data)
        else:
            raise ValueError(f"unknown chunk compression {chunk.compression!r}")
        if len(data) != chunk.uncompressed_size:
            raise ValueError(f"chunk size {len(data)} != {chunk.uncompressed_size}")
        if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
            raise ValueError("chunk CRC mismatch")
        out = []
        pos, n = 0, len(data)
        unpack_hdr, unpack_msg = _HDR.unpack_from, _MSG.unpack_from
        while pos < n:
            op, length = unpack_hdr(data, pos)
            body = pos + 9
            end = body + length
            if end > n:
                raise ValueError("record overruns its chunk")
            if op == Opcode.MESSAGE:
                cid, seq, log_t, pub_t = unpack_msg(data, body)
                if cids is None or cid in cids:
                    out.append((op, cid, seq, log_t, pub_t, data[body + 22:end]))
            elif op in (Opcode.SCHEMA, Opcode.CHANNEL) and self._indexing:
                self._meta_record(op, data[body:end])
            pos = end
        return out

    def _block_messages(self, block: _Block, cids: set[int]) -> list[tuple]:
        """Message tuples (as ``_chunk_records``) of the channels ``cids`` in a block."""
        if block.opcode == Opcode.CHUNK:
            return self._chunk_records(block.offset, cids)
        rec = self._read_record_at(block.offset)
        if rec is None:
            raise ValueError(f"message record at byte {block.offset} incomplete")
        cid, seq, log_t, pub_t = _MSG.unpack_from(rec[1], 0)
        return [(Opcode.MESSAGE, cid, seq, log_t, pub_t, rec[1][22:])]

    # --- catalogue ------------------------------------------------------------------------------

    def topics(self) -> dict[str, TopicInfo]:
        """Topic -> (schema name, message count), sorted by topic."""
        out: dict[str, TopicInfo] = {}
        for cid, ch in self._channels.items():
            n = self._counts.get(cid, 0)
            old = out.get(ch.topic)
            out[ch.topic] = TopicInfo(ch.schema, n) if old is None else \
                TopicInfo(old.schema, old.count + n)
        return dict(sorted(out.items()))

    def channel_metadata(self, topic: str) -> dict[str, str]:
        for ch in self._channels.values():
            if ch.topic == topic:
                return dict(ch.metadata)
        raise KeyError(f"no topic {topic!r} in {self.path}")

    def serial_config(self, device: str) -> tuple[int | None, str]:
        """(baud, format) of a raw serial device from its channel metadata."""
        md = self.channel_metadata(S.RAW_SERIAL_PREFIX + device)
        baud = md.get("baud", "")
        return (int(baud) if baud.isdigit() else None), md.get("format", "")

    def metadata(self) -> dict[str, dict[str, str]]:
        """MCAP metadata records: name -> key/value strings (records of the same name merged,
        later ones winning). ``metadata()["vdps.recording"]`` is the provenance record."""
        out: dict[str, dict[str, str]] = {}
        for name, md in self._metadata:
            out.setdefault(name, {}).update(md)
        return out

    @property
    def layout_version(self) -> str | None:
        return self.metadata().get(S.METADATA_NAME, {}).get("layout_version")

    # --- iteration ------------------------------------------------------------------------------

    def _select(self, topics: Iterable[str] | str | None,
                prefixes: Iterable[str] | str | None, schema: str | None = None) -> set[int]:
        if isinstance(topics, str):
            topics = (topics,)
        if isinstance(prefixes, str):
            prefixes = (prefixes,)
        topics = None if topics is None else set(topics)
        prefixes = None if prefixes is None else tuple(prefixes)
        out = set()
        for cid, ch in self._channels.items():
            if schema is not None and ch.schema != schema:
                continue
            if topics is None and prefixes is None:
                out.add(cid)
            elif (topics is not None and ch.topic in topics) or \
                    (prefixes is not None and ch.topic.startswith(prefixes)):
                out.add(cid)
        return out

    def _merged(self, cids: set[int]) -> Iterator[tuple[int, int, int, int, bytes]]:
        """(cid, t_ns, log_time, seq, data) of the selected channels in t_ns order."""
        if not cids:
            return
        unread = {c: self._counts.get(c, 0) for c in cids}
        bufs: dict[int, deque] = {c: deque() for c in cids}
        blocking = sum(1 for c in cids if unread[c] > 0)
        heap: list[tuple[int, int, int]] = []
        order = 0
        for block in self._blocks:
            if block.channels is not None and block.channels.isdisjoint(cids):
                continue
            try:
                records = self._block_messages(block, cids)
            except Exception as e:  # noqa: BLE001 - damaged block: note it, read the rest
                note = f"block at byte {block.offset} unreadable, skipped: {_one_line(e)}"
                if note not in self.problems:  # once per file, not once per pass
                    self.problems.append(note)
                continue
            for _, cid, seq, log_t, pub_t, data in records:
                buf = bufs.get(cid)
                if buf is None:
                    continue
                if not buf:
                    heapq.heappush(heap, (pub_t, order, cid))
                    if unread[cid] > 0:
                        blocking -= 1
                buf.append((pub_t, order, log_t, seq, data))
                unread[cid] -= 1
                order += 1
            while blocking == 0 and heap:
                _, _, c = heapq.heappop(heap)
                buf = bufs[c]
                pub_t, _, log_t, seq, data = buf.popleft()
                if buf:
                    heapq.heappush(heap, (buf[0][0], buf[0][1], c))
                elif unread[c] > 0:
                    blocking += 1
                yield c, pub_t, log_t, seq, data
        while heap:  # counts were short (damaged blocks): drain what is buffered, in order
            _, _, c = heapq.heappop(heap)
            buf = bufs[c]
            pub_t, _, log_t, seq, data = buf.popleft()
            if buf:
                heapq.heappush(heap, (buf[0][0], buf[0][1], c))
            yield c, pub_t, log_t, seq, data

    def iter_records(self, topics: Iterable[str] | str | None = None, *,
                     prefixes: Iterable[str] | str | None = None) -> Iterator[RawRecord]:
        """Undecoded messages in ``t_ns`` order (see :meth:`iter_messages` for selection)."""
        chans = self._channels
        for cid, t_ns, log_t, seq, data in self._merged(self._select(topics, prefixes)):
            yield RawRecord(chans[cid].topic, t_ns, log_t, seq, data)

    def iter_messages(self, topics: Iterable[str] | str | None = None, *,
                      prefixes: Iterable[str] | str | None = None
                      ) -> Iterator[tuple[str, int, dict]]:
        """``(topic, t_ns, doc)`` in ``t_ns`` order across the selected topics.

        A topic is selected when it is in ``topics`` or starts with one of ``prefixes``; with
        neither, every topic. JSON ``null`` stays ``None`` here. Undecodable messages are
        skipped and counted in ``rejected``.
        """
        chans = self._channels
        loads = json.loads
        for cid, t_ns, _, _, data in self._merged(self._select(topics, prefixes)):
            try:
                doc = loads(data)
            except ValueError as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield chans[cid].topic, t_ns, doc

    def _reject(self, topic: str, t_ns: int, e: BaseException) -> None:
        self.rejected += 1
        if self.rejected <= 20:
            self.problems.append(f"{topic} t_ns={t_ns}: undecodable message skipped "
                                 f"({_one_line(e)})")

    def iter_raw_can(self, bus: str | Iterable[str] | None = None):
        """``(bus, can.Message)`` of ``/raw/can/...`` in ``t_ns`` order; ``timestamp`` is
        ``t_ns / 1e9`` (seconds), ``channel`` the bus name, ``is_rx`` from ``direction``."""
        import can

        topics = None if bus is None else \
            [S.RAW_CAN_PREFIX + b for b in ((bus,) if isinstance(bus, str) else bus)]
        cids = self._select(topics, None if topics else (S.RAW_CAN_PREFIX,), S.RAW_CAN)
        chans = self._channels
        for cid, t_ns, _, _, data in self._merged(cids):
            name = chans[cid].topic[len(S.RAW_CAN_PREFIX):]
            try:
                d = json.loads(data)
                fd = d["is_fd"]
                msg = can.Message(timestamp=t_ns / 1e9, arbitration_id=d["arbitration_id"],
                                  is_extended_id=d["is_extended_id"],
                                  is_remote_frame=d["is_remote_frame"],
                                  is_error_frame=d["is_error_frame"], channel=name,
                                  dlc=d["dlc"], data=bytes.fromhex(d["data_hex"]),
                                  is_fd=fd, is_rx=d["direction"] != "tx",
                                  bitrate_switch=fd and d.get("bitrate_switch", False),
                                  error_state_indicator=fd and d.get("error_state_indicator",
                                                                     False),
                                  check=False)
            except (ValueError, KeyError, TypeError) as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield name, msg

    def iter_raw_serial(self, device: str | Iterable[str] | None = None
                        ) -> Iterator[tuple[str, int, bytes]]:
        """``(device, t_ns, bytes)`` of ``/raw/serial/...`` in ``t_ns`` order."""
        topics = None if device is None else \
            [S.RAW_SERIAL_PREFIX + d for d in ((device,) if isinstance(device, str) else device)]
        cids = self._select(topics, None if topics else (S.RAW_SERIAL_PREFIX,), S.RAW_SERIAL)
        chans = self._channels
        for cid, t_ns, _, _, data in self._merged(cids):
            try:
                raw = base64.b64decode(json.loads(data)["data_b64"], validate=True)
            except (ValueError, KeyError, TypeError) as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield chans[cid].topic[len(S.RAW_SERIAL_PREFIX):], t_ns, raw

    def iter_samples(self, prefixes: Iterable[str] | str = (S.DECODED_PREFIX,)):
        """Bus :class:`~vdps_hil.bus.samples.Sample` objects (``vdps.Sample.v1`` channels
        under ``prefixes``, ``/decoded/`` by default) in ``t_ns`` order; null fields -> NaN."""
        from vdps_hil.bus.samples import Sample

        chans = self._channels
        for cid, t_ns, _, _, data in self._merged(self._select(None, prefixes, S.SAMPLE)):
            try:
                sample = Sample.from_json(json.loads(data))
            except (ValueError, KeyError, TypeError) as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield sample

    # --- lifecycle ------------------------------------------------------------------------------

    def close(self) -> None:
        if self._owns and not self._f.closed:
            self._f.close()

    def __enter__(self) -> "RecordingReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
