"""LogSession (vdps_hil.app.session): python-can's virtual bus (a reader thread) and an IMU on a
real pseudo-terminal (a reader process); raw records first -- a decoder that stalls or falls
behind, a disk reserve reached and a slow tap cost decoded samples (counted), never raw bytes;
health and loss per source in the file."""

import json
import os
import pty
import select
import subprocess
import sys
import threading
import time
import tty

import can
import pytest

from vdps_hil.adapters.can_adapter import CanAdapter
from vdps_hil.adapters.imu_adapter import ImuAdapter
from vdps_hil.app.session import LogSession, room_bytes, start_readers
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_encode import encode_wheel_speeds
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.imu_mtdata2 import encode_imu_packet
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.recorder import HEALTH_METADATA
from vdps_hil.record.writer import RecordingWriter


def _run(sess, until, timeout_s=20.0):
    stop = threading.Event()
    result = {}
    th = threading.Thread(target=lambda: result.update(sess.run(stop)))
    th.start()
    try:
        until()
    finally:
        stop.set()
        th.join(timeout_s)
    assert not th.is_alive()
    return result


def _wait(cond, timeout_s=10.0):
    t_end = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < t_end:
        time.sleep(0.02)


def run_can_session(tmp_path, rng, n, **kw):
    # these tests are about recording, health and the tap; the lag rule has its own test
    # (a starved machine can hold the session past the 2 s default)
    kw.setdefault("decode_lag_s", 60.0)
    chan = f"sess_{rng.integers(1 << 30)}"
    a = CanAdapter("vdps", f"virtual:{chan}", decoder=VdpsCanDecoder())
    out = tmp_path / "s.mcap"
    w = RecordingWriter(out, metadata={"mode": "test"})
    lines = []
    sess = LogSession([a], w, status=lines.append, status_s=0.05, health_s=0.1, flush_s=0.1,
                      **kw)
    sess.open()
    tx = can.Bus(interface="virtual", channel=chan)

    def send():
        for k in range(n):
            for m in encode_wheel_speeds([1.0, 2.0, 3.0, 4.0], k % 256):
                tx.send(m)
        _wait(lambda: a.health.records >= 2 * n)
        time.sleep(0.3)

    try:
        res = _run(sess, send)
    finally:
        tx.shutdown()
        w.close()
    return out, res, lines, sess


def test_session_records_everything_with_health_and_loss(tmp_path, rng):
    out, res, lines, _ = run_can_session(tmp_path, rng, 500)
    assert res["written"] >= 2000 and res["raw_records"] == 1000
    assert any(ln.startswith("can.vdps:") and "drops 0 (os ?, reader 0, seq 0)" in ln
               for batch in lines for ln in batch)
    with RecordingReader(out) as r:
        t = r.topics()
        assert t["/raw/can/vdps"].count == 1000
        assert t["/decoded/can.vdps/wheel_speed"].count == 1000
        assert t["/health/can.vdps"].count >= 2
        h = json.loads(r.metadata()[HEALTH_METADATA]["can.vdps"])
    assert h["records"] == 1000 and h["counters"]["lost_frames"] == 0
    assert h["kinds"]["wheel_speed"]["count"] == 1000
    assert h["loss"]["read_by"] == "thread"  # virtual: python-can's blocking recv in a thread
    assert {h["loss"][k] for k in ("os", "reader", "sequence", "decoded_skipped")} == {0}


def test_what_the_readers_took_before_the_loop_began_is_not_taken_for_decoding_lag(tmp_path, rng):
    """``vdps log`` starts the readers as soon as the devices are open and its loop after the
    file and the tap exist (seconds on a loaded machine): frames read 2.5 s before ``run`` with a
    1 s lag limit are decoded, every one (the limit counts from the start of the loop for
    them; it had skipped them all, and ``--pipeline`` then saw no sample)."""
    chan = f"early_{rng.integers(1 << 30)}"
    a = CanAdapter("vdps", f"virtual:{chan}", decoder=VdpsCanDecoder())
    out = tmp_path / "early.mcap"
    w = RecordingWriter(out, metadata={"mode": "test"})
    sess = LogSession([a], w, decode_lag_s=1.0, health_s=0.1)
    sess.open()
    start_readers([a])
    tx = can.Bus(interface="virtual", channel=chan)
    try:
        for k in range(200):
            for m in encode_wheel_speeds([1.0, 2.0, 3.0, 4.0], k % 256):
                tx.send(m)
        time.sleep(2.5)  # the logger's start-up: the reader holds them meanwhile
        res = _run(sess, lambda: _wait(lambda: a.health.records >= 400))
    finally:
        tx.shutdown()
        w.close()
    with RecordingReader(out) as r:
        t = r.topics()
        assert t["/raw/can/vdps"].count == 400
        assert t["/decoded/can.vdps/wheel_speed"].count == 400
    assert res["loss"]["can.vdps"]["decoded_skipped"] == 0


