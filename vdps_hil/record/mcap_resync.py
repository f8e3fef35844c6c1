"""Finding the records of a damaged MCAP file (``record.recover``): the length a record's own
fields imply, the summary's chunk index, and the scan for the next valid record.

An MCAP record is ``opcode (1 byte) | length (u64 LE) | body``. The body of almost every record
is self-delimiting: fixed fields, strings and maps prefixed by a u32 byte count, chunk records
and attachment data by a u64 (MCAP specification, "Records")::

    record          body layout                                        implied body length
    Header          profile str, library str                           (4+a) + (4+b)
    Schema          id u16, name str, encoding str, data u32-bytes     2 + (4+a) + (4+b) + (4+c)
    Channel         id, schema_id u16, topic, encoding str, map        4 + (4+a) + (4+b) + (4+c)
    Chunk           3 x u64, crc u32, compression str, records u64     28 + (4+a) + (8+b)
    MessageIndex    channel_id u16, entries u32-bytes                  2 + (4+a)
    ChunkIndex      4 x u64, offsets map, u64, compression str, 2 x u64 32 + (4+a) + 8 + (4+b) + 16
    Attachment      2 x u64, name, media_type str, data u64, crc u32   16 + (4+a) + (4+b) + (8+c) + 4
    Metadata        name str, map                                      (4+a) + (4+b)
    DataEnd         crc u32                                            4
    (Message        channel u16, seq u32, 2 x u64, data to the end     -- not self-delimiting)

So a record whose length field was corrupted is recognised (announced != implied) and, when
the record after the implied end is plausible, read with the implied length: nothing is lost.
When the summary at the end of the file is intact (footer, summary CRC), its chunk index gives
every chunk's start and length. Otherwise a damaged spot is skipped by scanning forward for the
next *valid* record: a known opcode whose announced and implied lengths agree, that fits in
the file and is followed by a plausible record (or the end of the file); a random position
passes that with a probability of about 2^-48 (the top bytes of the length must be zero).
"""

from __future__ import annotations

import bisect
import io
import re
import struct
import zlib
from dataclasses import dataclass, field

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, ChunkIndex, Schema

__all__ = ["HEAD", "OPCODES", "RecordFinder", "Summary", "implied_length", "read_summary"]

HEAD = struct.Struct("<BQ")
OPCODES = frozenset(int(o) for o in Opcode)
_U32, _U64 = struct.Struct("<I"), struct.Struct("<Q")
_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary_start, summary_offset_start, crc
_MAGIC_LEN = 8

# body layouts (module docstring): a fixed byte count, "s" = u32-prefixed, "S" = u64-prefixed
_LAYOUT: dict[int, tuple] = {
    Opcode.HEADER: ("s", "s"), Opcode.FOOTER: (20,), Opcode.SCHEMA: (2, "s", "s", "s"),
    Opcode.CHANNEL: (4, "s", "s", "s"), Opcode.CHUNK: (28, "s", "S"),
    Opcode.MESSAGE_INDEX: (2, "s"), Opcode.CHUNK_INDEX: (32, "s", 8, "s", 16),
    Opcode.ATTACHMENT: (16, "s", "s", "S", 4), Opcode.ATTACHMENT_INDEX: (40, "s", "s"),
    Opcode.STATISTICS: (42, "s"), Opcode.METADATA: ("s", "s"), Opcode.METADATA_INDEX: (16, "s"),
    Opcode.SUMMARY_OFFSET: (17,), Opcode.DATA_END: (4,),
}

_RESYNC = (Opcode.CHUNK, Opcode.MESSAGE_INDEX, Opcode.METADATA, Opcode.ATTACHMENT, Opcode.SCHEMA,
           Opcode.CHANNEL, Opcode.DATA_END)
"""Records a scan may resynchronise on (data-section records that are self-delimiting)."""
_CANDIDATE = re.compile(b"[" + b"".join(re.escape(bytes([int(o)])) for o in _RESYNC) + b"]")


def implied_length(buf, body: int, end: int, op: int) -> int | None:
    """The body length the fields of the record of opcode ``op`` whose body starts at ``body``
    imply (module docstring), or None (a Message or unknown record, or fields past ``end``)."""
    layout = _LAYOUT.get(op)
    if layout is None:
        return None
    p = body
    for item in layout:
        if item == "s":
            if p + 4 > end:
                return None
            p += 4 + _U32.unpack_from(buf, p)[0]
        elif item == "S":
            if p + 8 > end:
                return None
            p += 8 + _U64.unpack_from(buf, p)[0]
        else:
            p += item
        if p > end:
            return None
    return p - body


