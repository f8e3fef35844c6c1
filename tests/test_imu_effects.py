"""Measurement effects taken out of the IMU readings before the estimator runs."""

from __future__ import annotations

import pytest

from vdps_hil.bus.samples import Sample
from vdps_hil.model.effects import make_effect
from vdps_hil.workbench import imu_effects as IE


def test_imu_bias_is_taken_out_of_the_readings():
    bias = make_effect("imu_bias", accel_bias_x_mps2=0.2, gyro_bias_z_radps=0.01)
    samples = [Sample(i * 1_000_000, "imu", "imu", {"specific_force_mps2_x": 1.0 + 0.2, "specific_force_mps2_y": 0.0,
                                                    "specific_force_mps2_z": 9.8 + 0.05,
                                                    "angular_rate_radps_x": 0.0, "angular_rate_radps_y": 0.0,
                                                    "angular_rate_radps_z": 0.3 + 0.01})
               for i in range(200)]
    out = IE.remove_imu_effects(samples, [bias])
    f = out[100].fields
    assert f["specific_force_mps2_x"] == pytest.approx(1.0)
    assert f["angular_rate_radps_z"] == pytest.approx(0.3)
    assert f["specific_force_mps2_z"] == pytest.approx(9.8)  # the default z bias 0.05 is in the effect


def test_the_gyro_track_is_interpolated_exactly_as_numpy_interp():
    """The per-sample interpolation of the smoothed gyro (``_Linear``) is np.interp's formula:
    equal bit for bit at random times inside the track, clamped to the end values outside."""
    import numpy as np

    rng = np.random.default_rng(11)
    x = np.arange(0.0, 5.0, 0.0025) + 0.0007
    y = rng.normal(size=(len(x), 6))
    at = IE._Linear(x, y)
    for t in np.concatenate([rng.uniform(-0.5, 5.5, 3000), x[:3], x[-3:]]):
        assert at(float(t)) == tuple(float(np.interp(t, x, y[:, k])) for k in range(6))


def test_a_steering_offset_is_taken_out_of_the_steering_samples():
    """The workbench's re-estimation with a fitted steering offset (``--add steering_offset``):
    the steering samples lose it exactly, the IMU samples are untouched (no IMU effect, and no
    gyro track needed for it)."""
    off = make_effect("steering_offset", offset_rad=-0.02)
    steer = [Sample(i * 10_000_000, "can", "steer", {"steer_wheel_angle_rad": 0.1 * i - 0.02}) for i in range(5)]
    imu = Sample(3, "imu", "imu", {"specific_force_mps2_x": 1.0})
    out = list(IE.imu_corrected(steer + [imu], [off], None))
    assert [s.fields["steer_wheel_angle_rad"] for s in out[:5]] == pytest.approx([0.1 * i for i in range(5)], abs=1e-15)
    assert out[5] is imu
