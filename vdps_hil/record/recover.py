"""Rescue a recording cut off by a crash, a ``kill -9`` or a full disk, or damaged in the
middle (``vdps recover``).

An MCAP file is a sequence of records ``opcode (1 byte) | length (8 bytes, LE) | body``. A
logger that dies leaves a file without its summary and footer, usually ending inside a record.
:func:`recover` walks the records from the start and copies every *complete* one into a new,
properly closed file:

* the length of each record is checked against the lengths its own fields imply and, when the
  file's summary is intact (footer and summary CRC), against the summary's chunk index
  (``record.mcap_resync``): a record whose length field alone is corrupted is read whole with
  its true length; a record that cannot be delimited at all is skipped, and the scan
  resynchronises on the next valid record (or the next chunk of the index), so one damaged spot
  loses at most the record it hit;
* a record whose body runs past the end of the file, with nothing valid after it, ends the scan
  (the cut);
* a chunk (compressed block of messages) is copied message by message when it decompresses
  and its CRC-32 matches; a damaged chunk is skipped and counted, and the scan goes on after
  it, so data after a damaged spot is not lost;
* schemas and channels are re-registered (our writer repeats them in every chunk, so every
  complete chunk is self-describing; an intact summary supplies those of a lost part),
  messages keep their ``log_time``, ``publish_time`` and sequence; metadata records and
  attachments are copied;
* the data section ends at the ``DataEnd`` record: a file that was closed properly is simply
  rewritten.

What is lost: the chunk that was being written when the process died (the logger closes a chunk
every ``flush_s``, 0.5 s, so at most about the last half second of data), and the records a
damaged spot actually hit.

The new file gets a metadata record ``vdps.recover`` with what was done (bytes scanned, where
the cut was, messages per topic, damaged chunks, whether the summary was used, and each
resynchronisation: the bad record's offset, where the scan resumed, the bytes skipped).
"""

from __future__ import annotations

import io
import json
import mmap
import os
import struct
import zlib
from typing import IO

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (Attachment, Channel, Chunk, Header, Message, Metadata, Schema)
from mcap.writer import CompressionType, IndexType, Writer

from vdps_hil.record.mcap_resync import RecordFinder, read_summary

__all__ = ["recover", "RecoverError", "RECOVER_METADATA"]

MAGIC = b"\x89MCAP0\r\n"
RECOVER_METADATA = "vdps.recover"
_HEAD = struct.Struct("<BQ")


class RecoverError(Exception):
    """The input cannot be recovered at all (not MCAP, unreadable): one line."""


def _one_line(e: BaseException) -> str:
    s = str(e).splitlines()[0] if str(e) else ""
    return f"{type(e).__name__}: {s}" if s else type(e).__name__


class _Copier:
    def __init__(self, out: Writer):
        self.out = out
        self.schemas: dict[int, int] = {}
        self.schema_keys: dict[tuple, int] = {}
        self.channels: dict[int, int] = {}
        self.channel_topic: dict[int, str] = {}
        self.pending_channels: dict[int, Channel] = {}
        self.messages_by_topic: dict[str, int] = {}
        self.orphans = 0
        self.last_t_ns: dict[str, int] = {}
        self.summary = None  # record.mcap_resync.Summary of an intact summary section, or None

    def schema(self, s: Schema) -> None:
        if s.id in self.schemas:
            return
        key = (s.name, s.encoding, bytes(s.data))
        sid = self.schema_keys.get(key)
        if sid is None:
            sid = self.out.register_schema(s.name, s.encoding, bytes(s.data))
            self.schema_keys[key] = sid
        self.schemas[s.id] = sid
        for cid in [c for c, ch in self.pending_channels.items() if ch.schema_id == s.id]:
            self.channel(self.pending_channels.pop(cid))

    def channel(self, c: Channel) -> None:
        if c.id in self.channels:
            return
        if c.schema_id != 0 and c.schema_id not in self.schemas:
            self.pending_channels[c.id] = c
            return
        sid = self.schemas.get(c.schema_id, 0)
        self.channels[c.id] = self.out.register_channel(c.topic, c.message_encoding, sid,
                                                        dict(c.metadata))
        self.channel_topic[c.id] = c.topic

    def message(self, m: Message) -> None:
        cid = self.channels.get(m.channel_id)
        if cid is None and self.summary is not None and m.channel_id in self.summary.channels:
            ch = self.summary.channels[m.channel_id]  # its channel record was in a lost part
            if ch.schema_id in self.summary.schemas:
                self.schema(self.summary.schemas[ch.schema_id])
            self.channel(ch)
            cid = self.channels.get(m.channel_id)
        if cid is None:
            self.orphans += 1  # its channel record was in a lost part (and no summary has it)
            return
        self.out.add_message(cid, m.log_time, bytes(m.data), m.publish_time, m.sequence)
        topic = self.channel_topic[m.channel_id]
        self.messages_by_topic[topic] = self.messages_by_topic.get(topic, 0) + 1
        if m.publish_time > self.last_t_ns.get(topic, -1):
            self.last_t_ns[topic] = m.publish_time


