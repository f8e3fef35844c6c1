"""Tests of hil.pacing: the bench clock maps monotonic time onto simulated time at any speed,
deadlines are absolute (a sleep that overshoots delays the items due during it and nothing
after them: no accumulated drift), late sends are counted with the stated tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vdps_hil.hil.pacing import BenchClock, Pacer, percentiles_ms
from vdps_hil.record.schemas import DEFAULT_SIM_EPOCH_NS

MS = 1_000_000


class FakeTime:
    """A monotonic clock whose sleeps always last ``overshoot_ns`` longer than asked."""

    def __init__(self, start_ns: int = 10**12, overshoot_ns: int = 0):
        self.t = start_ns
        self.overshoot_ns = overshoot_ns
        self.sleeps = 0

    def monotonic_ns(self) -> int:
        return self.t

    def sleep(self, s: float) -> None:
        self.sleeps += 1
        self.t += int(round(s * 1e9)) + self.overshoot_ns

    def work(self, ns: int) -> None:
        self.t += ns


@pytest.mark.parametrize("speed", [0.25, 1.0, 3.0])
def test_clock_maps_monotonic_time_to_simulated_time_and_back(speed):
    ft = FakeTime()
    c = BenchClock(speed, monotonic_ns=ft.monotonic_ns)
    assert not c.started and c.now_ns() == 0
    m0 = c.start()
    assert m0 == ft.t and c.started
    ft.work(400 * MS)  # 0.4 s of wall time
    assert c.now_ns() == round(400 * MS * speed)
    for t in (0, 1, 123_456_789, 5 * 10**9):
        assert abs(c.t_of(c.deadline(t)) - t) <= math.ceil(speed)  # inverse to the rounding
    t, wall = c.now()
    assert wall == DEFAULT_SIM_EPOCH_NS + t and c.wall(t) == wall
    assert c.wall_ms(speed * 2 * MS) == pytest.approx(2.0)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan])
def test_clock_refuses_a_speed_that_is_not_positive_and_finite(bad):
    with pytest.raises(ValueError, match="speed"):
        BenchClock(bad)


def test_deadlines_are_absolute_so_sleep_errors_do_not_accumulate():
    """200 items every 1 ms, each sleep 0.3 ms too long, 0.2 ms of work per item: with absolute
    deadlines every item goes out within overshoot + work of its deadline, and the last one
    0.2 s after the first (accumulated sleeps would be 200 * 0.5 ms = 0.1 s late by the end)."""
    ft = FakeTime(overshoot_ns=300_000)
    clock = BenchClock(1.0, monotonic_ns=ft.monotonic_ns)
    pacer = Pacer(clock, late_tolerance_s=0.002, sleep=ft.sleep)
    clock.start()
    sent_at = []
    for k in range(200):
        t_item = k * MS
        while not pacer.wait_until(t_item, max_wait_s=0.001):
            pass
        sent_at.append(ft.t)
        pacer.sent([t_item], ft.t)
        ft.work(200_000)
    lateness = np.array(sent_at) - (clock.mono0_ns + np.arange(200) * MS)
    assert lateness.min() >= 0
    assert lateness.max() <= 300_000 + 200_000  # one overshoot (+ the previous item's work), never more
    assert sent_at[-1] - sent_at[0] == pytest.approx(199 * MS, abs=0.5 * MS)
    st = pacer.stats()
    assert st["sends"] == 200 and st["late_sends"] == 0
    assert st["lateness_ms"]["max"] <= 0.5


def test_speed_scales_the_deadlines():
    ft = FakeTime()
    clock = BenchClock(4.0, monotonic_ns=ft.monotonic_ns)
    pacer = Pacer(clock, sleep=ft.sleep)
    clock.start()
    while not pacer.wait_until(1_000 * MS, max_wait_s=0.01):  # 1 s simulated
        pass
    assert ft.t - clock.mono0_ns == pytest.approx(250 * MS, abs=0.01 * MS)  # = 0.25 s wall


def test_late_sends_are_counted_beyond_the_tolerance_only():
    ft = FakeTime()
    clock = BenchClock(1.0, monotonic_ns=ft.monotonic_ns)
    pacer = Pacer(clock, late_tolerance_s=0.002)
    clock.start()
    t_items = np.array([0, 10, 20, 30]) * MS
    # sent at +1 ms, +2 ms (not late: equal to the tolerance), +2.001 ms and +50 ms
    for t, late in zip(t_items, (1 * MS, 2 * MS, 2 * MS + 1000, 50 * MS)):
        pacer.sent([t], clock.mono0_ns + t + late)
    pacer.sent([], clock.mono0_ns)  # nothing sent: nothing counted
    st = pacer.stats()
    assert st["sends"] == 4 and st["late_sends"] == 2
    assert st["lateness_ms"]["max"] == pytest.approx(50.0)
    assert st["late_tolerance_ms"] == 2.0


def test_an_item_already_due_is_not_waited_for():
    ft = FakeTime()
    clock = BenchClock(1.0, monotonic_ns=ft.monotonic_ns)
    pacer = Pacer(clock, sleep=ft.sleep)
    clock.start()
    ft.work(5 * MS)
    assert pacer.wait_until(3 * MS) and ft.sleeps == 0


def test_percentiles_in_milliseconds():
    p = percentiles_ms(np.arange(1, 101) * MS)
    assert p["p50"] == pytest.approx(50.5) and p["p99"] == pytest.approx(99.01) and p["max"] == 100.0
    assert p["n"] == 100
    empty = percentiles_ms([])
    assert math.isnan(empty["p50"]) and empty["n"] == 0