def test_disk_reserve_stops_decoded_topics_and_keeps_every_raw_frame(tmp_path, rng):
    # a reserve larger than any disk: decoded samples stop at once, raw frames go on
    out, res, lines, sess = run_can_session(tmp_path, rng, 300, reserve_bytes=1 << 62)
    with RecordingReader(out) as r:
        t = r.topics()
        h = json.loads(r.metadata()[HEALTH_METADATA]["can.vdps"])
        decoded = t["/decoded/can.vdps/wheel_speed"].count if \
            "/decoded/can.vdps/wheel_speed" in t else 0
        assert t["/raw/can/vdps"].count == 600
    assert not sess.decoded_ok and any("reserve reached" in ln for b in lines for ln in b)
    skipped = h["counters"]["decoded_skipped_disk"]
    assert skipped > 0 and decoded + skipped == 600
    assert h["loss"]["decoded_skipped"] == skipped and h["drops"] == 0


def test_room_is_bounded_by_the_file_size_limit(tmp_path):
    f = tmp_path / "x.mcap"
    f.write_bytes(b"\0" * 200_000)
    code = ("import resource, sys; from vdps_hil.app.session import room_bytes; "
            "resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, resource.RLIM_INFINITY)); "
            f"print(room_bytes({str(f)!r}))")
    room = int(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              check=True).stdout)
    assert room == 800_000
    assert room_bytes(str(f)) > 800_000  # this process has no limit


class _ImuDevice:
    """An MTi on the master side of a pty at ``rate_hz``: non-blocking writes like a UART; a
    packet that does not fit is dropped and counted. A packet this thread makes more than
    50 ms after its due time (the thread itself was stalled: a loaded machine) waits for room
    instead (counted as ``late``): the device would have sent it while the thread was not
    running, so the burst after the stall is not charged to the reader."""

    def __init__(self, n, rate_hz=1000.0):
        self.m, self.s = pty.openpty()
        tty.setraw(self.s)
        os.set_blocking(self.m, False)
        self.port = os.ttyname(self.s)
        self.n, self.rate_hz = n, rate_hz
        self.dropped = self.late = 0
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self):
        t0 = time.monotonic()
        k = 0
        while k < self.n:
            due = min(self.n, int((time.monotonic() - t0) * self.rate_hz) + 1)
            while k < due:
                pkt = encode_imu_packet(k * 1_000_000, [0.0, 0.0, 9.81], [0.0, 0.0, 0.1], k)
                if time.monotonic() - t0 - k / self.rate_hz > 0.05:
                    self.late += 1
                    select.select([], [self.m], [], 5.0)  # room for a small write
                try:
                    if os.write(self.m, pkt) != len(pkt):
                        self.dropped += 1  # (a pty takes whole small writes or none)
                except BlockingIOError:
                    self.dropped += 1
                k += 1
            time.sleep(0.0005)

    def close(self):
        os.close(self.m)
        os.close(self.s)


class _StallingImuDecoder(ImuDecoder):
    """The real decoder behind a stall of ``first_s`` at its first chunk and ``each_s`` at every
    chunk after (a decoder far slower than the device)."""

    def __init__(self, *a, first_s=1.0, each_s=0.004, **kw):
        super().__init__(*a, **kw)
        self.first_s, self.each_s = first_s, each_s

    def feed(self, t_ns, chunk):
        time.sleep(self.first_s)
        self.first_s = self.each_s
        return super().feed(t_ns, chunk)


def test_stalled_and_slow_decoder_costs_decoded_samples_never_raw_bytes(tmp_path):
    n = 1500  # 1.5 s at 1 kHz: 70 kB, three times what the pty holds
    dev = _ImuDevice(n)
    a = ImuAdapter("imu", dev.port)
    a.protocol.decoder = _StallingImuDecoder("imu", baud=a.baud)
    out = tmp_path / "imu.mcap"
    w = RecordingWriter(out, metadata={"mode": "test"})
    sess = LogSession([a], w, decode_lag_s=0.1, health_s=0.1)
    sess.open()

    def stream():
        dev.thread.start()
        dev.thread.join(30)
        time.sleep(0.3)

    try:
        _run(sess, stream, 60)
    finally:
        w.close()
        dev.close()
    assert dev.dropped == 0, dev.late  # the reader process drained the pty through the stall
    with RecordingReader(out) as r:
        raw = b"".join(data for _, _, data in r.iter_raw_serial("imu"))
        t = r.topics()
        decoded = t["/decoded/imu/imu"].count if "/decoded/imu/imu" in t else 0
        h = json.loads(r.metadata()[HEALTH_METADATA]["imu"])
    offline = ImuDecoder("imu")
    samples = offline.feed(0, raw) + offline.flush()
    assert [int(s.fields["seq_counter"]) for s in samples] == list(range(n))  # raw complete
    assert h["loss"]["read_by"] == "process"
    skipped = h["counters"]["decoded_skipped"]
    assert skipped > 0 and decoded < n  # the decoder lost its own work, counted
    assert h["counters"]["seq_gaps"] == 0 and h["drops"] == 0  # ... not taken for device loss


def test_slow_tap_drops_its_own_input_never_the_recording(tmp_path, rng):
    seen = []

    def tap(samples):
        time.sleep(0.05)
        seen.extend(samples)

    out, res, _, sess = run_can_session(tmp_path, rng, 2000, tap=tap, tap_queue=200,
                                        tap_drain_s=2.0)
    with RecordingReader(out) as r:
        t = r.topics()
        assert t["/raw/can/vdps"].count == 4000
        assert t["/decoded/can.vdps/wheel_speed"].count == 4000
    assert res["tap_dropped"] > 0 and len(seen) + res["tap_dropped"] == 4000