def _chunk_records(chunk: Chunk) -> list:
    if chunk.compression == "zstd":
        data = zstandard.ZstdDecompressor().decompress(chunk.data,
                                                       max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "":
        data = bytes(chunk.data)
    elif chunk.compression == "lz4":
        import lz4.frame  # optional; only files written with lz4 need it

        data = lz4.frame.decompress(chunk.data)
    else:
        raise ValueError(f"unknown chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise ValueError("chunk size mismatch")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ValueError("chunk CRC mismatch")
    out = []
    stream = ReadDataStream(io.BytesIO(data))
    n = len(data)
    while stream.count < n:
        if n - stream.count < _HEAD.size:
            raise ValueError("chunk ends inside a record header")
        op = stream.read1()
        length = stream.read8()
        start = stream.count
        if start + length > n:
            raise ValueError("chunk record runs past the chunk")
        if op == Opcode.SCHEMA:
            out.append(Schema.read(stream))
        elif op == Opcode.CHANNEL:
            out.append(Channel.read(stream))
        elif op == Opcode.MESSAGE:
            out.append(Message.read(stream, length))
        pad = length - (stream.count - start)
        if pad > 0:
            stream.read(pad)
    return out


def recover(src: str | os.PathLike | IO[bytes], dst: str | os.PathLike) -> dict:
    """Copy every complete record of ``src`` into a new closed MCAP ``dst``; returns a report.
    Raises RecoverError (one line) when ``src`` is not an MCAP file at all."""
    f, owns, name = _open_source(src)
    try:
        size = _size_of(f)
        if f.read(len(MAGIC)) != MAGIC:
            raise RecoverError(f"{name} is not an MCAP recording (bad magic)")
        if os.path.abspath(os.fspath(dst)) == os.path.abspath(name):
            raise RecoverError("output must be a new file, not the broken one")
        try:
            out_f = open(dst, "wb")
        except OSError as e:
            raise RecoverError(f"cannot write {dst}: {e.strerror or e}") from None
        report = {"input": name, "input_bytes": size, "complete_bytes": len(MAGIC),
                  "chunks_ok": 0, "chunks_damaged": 0, "damaged": [], "metadata_records": 0,
                  "attachments": 0, "properly_closed": False, "stop": "",
                  "summary_used": False, "resynchronised": []}
        with out_f:
            w = Writer(out_f, compression=CompressionType.ZSTD, index_types=IndexType.ALL,
                       repeat_channels=True, repeat_schemas=True, use_chunking=True,
                       use_statistics=True, use_summary_offsets=True, enable_crcs=True)
            cp = _Copier(w)
            if not _copy_records(f, size, w, cp, report):
                w.start(profile="", library="vdps-hil recover")
            _finish(w, cp, report)
        return report
    finally:
        if owns:
            f.close()


def _open_source(src: str | os.PathLike | IO[bytes]) -> tuple[IO[bytes], bool, str]:
    """(file, whether we opened it, its name)."""
    if hasattr(src, "read"):
        return src, False, getattr(src, "name", "<stream>")
    name = os.fspath(src)
    try:
        return open(name, "rb"), True, name
    except OSError as e:
        raise RecoverError(f"cannot open {name}: {e.strerror or e}") from None


def _size_of(f: IO[bytes]) -> int | None:
    try:
        return os.fstat(f.fileno()).st_size if hasattr(f, "fileno") else None
    except (OSError, io.UnsupportedOperation):
        return None


def _load(f: IO[bytes], size: int | None):
    """The file's bytes (after its checked magic was read) as a buffer, memory-mapped when it
    is a real file, and their count."""
    if size:
        try:
            return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ), size
        except (OSError, ValueError, io.UnsupportedOperation, AttributeError):
            pass
    try:
        f.seek(0)
        data = f.read()
    except (OSError, io.UnsupportedOperation):  # a pipe: the magic was read already
        data = MAGIC + f.read()
    return data, len(data)


def _copy_records(f: IO[bytes], size: int | None, w: Writer, cp: _Copier, report: dict) -> bool:
    """Walk the records after the magic until the end of the data section or the cut, copying
    each complete one (``report`` updated) and resynchronising after a damaged one
    (``record.mcap_resync``); returns whether the output writer was started."""
    buf, size = _load(f, size)
    try:
        summary = read_summary(buf, size)
        report["summary_used"] = summary is not None
        cp.summary = summary
        return _walk(RecordFinder(buf, size, summary), w, cp, report)
    finally:
        if isinstance(buf, mmap.mmap):
            buf.close()


def _walk(rf: RecordFinder, w: Writer, cp: _Copier, report: dict) -> bool:
    started = False
    offset = len(MAGIC)
    while True:
        head = rf.header(offset)
        if head is None:
            report["stop"] = ("end of file" if offset >= rf.size else
                              f"cut inside a record header at byte {offset}")
            break
        op, _ = head
        length = rf.length(offset)
        if length is None:
            nxt = rf.resync(offset)
            if nxt is None:
                report["stop"] = f"cut inside a record (opcode {op}) at byte {offset}"
                break
            report["resynchronised"].append({"bad_record_at": offset, "opcode": op,
                                             "resumed_at": nxt, "skipped_bytes": nxt - offset})
            offset = nxt
            continue
        body = bytes(rf.buf[offset + _HEAD.size:offset + _HEAD.size + length])
        rec_offset = offset
        offset += _HEAD.size + length
        if op == Opcode.HEADER and not started:
            try:
                h = Header.read(ReadDataStream(io.BytesIO(body)))
                w.start(profile=h.profile, library=f"vdps-hil recover ({h.library})")
            except Exception:  # noqa: BLE001
                w.start(profile="", library="vdps-hil recover")
            started = True
            report["complete_bytes"] = offset
            continue
        if not started:
            w.start(profile="", library="vdps-hil recover")
            started = True
        if op == Opcode.DATA_END or op == Opcode.FOOTER:
            report["properly_closed"] = True
            report["stop"] = "end of data section"
            report["complete_bytes"] = offset
            break
        _copy_record(op, body, length, rec_offset, w, cp, report)
        report["complete_bytes"] = offset
    return started


def _copy_record(op: int, body: bytes, length: int, rec_offset: int, w: Writer, cp: _Copier,
                 report: dict) -> None:
    """One complete record of the data section into the output; a damaged one is skipped and
    noted in ``report``."""
    try:
        stream = ReadDataStream(io.BytesIO(body))
        if op == Opcode.CHUNK:
            try:
                records = _chunk_records(Chunk.read(stream))
            except Exception as e:  # noqa: BLE001 - damaged chunk: skip it
                report["chunks_damaged"] += 1
                if len(report["damaged"]) < 20:
                    report["damaged"].append(f"chunk at byte {rec_offset}: "
                                             f"{_one_line(e)}")
                return
            for r in records:
                if isinstance(r, Schema):
                    cp.schema(r)
                elif isinstance(r, Channel):
                    cp.channel(r)
                else:
                    cp.message(r)
            report["chunks_ok"] += 1
        elif op == Opcode.SCHEMA:
            cp.schema(Schema.read(stream))
        elif op == Opcode.CHANNEL:
            cp.channel(Channel.read(stream))
        elif op == Opcode.MESSAGE:
            cp.message(Message.read(stream, length))
        elif op == Opcode.METADATA:
            md = Metadata.read(stream)
            w.add_metadata(md.name, dict(md.metadata))
            report["metadata_records"] += 1
        elif op == Opcode.ATTACHMENT:
            a = Attachment.read(stream)
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type,
                             bytes(a.data))
            report["attachments"] += 1
        # message indexes, chunk indexes and the like are rebuilt by the writer
    except Exception as e:  # noqa: BLE001 - a damaged record: skip it
        if len(report["damaged"]) < 20:
            report["damaged"].append(f"record {op} at byte {rec_offset}: "
                                     f"{_one_line(e)}")


def _finish(w: Writer, cp: _Copier, report: dict) -> None:
    """The report's totals, the ``vdps.recover`` metadata record, the summary and footer."""
    report["messages"] = sum(cp.messages_by_topic.values())
    report["topics"] = dict(sorted(cp.messages_by_topic.items()))
    report["last_t_ns"] = dict(sorted(cp.last_t_ns.items()))
    report["orphan_messages"] = cp.orphans
    w.add_metadata(RECOVER_METADATA, {k: v if isinstance(v, str) else json.dumps(v)
                                      for k, v in report.items()})
    w.finish()
