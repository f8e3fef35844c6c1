"""Bounded fan-out (vdps_hil.bus.subscription): an overflow is dropped for that listener only and
counted, per source and in the adapter's health."""

from list_adapter import ListAdapter, drain_all

from vdps_hil.bus.clocks import ReplayClock
from vdps_hil.bus.subscription import Subscription


def test_bounded_queue_counts_overflow_per_source_and_in_health():
    a = ListAdapter([(i, i) for i in range(50)], clock=ReplayClock())
    small = a.subscribe(Subscription("small", maxsize=10, raw=False))
    big = a.subscribe(Subscription("big", maxsize=1000, raw=False))
    a.open()
    drain_all(a)
    assert len(small.drain()) == 10 and small.overflows == 40
    assert small.overflows_by_source == {"src": 40}
    assert len(big.drain()) == 50 and big.overflows == 0  # one slow listener hurts only itself
    assert a.health.counters["queue_overflow"] == 40
    assert a.health.drops == 40
