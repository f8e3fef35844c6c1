"""Tests of hil.sequencer: measurements wait for the IMU of their instant, leave in time order,
and never wait longer than the hold."""

from __future__ import annotations

from vdps_hil.hil.sequencer import InputSequencer


def test_sequencer_releases_measurements_once_the_imu_has_passed_them():
    ms = 1_000_000
    seq = InputSequencer(max_hold_s=0.05)
    assert seq.push("susp@3", 3 * ms, "suspension", 0) == []  # no IMU yet: held
    assert seq.push("imu@2", 2 * ms, "imu", 0) == ["imu@2"]
    assert seq.push("ws@1", 1 * ms, "wheel_speed", 0) == ["ws@1"]  # behind the IMU: at once
    assert seq.push("ws@4", 4 * ms, "wheel_speed", 0) == []
    assert seq.push("imu@4", 4 * ms, "imu", 0) == ["susp@3", "ws@4", "imu@4"]  # in time order, then the IMU
    assert seq.push("gnss@9", 9 * ms, "gnss_pos", 10 * ms) == []
    assert seq.expire(59 * ms) == [] and seq.expire(60 * ms) == ["gnss@9"]  # the IMU stopped: 50 ms at most
    assert seq.expired == 1 and len(seq) == 0
    assert seq.push("ws@20", 20 * ms, "wheel_speed", 70 * ms) == [] and seq.flush() == ["ws@20"]
