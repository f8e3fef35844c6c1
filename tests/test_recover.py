"""Recovery of cut and damaged recordings: every complete chunk rescued, nothing invented."""

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