@dataclass
class Summary:
    """What an intact summary section holds: chunk ``start -> length`` (chunk index), and the
    schemas and channels by id."""

    chunks: dict[int, int] = field(default_factory=dict)
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)


def read_summary(buf, size: int) -> Summary | None:
    """The summary of a file whose footer and summary CRC are intact, else None."""
    at = size - _MAGIC_LEN - _FOOTER.size
    if at < _MAGIC_LEN:
        return None
    op, length, start, _, crc = _FOOTER.unpack_from(buf, at)
    if op != Opcode.FOOTER or length != 20 or not _MAGIC_LEN <= start < at:
        return None
    if crc and zlib.crc32(buf[start:at + _FOOTER.size - 4]) != crc:
        return None
    out = Summary()
    p = start
    try:
        while p + HEAD.size <= at:
            rop, n = HEAD.unpack_from(buf, p)
            if p + HEAD.size + n > at:
                return None
            stream = ReadDataStream(io.BytesIO(buf[p + HEAD.size:p + HEAD.size + n]))
            if rop == Opcode.CHUNK_INDEX:
                ci = ChunkIndex.read(stream)
                out.chunks[ci.chunk_start_offset] = ci.chunk_length
            elif rop == Opcode.SCHEMA:
                s = Schema.read(stream)
                out.schemas[s.id] = s
            elif rop == Opcode.CHANNEL:
                c = Channel.read(stream)
                out.channels[c.id] = c
            p += HEAD.size + n
    except Exception:  # noqa: BLE001 - a summary that does not parse is not used
        return None
    return out


class RecordFinder:
    """Where the records of ``buf`` (``size`` bytes) are, despite damage (module docstring)."""

    def __init__(self, buf, size: int, summary: Summary | None):
        self.buf, self.size, self.summary = buf, size, summary
        self._starts = sorted(summary.chunks) if summary else []

    def header(self, p: int) -> tuple[int, int] | None:
        return HEAD.unpack_from(self.buf, p) if p + HEAD.size <= self.size else None

    def _consistent(self, p: int) -> int | None:
        """The length of a record at ``p`` whose announced and implied lengths agree and that
        fits in the file, else None."""
        h = self.header(p)
        if h is None or h[0] not in OPCODES:
            return None
        op, n = h
        if p + HEAD.size + n > self.size:
            return None
        imp = implied_length(self.buf, p + HEAD.size, self.size, op)
        return n if imp is None or imp == n else None

    def plausible(self, p: int) -> bool:
        """``p`` is the end of the file or the start of a consistent record other than a
        Message (whose length nothing checks: inside message indexes, small little-endian
        integers often look like one)."""
        if p == self.size:
            return True
        return self._consistent(p) is not None and self.buf[p] != Opcode.MESSAGE

    def length(self, p: int) -> int | None:
        """The body length to trust for the record at ``p``, or None (damaged or cut): the
        chunk index's for a chunk it lists; the announced one when it agrees with the fields (or
        the record is a Message, which has none to check, and fits); else the implied one when
        a plausible record follows it (only the length field was wrong); else the announced one
        when it is longer than the fields and a plausible record follows (fields a newer MCAP
        adds)."""
        op, n = self.header(p)
        body = p + HEAD.size
        if self.summary is not None and op == Opcode.CHUNK and p in self.summary.chunks:
            n_idx = self.summary.chunks[p] - HEAD.size
            if body + n_idx <= self.size and self.plausible(body + n_idx):
                return n_idx
        if op not in OPCODES:
            return None
        imp = implied_length(self.buf, body, self.size, op)
        fits = body + n <= self.size
        if fits and (imp == n or imp is None):
            return n
        if imp is not None and self.plausible(body + imp):
            return imp
        if fits and imp is not None and imp < n and self.plausible(body + n):
            return n
        return None

    def resync(self, p: int) -> int | None:
        """The first valid record after ``p`` (module docstring), or the next chunk of the
        chunk index, whichever comes first; None when nothing valid follows."""
        limit = self.size
        i = bisect.bisect_right(self._starts, p)
        if i < len(self._starts):
            limit = self._starts[i]
        for m in _CANDIDATE.finditer(self.buf, p + 1, limit):
            q = m.start()
            n = self._consistent(q)
            if n is not None and self.plausible(q + HEAD.size + n):
                return q
        return limit if limit < self.size else None
