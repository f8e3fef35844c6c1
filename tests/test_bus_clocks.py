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
