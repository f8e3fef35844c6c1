"""Bus clocks (vdps_hil.bus.clocks) as an adapter stamps with them: live monotonic time with the
wall time from one offset."""

from list_adapter import ListAdapter, drain_all

from vdps_hil.bus.clocks import SystemClock


def test_live_stamps_monotonic_and_wall_from_one_offset():
    clock = SystemClock()
    a = ListAdapter([(None, i) for i in range(5)], clock=clock)
    sub = a.subscribe(raw=False)
    a.open()
    drain_all(a)
    s = sub.drain()
    assert [x.t_ns for x in s] == sorted(x.t_ns for x in s)
    assert all(x.wall_time_ns - x.t_ns == clock.offset_ns for x in s)


def test_wall_minus_monotonic_keeps_the_tightest_of_its_paired_reads(monkeypatch):
    """A thread preempted between its two clock reads gives an offset off by the preemption; of
    several pairs bracketed by monotonic reads, the tightest is kept: here the first pair is held
    up 2 ms (its offset would be 1 ms off), the second is read within 1 us."""
    import time

    from vdps_hil.bus.clocks import wall_minus_monotonic_ns

    offset = 1_700_000_000_000_000_000
    mono = iter([0, 2_000_000, 5_000_000, 5_001_000, 9_000_000, 9_500_000])
    reads = []

    def monotonic_ns():
        reads.append(next(mono))
        return reads[-1]

    def time_ns():  # the wall clock read just after the preceding monotonic read
        return reads[-1] + offset

    monkeypatch.setattr(time, "monotonic_ns", monotonic_ns)
    monkeypatch.setattr(time, "time_ns", time_ns)
    got = wall_minus_monotonic_ns(tries=3)
    assert got == offset - 500  # the 1 us pair, read at its start: within half its bracket
    assert abs(got - offset) <= 500
