"""Streaming removal of IMU measurement effects (estimation.imu_correction)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.imu_correction import ImuEffectCorrection
from vdps_hil.model.effects import REGISTRY
from vdps_hil.model.effects.base import ImuKinematics

F = ("specific_force_mps2_x", "specific_force_mps2_y", "specific_force_mps2_z")
W = ("angular_rate_radps_x", "angular_rate_radps_y", "angular_rate_radps_z")
RATE_HZ = 1000.0


def _truth(t):
    """A yaw-and-roll oscillation (0.5 Hz, 0.3 rad/s yaw, 0.1 rad/s roll) with 2 m/s^2 of
    lateral specific force at the CG: omega, omega_dot exact."""
    w = 2 * math.pi * 0.5
    om = (0.1 * math.sin(w * t), 0.0, 0.3 * math.sin(w * t + 0.4))
    od = (0.1 * w * math.cos(w * t), 0.0, 0.3 * w * math.cos(w * t + 0.4))
    f = (0.3, 2.0 * math.sin(w * t), 9.81)
    return f, om, od


def _stream(effects, seconds=6.0):
    """(t, CG truth specific force, measured samples) with the effects applied exactly."""
    out, truth = [], []
    for k in range(int(seconds * RATE_HZ)):
        t = k / RATE_HZ
        f, om, od = _truth(t)
        fields = dict(zip(F, f)) | dict(zip(W, om))
        kin = ImuKinematics(t, f, om, od)
        for e in effects:
            fields = e.apply(fields, kin)
        out.append(Sample(int(round(t * 1e9)), "imu0", "imu", fields))
        truth.append(f + om)
    return np.array(truth), out


def test_bias_is_removed_exactly():
    """An additive bias is removed to rounding (eq 1 is exact for it)."""
    eff = REGISTRY["imu_bias"](accel_bias_x_mps2=0.05, accel_bias_y_mps2=-0.08, gyro_bias_z_radps=0.002)
    truth, samples = _stream([eff], seconds=1.0)
    node = ImuEffectCorrection([eff])
    got = np.array([[c.fields[n] for n in F + W] for c in map(node.process, samples)])
    np.testing.assert_allclose(got, truth, atol=1e-12)
    assert node.corrected == len(samples)


def test_lever_arm_is_removed_to_the_filter_lag():
    """Lever arm 0.5 m ahead and 0.2 m left: the effect adds about 0.5 m/s^2 (RMS 0.33) of
    lateral specific force; after the correction the residual (from the 16 ms lag of the
    band-limited derivative, eq 2-3) is below 10 % of the effect's RMS after a 1 s warm-up."""
    eff = REGISTRY["imu_lever_arm"](lever_x_m=0.5, lever_y_m=0.2, lever_z_m=0.0)
    truth, samples = _stream([eff])
    node = ImuEffectCorrection([eff])
    got = np.array([[c.fields[n] for n in F] for c in map(node.process, samples)])
    meas = np.array([[s.fields[n] for n in F] for s in samples])
    k = int(RATE_HZ)
    effect_rms = np.sqrt(np.mean((meas[k:] - truth[k:, :3]) ** 2, axis=0))
    resid_rms = np.sqrt(np.mean((got[k:] - truth[k:, :3]) ** 2, axis=0))
    assert effect_rms[1] > 0.2
    assert np.all(resid_rms <= 0.10 * effect_rms + 1e-6), (effect_rms, resid_rms)


def test_bias_and_lever_arm_together_and_other_samples_untouched():
    """Both effects: the gyro bias is taken out before the derivative (otherwise a constant
    offset in omega would enter omega x (omega x r)); other kinds pass unchanged."""
    effs = [REGISTRY["imu_bias"](), REGISTRY["imu_lever_arm"](lever_x_m=0.5)]
    truth, samples = _stream(effs)
    node = ImuEffectCorrection(effs)
    got = np.array([[c.fields[n] for n in F + W] for c in map(node.process, samples)])
    k = int(RATE_HZ)
    assert np.max(np.abs(got[k:, 3:] - truth[k:, 3:])) < 1e-12
    assert np.sqrt(np.mean((got[k:, :3] - truth[k:, :3]) ** 2)) < 0.02
    other = Sample(5, "can0", "wheel_speed", {"wheel_speed_radps_1": 30.0})
    assert node.process(other) is other


def test_gap_restarts_the_filter_and_bad_config_is_refused():
    eff = REGISTRY["imu_lever_arm"](lever_x_m=1.0)
    node = ImuEffectCorrection([eff])
    s0 = Sample(0, "imu0", "imu", dict(zip(F, (0, 0, 9.81))) | dict(zip(W, (0, 0, 0.0))))
    s1 = Sample(int(5e9), "imu0", "imu", dict(zip(F, (0, 0, 9.81))) | dict(zip(W, (0, 0, 0.5))))
    node.process(s0)
    out = node.process(s1)  # 5 s gap: no derivative spike from 0 -> 0.5 rad/s
    # only the centripetal term omega x (omega x r) = -r w^2 on x remains: 1.0 * 0.25
    assert out.fields[F[0]] == pytest.approx(0.25, abs=1e-12)
    with pytest.raises(ValueError):
        ImuEffectCorrection([eff], cutoff_hz=0.0)


def test_a_steering_offset_is_taken_out_of_the_steering_samples_exactly():
    """A saved model's steering offset (``steering_offset``) is taken out of the ``steer``
    samples (the estimator's wheel-speed row and the identifier's slip angles read them), with or
    without IMU effects beside it; the IMU samples are then left to the IMU effects alone."""
    off = REGISTRY["steering_offset"](offset_rad=0.03)
    node = ImuEffectCorrection([off])
    s = Sample(7, "can0", "steer", {"steer_wheel_angle_rad": 0.25 + 0.03})
    assert node.process(s).fields["steer_wheel_angle_rad"] == pytest.approx(0.25, abs=1e-15)
    imu = Sample(8, "imu0", "imu", dict(zip(F, (0.0, 0.0, 9.81))) | dict(zip(W, (0.0, 0.0, 0.0))))
    assert node.process(imu) is imu  # nothing of the offset's reaches the IMU
    both = ImuEffectCorrection([off, REGISTRY["imu_bias"]()])
    assert both.process(s).fields["steer_wheel_angle_rad"] == pytest.approx(0.25, abs=1e-15)
    assert both.process(imu).fields["specific_force_mps2_x"] == pytest.approx(-0.05)
    bad = Sample(9, "can0", "steer", {"steer_wheel_angle_rad": 0.1}, valid=False)
    assert both.process(bad) is bad
