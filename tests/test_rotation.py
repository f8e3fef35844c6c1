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


def test_bulk_can_and_serial_writes_rotate_per_message(tmp_path):
    """write_can_frames and write_serial_chunks on a rotating writer go message by message, so
    the segments are those of write_can / write_serial once each."""
    import numpy as np
    from mcap.reader import make_reader

    from vdps_hil.record import schemas as S

    t = np.arange(1, 401, dtype=np.int64) * 1_000_000
    data = np.zeros((400, 8), np.uint8)
    chunks = [(int(x), b"abc") for x in t]
    names = []  # the messages of each segment
    for bulk in (True, False):
        w = RotatingRecordingWriter(tmp_path / f"{bulk}.mcap", max_s=0.1, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
        if bulk:
            w.write_can_frames("c", t, np.full(400, 5), np.full(400, 8), data)
            w.write_serial_chunks("imu", chunks, baud=9600, fmt="x")
        else:
            for k, tk in enumerate(t.tolist()):
                w.write_can("c", tk, {"arbitration_id": 5, "data": bytes(8)})
            for tk, d in chunks:
                w.write_serial("imu", tk, d, baud=9600, fmt="x")
        w.close()
        segments = []
        for f in w.files:
            with open(f, "rb") as fh:
                segments.append([(c.topic, m.log_time, m.data) for _, c, m in make_reader(fh).iter_messages()])
        names.append(segments)
    assert names[0] == names[1] and len(names[0]) >= 4
