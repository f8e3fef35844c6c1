"""Rotation by size and by time: every segment complete and readable alone, nothing lost
or duplicated across segments."""

import pytest

from vdps_hil.bus.samples import Sample
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.rotation import RotatingRecordingWriter, segment_path


def write(w, n, dt_ns=1_000_000):
    for i in range(n):
        w.write_sample(Sample(t_ns=i * dt_ns, source="imu", kind="imu",
                              fields={"seq_counter": float(i), "specific_force_mps2_x": i * 0.1},
                              wall_time_ns=1 + i))


def read_all(files):
    out = []
    for f in files:
        with RecordingReader(f) as r:
            assert not r.truncated
            md = r.metadata()
            assert md["vdps.recording"]["mode"] == "test"
            out.append((int(md["vdps.segment"]["index"]),
                        [int(s.fields["seq_counter"]) for s in r.iter_samples()]))
    return out


def test_segment_names(tmp_path):
    assert segment_path(tmp_path / "out.mcap", 3).name == "out_0003.mcap"


def test_rotation_by_time(tmp_path):
    w = RotatingRecordingWriter(tmp_path / "out.mcap", max_s=1.0, metadata={"mode": "test"})
    write(w, 3500)  # 3.5 s at 1 kHz
    w.close()
    assert len(w.files) == 4
    segs = read_all(w.files)
    assert [i for i, _ in segs] == [0, 1, 2, 3]
    assert sum((s for _, s in segs), []) == list(range(3500))
    assert [len(s) for _, s in segs[:3]] == [1001, 1001, 1001]  # 0..1 s inclusive, then next


def test_rotation_by_size(tmp_path):
    w = RotatingRecordingWriter(tmp_path / "out.mcap", max_bytes=50_000, chunk_size=8192,
                                metadata={"mode": "test"})
    write(w, 20_000)
    w.close()
    assert len(w.files) >= 3
    segs = read_all(w.files)
    assert sum((s for _, s in segs), []) == list(range(20_000))
    import os
    sizes = [os.path.getsize(f) for f in w.files]
    assert all(s < 50_000 + 20_000 for s in sizes)  # at most about a chunk over


def test_bad_limits():
    with pytest.raises(ValueError):
        RotatingRecordingWriter("x.mcap", max_bytes=0)


def test_copied_messages_rotate_like_written_ones(tmp_path):
    """A rotating writer's copier writes each copy at once (no queue), so rotation by time
    splits copies exactly where it splits direct writes."""
    from vdps_hil.record import schemas as S

    w = RotatingRecordingWriter(tmp_path / "out.mcap", max_s=1.0, metadata={"mode": "test"})
    copy = w.copier(lambda topic: (S.RAW_SERIAL, {"device": "imu", "baud": "", "format": ""}))
    for i in range(2500):
        copy(("/raw/serial/imu", i * 1_000_000, 1 + i, 0, b'{"k":%d}' % i))
    w.close()
    counts = []
    for f in w.files:
        with RecordingReader(f) as r:
            counts.append([int(rec.data[5:-1]) for rec in r.iter_records()])
    assert [len(c) for c in counts] == [1001, 1001, 498]
    assert sum(counts, []) == list(range(2500))
