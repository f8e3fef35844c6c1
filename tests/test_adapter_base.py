"""Adapter base class: stamping, time going backwards, device loss and reconnection, decoder
faults, the first open, the run loop (its health: test_adapter_health.py; the bus plumbing it
uses: test_bus_clocks.py, test_bus_subscription.py)."""

import threading

import pytest
from list_adapter import ListAdapter, drain_all

from vdps_hil.adapters.base import AdapterError
from vdps_hil.bus.clocks import ReplayClock
from vdps_hil.bus.raw import RawSerial
from vdps_hil.bus.samples import Sample


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
