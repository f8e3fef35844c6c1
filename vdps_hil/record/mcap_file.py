"""The index of an MCAP file, and its chunks decoded into message tuples.

:class:`McapIndex` (the base of :class:`~vdps_hil.record.reader.RecordingReader`) builds, from
a file whose magic has been checked, the catalogue the reader merges from: schemas, channels,
per-channel message counts, the blocks to read (chunks, or message records outside chunks) and
the metadata records; ``_chunk_records`` decompresses one chunk into ``(MESSAGE, cid, seq,
log_t, pub_t, data)`` tuples.

Broken files. A file without a valid summary (cut off by a crash or a full disk, still being
written, or a summary failing its CRC) is scanned record by record: every complete chunk is read
(chunk CRCs checked), the first incomplete record ends the scan, and ``truncated`` /
``problems`` say so. A corrupt chunk inside an otherwise good file is skipped and noted in
``problems`` (by the reader, when it reads the block); everything around it is read.
"""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass
from typing import IO

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Metadata, Schema

__all__ = ["McapIndex", "Block", "ChannelInfo", "MAGIC", "one_line"]

MAGIC = b"\x89MCAP0\r\n"
_HDR = struct.Struct("<BQ")
_MSG = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time
_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary_start, summary_offset_start, crc


@dataclass(frozen=True)
class ChannelInfo:
    topic: str
    schema: str
    encoding: str
    metadata: dict


@dataclass(frozen=True)
class Block:
    """A unit of reading: a chunk record, or a message record outside chunks."""

    offset: int
    opcode: int
    channels: frozenset | None  # channel ids inside, None = unknown


def _body_stream(body: bytes) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(body))


def one_line(e: BaseException) -> str:
    """``Type: first line of the message`` of an exception."""
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


class McapIndex:
    """The catalogue of the MCAP file ``f`` (``size`` bytes, magic checked): from its summary,
    else by scanning it (module docstring). Attributes: ``truncated`` (no valid summary: read by
    scanning), ``problems`` (one-line notes about anything skipped)."""

    def __init__(self, f: IO[bytes], size: int):
        self._f, self._size = f, size
        self.problems: list[str] = []
        self.truncated = False
        self._schemas: dict[int, tuple[str, str]] = {}
        self._channels: dict[int, ChannelInfo] = {}
        self._counts: dict[int, int] = {}
        self._blocks: list[Block] = []
        self._metadata: list[tuple[str, dict]] = []
        self._dctx = zstandard.ZstdDecompressor()
        self._indexing = False
        if not self._load_summary():
            self.truncated = self._indexing = True
            try:
                self._scan()
            finally:
                self._indexing = False

    def _load_summary(self) -> bool:
        """Index from the summary section; False when there is no usable summary."""
        footer_pos = self._size - len(MAGIC) - _FOOTER.size
        if footer_pos < len(MAGIC):
            return False
        self._f.seek(footer_pos)
        tail = self._f.read(_FOOTER.size + len(MAGIC))
        if tail[-len(MAGIC):] != MAGIC:
            return False  # no closing magic: cut off, or still being written
        op, length, summary_start, _, summary_crc = _FOOTER.unpack(tail[:_FOOTER.size])
        if op != Opcode.FOOTER or length != _FOOTER.size - _HDR.size:
            self.problems.append("damaged footer: scanned the file")
            return False
        if not len(MAGIC) <= summary_start < footer_pos:
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
                self._blocks.append(Block(ci.chunk_start_offset, Opcode.CHUNK, chans))
            for mi in summary.metadata_indexes:
                rec = self._read_record_at(mi.offset)
                if rec is not None and rec[0] == Opcode.METADATA:
                    m = Metadata.read(_body_stream(rec[1]))
                    self._metadata.append((m.name, dict(m.metadata)))
        except Exception as e:  # noqa: BLE001 - inconsistent summary: fall back to a scan
            self.problems.append(f"summary unusable ({one_line(e)}); scanned the file")
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
        self._channels[ch.id] = ChannelInfo(ch.topic, name, ch.message_encoding,
                                             dict(ch.metadata))

    def _scan(self) -> None:
        """Index a file without summary by walking its records from the start."""
        pos = len(MAGIC)
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
                    self._blocks.append(Block(pos, op, frozenset(counts)))
                elif op in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA, Opcode.MESSAGE):
                    body = self._f.read(length)
                    if op == Opcode.MESSAGE:
                        cid = _MSG.unpack_from(body, 0)[0]
                        self._counts[cid] = self._counts.get(cid, 0) + 1
                        self._blocks.append(Block(pos, op, frozenset((cid,))))
                    else:
                        self._meta_record(op, body)
            except Exception as e:  # noqa: BLE001 - a damaged record: note it, keep scanning
                self.problems.append(f"record at byte {pos} (opcode 0x{op:02x}) unreadable, "
                                     f"skipped: {one_line(e)}")
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

    def _block_messages(self, block: Block, cids: set[int]) -> list[tuple]:
        """Message tuples (as ``_chunk_records``) of the channels ``cids`` in a block."""
        if block.opcode == Opcode.CHUNK:
            return self._chunk_records(block.offset, cids)
        rec = self._read_record_at(block.offset)
        if rec is None:
            raise ValueError(f"message record at byte {block.offset} incomplete")
        cid, seq, log_t, pub_t = _MSG.unpack_from(rec[1], 0)
        return [(Opcode.MESSAGE, cid, seq, log_t, pub_t, rec[1][22:])]

