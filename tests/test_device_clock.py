"""Tests of vdps_hil.record.device_clock: unwrapping, the leaky running minimum, stamping."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.bus.samples import Sample
from vdps_hil.record.device_clock import ClockAligner, DeviceStamper, Unwrapper

MS = 1_000_000


def test_unwrapper_follows_wraps_both_ways():
    u = Unwrapper(1 << 16)
    assert [u(v) for v in (65530, 65535, 3, 10, 4, 20000)] == [65530, 65535, 65539, 65546, 65540, 85536]


@settings(max_examples=60, deadline=None)
@given(offset=st.integers(-10**12, 10**12),
       delays=st.lists(st.lists(st.integers(0, 3 * MS), min_size=1, max_size=6), min_size=2, max_size=40))
def test_stamper_recovers_the_offset_when_each_batch_has_an_unqueued_message(offset, delays):
    """host = dev + offset + queueing delay >= 0; one message per batch with no delay: every
    stamp equals dev + offset, up to the leak (100 ppm of the time between batches)."""
    stamper = DeviceStamper(ClockAligner(jump_s=0.02, confirm_s=0.2))
    dev = 0
    for batch_delays in delays:
        batch_delays = list(batch_delays) + [0]
        batch = []
        for dl in batch_delays:
            dev += MS
            batch.append((Sample(0, "imu", "imu"), dev + offset + dl, dev))
        out = stamper.stamp(batch)
        for s, (_, _, d) in zip(out, batch):
            assert 0 <= s.t_ns - (d + offset) <= 1_000  # leak: 100 ppm x at most ~7 ms
    assert stamper.clock.jumps == 0 and stamper.outliers == 0


def test_a_single_corrupt_time_stamp_does_not_move_the_offset():
    stamper = DeviceStamper(ClockAligner(jump_s=0.02, confirm_s=0.2))
    out = []
    for k in range(100):
        dev = k * MS + (5_000 * MS if k == 50 else 0)  # one packet with a wild device time
        out += stamper.stamp([(Sample(k * MS + 7, "imu", "imu"), k * MS + 7, dev)])
    assert [s.t_ns for s in out] == [k * MS + 7 for k in range(100)]  # the outlier keeps its receive time
    assert stamper.outliers == 1 and stamper.clock.jumps == 0


def test_a_slow_device_clock_is_followed_by_the_leak():
    """Device clock 50 ppm slow: host - dev grows 50 us/s; the 100 ppm leak follows it."""
    clock = ClockAligner(leak_ppm=100.0)
    for k in range(20_000):  # 20 s at 1 kHz
        dev = k * MS
        clock.observe(int(dev * (1 + 50e-6)), dev)
    assert abs(clock.to_host(dev) - int(dev * (1 + 50e-6))) <= 100_000  # within 0.1 ms after 20 s
