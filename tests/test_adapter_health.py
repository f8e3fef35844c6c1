"""Per-source health of the adapters (vdps_hil.adapters.health): learned rate, a gap counted as a
timeout, the live timeout flag, nested decoder counters summed."""

import pytest
from list_adapter import NS, ListAdapter, drain_all

from vdps_hil.adapters.health import KindStats
from vdps_hil.bus.clocks import ReplayClock
from vdps_hil.bus.subscription import Subscription


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


def test_loss_is_sorted_by_where_it_happened():
    class Lossy(ListAdapter):
        def decoder_counters(self):
            return {"seq_gaps": 3, "bus": {"lost_frames": 2}}

    a = Lossy([])
    h = a.health
    h.count("reader_overflow", 5)
    h.count("os_overrun", 7)
    h.count("decoded_skipped", 11)
    h.os_counters = "yes"
    lo = h.snapshot()["loss"]
    assert (lo["os"], lo["reader"], lo["sequence"], lo["decoded_skipped"]) == (7, 5, 5, 11)
    assert lo["detail"] == {"os_overrun": 7, "reader_overflow": 5, "seq_gaps": 3,
                            "lost_frames": 2, "decoded_skipped": 11}
    assert h.drops == 17  # decoding skipped is not raw data lost
    line = a.status_line()
    assert "drops 17 (os 7, reader 5, seq 5), decode skipped 11" in line
