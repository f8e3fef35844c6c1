"""Adapter base class: stamping, health (learned rate, timeouts, time going backwards),
bounded fan-out with counted overflows, device loss and reconnection, decoder faults."""

import threading

import pytest

from vdps_hil.adapters.base import (Adapter, AdapterError, DeviceLost, EndOfInput, KindStats,
                                    RawSerial, ReplayClock, Subscription, SystemClock)
from vdps_hil.bus.samples import Sample

NS = 1_000_000_000


class ListAdapter(Adapter):
    """A minimal real subclass: payloads come from a list; decoding turns an int into a
    sample (or raises for the string 'boom')."""

    transport = "test"

    def __init__(self, items, *, fail_open_times=0, lose_at=None, **kw):
        super().__init__("src", "list", **kw)
        self.items = list(items)
        self.fail_open_times = fail_open_times
        self.lose_at = set(lose_at or ())
        self.opens = 0

    def _open(self):
        self.opens += 1
        if self.fail_open_times > 0:
            self.fail_open_times -= 1
            raise DeviceLost("not there")

    def _close(self):
        pass

    def _read(self, timeout_s):
        if not self.items:
            raise EndOfInput()
        item = self.items.pop(0)
        if item in self.lose_at:
            self.lose_at.discard(item)
            raise DeviceLost("unplugged")
        return [item]

    def _raw(self, t_ns, wall, payload):
        return RawSerial(t_ns, wall, self.name, repr(payload).encode())

    def _decode(self, t_ns, payload):
        v = payload
        if v == "boom":
            raise RuntimeError("decoder bug")
        return [Sample(t_ns=t_ns, source=self.name, kind="k", fields={"seq_counter": float(v)})]


def drain_all(a):
    while True:
        try:
            a.poll(0.0)
        except EndOfInput:
            return


def test_replay_learns_rate_and_counts_a_gap_as_timeout():
    # 100 Hz for 1 s, a 0.5 s hole (50 periods > 10), then 100 Hz again.
    times = [i * NS // 100 for i in range(100)] + [int(1.5 * NS) + i * NS // 100 for i in range(50)]
    a = ListAdapter([(t, i) for i, t in enumerate(times)], clock=ReplayClock())
    sub = a.subscribe(Subscription(samples=True, raw=False))
    a.open()
    drain_all(a)
    ks = a.health.kinds["k"]
    assert ks.count == 150
    assert ks.rate_hz == pytest.approx(100.0, rel=0.02)
    assert ks.timeouts == 1
    assert ks.max_gap_ns == pytest.approx(0.51 * NS, abs=1e3)
    got = sub.drain()
    assert [s.t_ns for s in got] == times
    assert all(s.valid for s in got)
    # replay: wall time = the file's time
    assert all(s.wall_time_ns == s.t_ns for s in got)


def test_time_going_backwards_is_counted_and_marked_invalid_never_dropped():
    ts = [0, 10, 20, 15, 30]
    a = ListAdapter([(t * 1_000_000, i) for i, t in enumerate(ts)], clock=ReplayClock())
    sub = a.subscribe()
    a.open()
    drain_all(a)
    events = sub.drain()
    samples = [e for e in events if isinstance(e, Sample)]
    raws = [e for e in events if isinstance(e, RawSerial)]
    assert len(samples) == 5 and len(raws) == 5
    assert a.health.counters["time_backwards"] == 1
    assert [s.valid for s in samples] == [True, True, True, False, True]
    assert a.health.error_total() == 1


def test_live_stamps_monotonic_and_wall_from_one_offset():
    clock = SystemClock()
    a = ListAdapter([(None, i) for i in range(5)], clock=clock)
    sub = a.subscribe(raw=False)
    a.open()
    drain_all(a)
    s = sub.drain()
    assert [x.t_ns for x in s] == sorted(x.t_ns for x in s)
    assert all(x.wall_time_ns - x.t_ns == clock.offset_ns for x in s)


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


def test_decoder_exception_is_counted_and_the_rest_still_flows():
    a = ListAdapter([(1, 1), (2, "boom"), (3, 3)], clock=ReplayClock())
    sub = a.subscribe(raw=False)
    a.open()
    drain_all(a)
    assert [s.t_ns for s in sub.drain()] == [1, 3]
    assert a.health.counters["decoder_exceptions"] == 1
    assert "decoder bug" in a.health.last_error


def test_device_lost_then_back_counts_outage_and_reconnect():
    a = ListAdapter([(i, i) for i in range(6)], lose_at=[(3, 3)], reconnect_s=0.0,
                    clock=ReplayClock())
    sub = a.subscribe(raw=False)
    a.open()
    drain_all(a)
    c = a.health.counters
    assert c["outages"] == 1 and c["reconnects"] == 1
    assert [s.t_ns for s in sub.drain()] == [0, 1, 2, 4, 5]  # the payload lost with the device


def test_first_open_failure_is_a_one_line_adapter_error():
    a = ListAdapter([], fail_open_times=1)
    with pytest.raises(AdapterError) as e:
        a.open()
    assert "\n" not in str(e.value) and "list" in str(e.value)


def test_live_timeout_flag_and_status_line():
    ks = KindStats()
    for i in range(20):
        ks.add(i * 10_000_000, 10.0, 0)  # 100 Hz
    assert not ks.check(19 * 10_000_000 + 50_000_000, 10.0, 0)  # 5 periods: fine
    assert ks.check(19 * 10_000_000 + 150_000_000, 10.0, 0)  # 15 periods: timed out
    assert ks.timeouts == 1 and ks.timed_out
    assert not ks.check(19 * 10_000_000 + 300_000_000, 10.0, 0)  # counted once
    _, resumed = ks.add(19 * 10_000_000 + 400_000_000, 10.0, 0)
    assert resumed and not ks.timed_out and ks.timeouts == 1


def test_run_stops_on_event_and_closes():
    a = ListAdapter([(None, i) for i in range(3)])
    stop = threading.Event()
    th = threading.Thread(target=a.run, args=(stop,))
    th.start()
    th.join(2.0)  # EndOfInput ends the run by itself
    assert not th.is_alive()
    assert a.health.state == "closed" and a.health.samples == 3
    line = a.status_line()
    assert line.startswith("src:") and "drops 0" in line and "[CLOSED]" in line


def test_nested_decoder_counters_are_summed():
    class Nested(ListAdapter):
        def decoder_counters(self):
            return {"bus": {"unknown_id": 2}, "A": {"dlc_mismatch": 1, "lost_frames": 3},
                    "B": {"dlc_mismatch": 4}}

    a = Nested([])
    c = a.health.all_counters()
    assert c["unknown_id"] == 2 and c["dlc_mismatch"] == 5 and c["lost_frames"] == 3
    assert a.health.drops == 3
    assert a.health.error_total() == 5  # unknown IDs are not errors
