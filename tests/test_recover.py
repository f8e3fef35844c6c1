"""Recovery of cut and damaged recordings: every complete chunk rescued, nothing invented."""

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.bus.samples import Sample
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.recover import RecoverError, recover
from vdps_hil.record.writer import RecordingWriter


def write_file(path, n=2000, flush_every=100):
    """n samples with seq_counter 0..n-1; the chunk is closed every ``flush_every``."""
    with RecordingWriter(path, metadata={"mode": "test"}) as w:
        for i in range(n):
            w.write_sample(Sample(t_ns=i * 1_000_000, source="imu", kind="imu",
                                  fields={"seq_counter": float(i)}, wall_time_ns=1 + i))
            if i % flush_every == flush_every - 1:
                w.flush()
    return path.read_bytes()


def seqs(path):
    with RecordingReader(path) as r:
        assert not r.truncated
        return [int(s.fields["seq_counter"]) for s in r.iter_samples()]


def test_intact_file_is_rewritten_unchanged(tmp_path):
    write_file(tmp_path / "a.mcap")
    rep = recover(tmp_path / "a.mcap", tmp_path / "b.mcap")
    assert rep["properly_closed"] and rep["messages"] == 2000
    assert seqs(tmp_path / "b.mcap") == list(range(2000))
    with RecordingReader(tmp_path / "b.mcap") as r:
        md = r.metadata()
        assert md["vdps.recording"]["mode"] == "test"
        assert "vdps.recover" in md


@pytest.fixture(scope="module")
def full_file(tmp_path_factory):
    """One closed file and the byte range of each chunk (from its own summary)."""
    from mcap.reader import make_reader

    p = tmp_path_factory.mktemp("full") / "full.mcap"
    data = write_file(p, 1000, 100)
    with open(p, "rb") as f:
        summary = make_reader(f).get_summary()
    ends = sorted(ci.chunk_start_offset + ci.chunk_length for ci in summary.chunk_indexes)

    class Full(tuple):
        def __repr__(self):
            return f"<{len(self[0])} bytes, {len(self[1])} chunks>"

    return Full((data, ends))


@settings(max_examples=25, deadline=None)
@given(st.floats(0.02, 0.999))
def test_cut_anywhere_rescues_every_complete_chunk(tmp_path_factory, full_file, frac):
    data, chunk_ends = full_file
    d = tmp_path_factory.mktemp("cut")
    n_cut = int(len(data) * frac)
    cut = d / "cut.mcap"
    cut.write_bytes(data[:n_cut])
    rep = recover(cut, d / "fixed.mcap")
    got = seqs(d / "fixed.mcap")
    complete = sum(1 for e in chunk_ends if e <= n_cut)
    assert got == list(range(100 * complete))  # every complete chunk, in order, no more
    with RecordingReader(cut) as r:  # the reader's own scan of the cut file agrees
        assert [int(s.fields["seq_counter"]) for s in r.iter_samples()] == got
    if n_cut < chunk_ends[-1]:
        assert not rep["properly_closed"]
        assert rep["stop"].startswith("cut") or rep["stop"] == "end of file"


def test_damaged_chunk_in_the_middle_is_skipped_and_the_rest_kept(tmp_path):
    data = bytearray(write_file(tmp_path / "full.mcap"))
    k = len(data) // 2
    data[k:k + 30] = b"\x55" * 30
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data[: int(len(data) * 0.9)]))
    rep = recover(bad, tmp_path / "fixed.mcap")
    got = seqs(tmp_path / "fixed.mcap")
    assert rep["chunks_damaged"] >= 1
    assert 0 in got and max(got) > 1000  # before and after the damage
    assert len(got) >= 2000 * 0.9 - 2 * 100 - 200


