"""LogSession (vdps_hil.app.session) in one process: python-can's virtual bus as the device, the
recording read back, health in the file, overflow of a too-small queue counted."""

import json
import threading
import time

import can

from vdps_hil.adapters.can_adapter import CanAdapter
from vdps_hil.app.session import LogSession
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_encode import encode_wheel_speeds
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.recorder import HEALTH_METADATA
from vdps_hil.record.writer import RecordingWriter


def run_session(tmp_path, rng, n, queue_size=1_000_000):
    chan = f"sess_{rng.integers(1 << 30)}"
    a = CanAdapter("vdps", f"virtual:{chan}", decoder=VdpsCanDecoder())
    out = tmp_path / "s.mcap"
    w = RecordingWriter(out, metadata={"mode": "test"})
    lines = []
    sess = LogSession([a], w, queue_size=queue_size, status=lines.append, status_s=0.05,
                      health_s=0.1, flush_s=0.1)
    sess.open()
    stop = threading.Event()
    result = {}
    th = threading.Thread(target=lambda: result.update(sess.run(stop)))
    th.start()
    tx = can.Bus(interface="virtual", channel=chan)
    try:
        for k in range(n):
            for m in encode_wheel_speeds([1.0, 2.0, 3.0, 4.0], k % 256):
                tx.send(m)
        t_end = time.monotonic() + 10
        while a.health.records < 2 * n and time.monotonic() < t_end and \
                sess.sub.overflows + a.health.records < 2 * n:
            time.sleep(0.02)
        time.sleep(0.3)
    finally:
        stop.set()
        th.join(10)
        tx.shutdown()
        w.close()
    return out, result, lines


def test_session_records_everything_with_health(tmp_path, rng):
    out, res, lines = run_session(tmp_path, rng, 500)
    assert res["written"] >= 2000 and res["queue_overflow"] == 0
    assert any(ln.startswith("can.vdps:") for batch in lines for ln in batch)
    with RecordingReader(out) as r:
        t = r.topics()
        assert t["/raw/can/vdps"].count == 1000
        assert t["/decoded/can.vdps/wheel_speed"].count == 1000
        assert t["/health/can.vdps"].count >= 2
        h = json.loads(r.metadata()[HEALTH_METADATA]["can.vdps"])
        assert h["records"] == 1000 and h["counters"]["lost_frames"] == 0
        assert h["kinds"]["wheel_speed"]["count"] == 1000


def test_small_queue_overflow_is_counted_not_silent(tmp_path, rng):
    out, res, _ = run_session(tmp_path, rng, 3000, queue_size=50)
    with RecordingReader(out) as r:
        written = r.topics()["/raw/can/vdps"].count + \
            r.topics()["/decoded/can.vdps/wheel_speed"].count
        h = json.loads(r.metadata()[HEALTH_METADATA]["can.vdps"])
    # every event either reached the file or was counted as a drop
    assert written + res["queue_overflow"] == 2 * 6000
    assert h["counters"].get("queue_overflow", 0) == res["queue_overflow"]
