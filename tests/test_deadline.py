"""hil.deadline: the pipeline skips every sample from a wire-stamped sample (IMU, CAN) later than
the deadline until one is within half of it (GNSS fixes are not judged), counts what it skipped, and scales the deadline with
the bench speed (never below twice the sequencer's hold)."""

from __future__ import annotations

from vdps_hil.bus.samples import Sample
from vdps_hil.hil.deadline import DeadlineGuard
from vdps_hil.hil.pacing import BenchClock

MS = 1_000_000


def _sample(kind: str, t_ns: int) -> Sample:
    return Sample(t_ns=t_ns, source="imu" if kind == "imu" else "can.vdps", kind=kind, fields={})


def test_skips_from_a_late_imu_sample_until_one_is_within_half_the_deadline():
    now = [0]
    g = DeadlineGuard(BenchClock(1.0, mono0_ns=0, monotonic_ns=lambda: now[0]), 0.1, hold_s=0.05)
    assert g.deadline_ns == 100 * MS and g.resume_ns == 50 * MS
    seen = []
    for k in range(400):  # 1 kHz IMU, a wheel speed after each; the loop 120 ms late over 100-200 ms
        t = k * MS
        lag = 120 * MS if 100 <= k < 200 else (60 * MS if 200 <= k < 250 else 0)
        now[0] = t + lag
        seen.append((k, g.skip(_sample("imu", t)), g.skip(_sample("wheel_speed", t))))
    skipped = [k for k, a, b in seen if a]
    assert skipped == list(range(100, 250))  # 60 ms late is not back: above half the deadline
    assert all(a == b for _, a, b in seen)  # on time, the wheel speeds follow the IMU
    c = g.counts()
    assert c == {"samples": 300, "episodes": 1, "by_kind": {"imu": 150, "wheel_speed": 150},
                 "first_t_s": 0.1, "deadline_ms": 100.0}


def test_the_deadline_is_in_bench_time_and_none_never_skips():
    now = [10**10]
    clock = BenchClock(4.0, mono0_ns=0, monotonic_ns=lambda: now[0])
    assert DeadlineGuard(clock, 0.1, hold_s=0.05).deadline_ns == 400 * MS  # 100 ms wall at 4x
    assert DeadlineGuard(BenchClock(0.25), 0.1, hold_s=0.05).deadline_ns == 100 * MS  # twice the hold
    never = DeadlineGuard(clock, None)
    assert not never.skip(_sample("imu", 0)) and never.counts()["samples"] == 0


def test_a_burst_of_late_can_samples_is_skipped_with_half_a_deadline_of_imu_input():
    """CAN samples are stamped by the interface: a burst of them 150 ms late is skipped from its
    first sample on, not handled until an IMU packet shows the lateness; an on-time CAN sample
    does not end the episode, an on-time IMU sample ends it only once 50 ms of IMU input has
    been skipped (an outage the estimator sees: "sensor missing"); a GNSS fix reported 150 ms
    after its time does not start skipping."""
    now = [500 * MS]
    g = DeadlineGuard(BenchClock(1.0, mono0_ns=0, monotonic_ns=lambda: now[0]), 0.1, hold_s=0.05)
    assert not g.skip(_sample("gnss_pos", 350 * MS))  # fix time: not judged
    assert [g.skip(_sample("suspension", t * MS)) for t in range(350, 360)] == [True] * 10
    assert g.skip(_sample("wheel_speed", 490 * MS))  # on time, but only the IMU ends an episode
    imu = []
    for k in range(100):  # the IMU on time (10 ms late) from 490 ms on, 1 kHz
        now[0] = (500 + k) * MS
        imu.append(g.skip(_sample("imu", (490 + k) * MS)))
    assert imu == [True] * 50 + [False] * 50  # 50 ms of IMU input skipped, then handled
    c = g.counts()
    assert c["by_kind"] == {"suspension": 10, "wheel_speed": 1, "imu": 50} and c["episodes"] == 1
