"""Tests of hil.stamping: CAN frames stamped by the interface's time on the bench axis, never
before the start, the previous frame or after reception."""

from __future__ import annotations

import time

import can
import pytest

from vdps_hil.bus.clocks import wall_minus_monotonic_ns
from vdps_hil.hil.pacing import BenchClock
from vdps_hil.hil.stamping import InterfaceTimeCanAdapter


def test_can_frames_are_stamped_with_the_interface_time_on_the_bench_axis():
    """A frame's interface time stamp (wall clock) becomes bench time; never later than its
    reception, never before the previous frame's stamp, never before the bench's start (a
    sender's and a receiver's wall-minus-monotonic offsets differ by microseconds: the first
    frame of a run must not get a negative time)."""
    clock = BenchClock(2.0)
    clock.start()
    sender = can.Bus(interface="virtual", channel="test-stamps", preserve_timestamps=True)
    ad = InterfaceTimeCanAdapter("vdps", "virtual:test-stamps", clock=clock)
    ad.open()
    try:
        wall_minus_mono = wall_minus_monotonic_ns()
        m0 = clock.mono0_ns
        wall = lambda mono_ns: (mono_ns + wall_minus_mono) / 1e9  # noqa: E731
        # 3 ms before the start, 10 ms, earlier than that, the future
        stamps = [wall(m0 - 3_000_000), wall(m0 + 10_000_000), wall(m0 + 5_000_000), wall(m0 + 10**12)]
        for k, ts in enumerate(stamps):
            sender.send(can.Message(timestamp=ts, arbitration_id=0x100 + k, data=b"\x01", is_extended_id=False))
        time.sleep(0.025)
        got = ad._read(0.1)
        now = clock.now_ns()
    finally:
        ad.close()
        sender.shutdown()
    t = [t for t, _ in got]
    assert t[0] == 0  # before the start: the start
    # 10 ms of wall time at speed 2; 50 us for the two offsets (each read within a few us, on a
    # float seconds stamp that holds ~0.5 us at today's epoch)
    assert t[1] == pytest.approx(20_000_000, abs=50_000)
    assert t[2] == t[1]  # not before the previous frame
    assert t[1] <= t[3] <= now  # a stamp in the future is taken as the reception time
