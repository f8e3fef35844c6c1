"""Tests of vdps_hil.record.mcap_resync: implied record lengths on every record type of real
files (ours and the mcap library's), the summary reader, and resynchronisation."""

from __future__ import annotations

import struct

import pytest
from mcap.writer import Writer

from vdps_hil.record.mcap_resync import HEAD, RecordFinder, implied_length, read_summary
from vdps_hil.bus.samples import Sample
from vdps_hil.record.writer import RecordingWriter


def _all_records(data: bytes):
    """Every top-level record (offset, opcode, length) of an intact file, summary included."""
    out, p = [], 8
    while p + 9 <= len(data) - 8:
        op, n = HEAD.unpack_from(data, p)
        out.append((p, op, n))
        p += 9 + n
    assert p == len(data) - 8
    return out


@pytest.fixture(scope="module")
def library_file(tmp_path_factory):
    """A file of the mcap library with every record kind: chunked and unchunked messages,
    attachments, metadata, statistics, indexes, summary offsets."""
    p = tmp_path_factory.mktemp("lib") / "all.mcap"
    with open(p, "wb") as f:
        w = Writer(f, chunk_size=200)
        w.start("prof", "lib")
        sid = w.register_schema("s", "jsonschema", b"{}")
        cid = w.register_channel("/t", "json", sid, {"k": "v"})
        for i in range(50):
            w.add_message(cid, i, b'{"i": %d}' % i, i)
        w.add_attachment(1, 2, "a.bin", "application/octet-stream", b"\x00" * 33)
        w.add_metadata("m", {"a": "b"})
        w.finish()
    return p.read_bytes()


def test_implied_length_equals_the_announced_one_on_every_record(library_file, tmp_path):
    with RecordingWriter(tmp_path / "ours.mcap", metadata={"x": "y"}) as w:
        for i in range(300):
            w.write_sample(Sample(t_ns=i, source="imu", kind="imu", fields={"a": 1.0}, wall_time_ns=i))
    for data in (library_file, (tmp_path / "ours.mcap").read_bytes()):
        recs = _all_records(data)
        assert len({op for _, op, _ in recs}) >= 8
        for p, op, n in recs:
            imp = implied_length(data, p + 9, len(data), op)
            assert imp == (None if op == 0x05 else n), (p, op)


def test_the_summary_is_read_when_intact_and_refused_when_its_crc_fails(library_file):
    s = read_summary(library_file, len(library_file))
    assert s is not None and len(s.chunks) >= 3 and s.channels[1].topic == "/t" and 1 in s.schemas
    for start, length in s.chunks.items():
        assert library_file[start] == 0x06 and HEAD.unpack_from(library_file, start)[1] + 9 == length
    bad = bytearray(library_file)
    first = min(p for p, op, _ in _all_records(library_file) if op == 0x08)  # a chunk index
    bad[first + 20] ^= 0xFF
    assert read_summary(bytes(bad), len(bad)) is None
    assert read_summary(library_file[:-30], len(library_file) - 30) is None  # no footer


def test_a_length_field_alone_is_corrected_from_the_fields(library_file):
    chunks = [p for p, op, _ in _all_records(library_file) if op == 0x06]
    b = bytearray(library_file)
    true_n = HEAD.unpack_from(b, chunks[1])[1]
    struct.pack_into("<Q", b, chunks[1] + 1, 3)
    assert RecordFinder(bytes(b), len(b), None).length(chunks[1]) == true_n
    assert RecordFinder(bytes(b), len(b), read_summary(bytes(b), len(b))).length(chunks[1]) == true_n


def test_resync_finds_the_next_valid_record_after_a_destroyed_one(library_file):
    recs = _all_records(library_file)
    chunks = [p for p, op, _ in recs if op == 0x06]
    b = bytearray(library_file)
    b[chunks[1]:chunks[1] + 60] = b"\x06" * 60  # header and fields: opcodes, none consistent
    rf = RecordFinder(bytes(b), len(b), None)
    assert rf.length(chunks[1]) is None
    nxt = rf.resync(chunks[1])
    assert nxt == min(p for p, _, _ in recs if p > chunks[1])  # the chunk's message index
    end = [p for p, op, _ in recs if op == 0x0F][0]
    assert RecordFinder(bytes(b[:end - 3]), end - 3, None).resync(end - 40) is None  # a cut
