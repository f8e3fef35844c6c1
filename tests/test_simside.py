"""Tests of hil.simside: the vehicle's side puts exactly the drive's sensor output on the live
wires -- the same frames and bytes, in the same order, as the recording ``vdps sim`` writes for
the same seed -- at their times on the bench clock, and hands the pipeline's frames to the ECU."""

from __future__ import annotations

import io
import os
import threading
import time

import can
import numpy as np
import pytest

from vdps_hil.codecs.can_encode import VdpsCanEncoder
from vdps_hil.hil.can_devices import VirtualCanDevice
from vdps_hil.hil.ecu import Ecu
from vdps_hil.hil.pacing import BenchClock
from vdps_hil.hil.serial_device import PtySerialDevice
from vdps_hil.hil.simside import LiveSink, SimulatorSide
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive

SPEED = 8.0  # simulated s per wall s: the test is about content and order, not timing


def _read_pty(port: str, sink: bytearray, stop: threading.Event) -> None:
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        while not stop.is_set():
            try:
                sink += os.read(fd, 65536)
            except BlockingIOError:
                time.sleep(0.001)
    finally:
        os.close(fd)


def test_the_wires_carry_exactly_what_the_recording_holds():
    # same seed and block length (the dropped_frames draws follow the blocks)
    kw = dict(seed=4, duration_s=0.6, faults=["dropped_frames:fraction=0.05"], block_s=0.01)
    buf = io.BytesIO()
    Drive("paper", **kw).run(buf)
    buf.seek(0)
    with RecordingReader(buf) as r:
        rec_frames = [(m.arbitration_id, bytes(m.data)) for _, m in r.iter_raw_can("vdps")]
        rec_serial = {dev: b"".join(d for dv, _, d in r.iter_raw_serial() if dv == dev) for dev in ("imu", "gnss")}
        rec_truth = r.topics()["/truth/state"].count

    can_dev = VirtualCanDevice()
    can_dev.open()
    serial = {"imu": PtySerialDevice("imu", fifo_bytes=1 << 20), "gnss": PtySerialDevice("gnss")}
    listener = can.Bus(interface="virtual", channel=can_dev.channel)
    got = {"imu": bytearray(), "gnss": bytearray()}
    stop = threading.Event()
    readers = [threading.Thread(target=_read_pty, args=(serial[d].port, got[d], stop), daemon=True) for d in got]
    for th in readers:
        th.start()
    truth = []
    try:
        clock = BenchClock(SPEED)
        side = SimulatorSide(Drive("paper", **kw), can_dev, serial, clock, Ecu(),
                             on_truth=lambda topic, t, doc: truth.append((topic, t)))
        side.run()
        side.flush()
        frames = []
        while True:
            m = listener.recv(0.2)
            if m is None:
                break
            frames.append((m.arbitration_id, bytes(m.data)))
        time.sleep(0.2)
    finally:
        stop.set()
        for th in readers:
            th.join(2.0)
        listener.shutdown()
        side.stop_receiver()
        can_dev.close()
        for d in serial.values():
            d.close()
    assert frames == rec_frames
    assert bytes(got["imu"]) == rec_serial["imu"] and bytes(got["gnss"]) == rec_serial["gnss"]
    assert sum(1 for topic, _ in truth if topic == "state") == rec_truth
    assert side.sim_s == pytest.approx(0.6) and side.wall_s > 0
    sent = side.sent_counts()
    assert sent["frames_sent"] == len(rec_frames) and sent["lines_sent"] == rec_serial["gnss"].count(b"\n")
    assert side.pacer.sends > 0


def test_the_send_loop_makes_one_pass_per_tick_at_most():
    """At real time the drive's items are due 0.3 ms apart; the loop sends what is due once per
    1 ms tick (wall) instead of once per item (~3,000 passes per simulated second before)."""
    can_dev = VirtualCanDevice()
    can_dev.open()
    serial = {"imu": PtySerialDevice("imu", fifo_bytes=1 << 22), "gnss": PtySerialDevice("gnss", fifo_bytes=1 << 22)}
    try:
        side = SimulatorSide(Drive("paper", duration_s=0.4, block_s=0.01), can_dev, serial, BenchClock(1.0), Ecu())
        side.run()
    finally:
        side.stop_receiver()
        can_dev.close()
        for d in serial.values():
            d.close()
    assert side.sim_s == pytest.approx(0.4) and side.pacer.sends > 1000  # items of 0.4 s
    assert side.passes <= side.wall_s / 0.001 + 20  # + the start and the last sends


def test_frames_from_the_pipeline_reach_the_ecu_with_their_bench_time():
    can_dev = VirtualCanDevice()
    can_dev.open()
    serial = {"imu": PtySerialDevice("imu", fifo_bytes=1 << 20), "gnss": PtySerialDevice("gnss", fifo_bytes=1 << 20)}
    pipeline_bus = can.Bus(interface="virtual", channel=can_dev.channel)
    try:
        enc = VdpsCanEncoder()
        clock = BenchClock(SPEED)
        ecu = Ecu(react=True)
        side = SimulatorSide(Drive("paper", duration_s=2.0, block_s=0.01), can_dev, serial, clock, ecu)
        side.prepare()
        th = threading.Thread(target=side.run, daemon=True)
        th.start()
        while clock.now_ns() < 200_000_000:  # 0.2 s simulated
            time.sleep(0.002)
        pipeline_bus.send(enc.warning(2, 1.0, 0.5, 0.9, 0))
        th.join(10.0)
        side.stop_receiver()
    finally:
        pipeline_bus.shutdown()
        can_dev.close()
        for d in serial.values():
            d.close()
    assert len(side.frames_from_pipeline) == 1
    t_w = ecu.summary()["intervention_t_s"]
    assert 0.2 <= t_w < 1.5 and ecu.actuation_start_ns == pytest.approx((t_w + 0.1) * 1e9, abs=1)
    # the ECU acts on the simulator: braking by the end of the drive (2 s)
    assert side.session.sim.current_inputs().brake_torque_nm[0] > 0.0


def test_live_sink_orders_what_is_due():
    sink = LiveSink()
    sink.can_block("vdps", np.array([5, 7]), np.array([5, 7]), np.array([0, 1]), np.zeros((2, 8), np.uint8),
                   [(0x100, 5), (0x101, 5)])
    sink.serial_chunks("imu", 921600, "xsens-mtdata2", [(3, b"a"), (9, b"b")])
    assert sink.next_due_ns() == 3 and not sink.empty
    sink.truth("state", 0, {"roll_v_rad": -0.2})
    sink.truth("events", 0, {"kind": "tip_up", "t_s": 0.0})
    assert sink.max_abs_roll_v_rad == 0.2 and sink.events[0]["kind"] == "tip_up"