def test_not_mcap_is_one_line(tmp_path):
    p = tmp_path / "x.mcap"
    p.write_bytes(b"hello world")
    with pytest.raises(RecoverError) as e:
        recover(p, tmp_path / "y.mcap")
    assert "not an MCAP" in str(e.value)
    with pytest.raises(RecoverError, match="new file"):
        write_file(tmp_path / "z.mcap", 10)
        recover(tmp_path / "z.mcap", tmp_path / "z.mcap")


# ------------------------------------------------------------- a corrupted record length field
def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of every top-level record of an intact file, up to DataEnd."""
    out, p = [], 8
    while p + 9 <= len(data):
        op, n = struct.unpack_from("<BQ", data, p)
        out.append((p, op, n))
        if op == 0x0F:  # DataEnd
            break
        p += 9 + n
    return out


@pytest.fixture(scope="module")
def many_chunks(tmp_path_factory):
    """2000 samples in 40 chunks (each record: a chunk and its message index), closed."""
    p = tmp_path_factory.mktemp("len") / "full.mcap"
    data = write_file(p, 2000, 50)
    recs = _records(data)
    assert sum(op == 0x06 for _, op, _ in recs) == 40
    return data, recs


def _recover_bytes(tmp_path, data: bytes) -> tuple[dict, list[int]]:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(data)
    rep = recover(bad, tmp_path / "fixed.mcap")
    return rep, seqs(tmp_path / "fixed.mcap")


def _assert_kept(got: list[int], n: int = 2000, share: float = 0.99) -> None:
    assert got == sorted(set(got)) and set(got) <= set(range(n))  # in order, nothing invented
    assert len(got) >= share * n, f"kept {len(got)} of {n}"


@pytest.mark.parametrize("summary", [True, False], ids=["with summary", "cut before the summary"])
@pytest.mark.parametrize("value", [1 << 40, 17, 5000, 0], ids=["past the end", "tiny", "inside", "zero"])
@pytest.mark.parametrize("which", ["chunk", "message index"])
def test_one_corrupted_length_field_keeps_every_record(tmp_path, many_chunks, summary, value, which):
    """The length field of one record in the middle is overwritten: the record is still read
    (its fields imply its length; the chunk index has it) and everything after it is kept."""
    data, recs = many_chunks
    op_wanted = 0x06 if which == "chunk" else 0x07
    off = [o for o, op, _ in recs if op == op_wanted][20]
    b = bytearray(data)
    struct.pack_into("<Q", b, off + 1, value)
    if not summary:
        b = b[:recs[-1][0]]  # no DataEnd, no summary, no footer: as after a crash
    rep, got = _recover_bytes(tmp_path, bytes(b))
    _assert_kept(got)
    assert got == list(range(2000))  # a length field alone loses nothing
    assert rep["summary_used"] is summary


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10**6), st.integers(0, 2**64 - 1), st.booleans())
def test_any_corrupted_length_field_keeps_99_percent(tmp_path_factory, many_chunks, pick, value, summary):
    data, recs = many_chunks
    off, _, _ = recs[1:-1][pick % (len(recs) - 2)]  # any record between the header and DataEnd
    b = bytearray(data)
    struct.pack_into("<Q", b, off + 1, value)
    if not summary:
        b = b[:recs[-1][0]]
    rep, got = _recover_bytes(tmp_path_factory.mktemp("any"), bytes(b))
    _assert_kept(got)


def test_a_damaged_spot_without_summary_resynchronises_on_the_next_chunk(tmp_path, many_chunks):
    """Header and body start of one chunk overwritten, no summary: that chunk is lost (50
    records), the scan resumes at the next valid record and keeps the rest."""
    data, recs = many_chunks
    off = [o for o, op, _ in recs if op == 0x06][10]
    b = bytearray(data[:recs[-1][0]])
    b[off:off + 40] = b"\xa5" * 40
    rep, got = _recover_bytes(tmp_path, bytes(b))
    assert got == [i for i in range(2000) if not 500 <= i < 550]
    assert rep["resynchronised"] and rep["resynchronised"][0]["bad_record_at"] == off
