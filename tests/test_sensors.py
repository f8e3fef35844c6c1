"""Tests of sim.sensors on synthetic truth blocks: IMU kinematics (lever arm, mounting
rotation, effects, scale factor and misalignment), GNSS antenna geometry, Gauss-Markov error,
sentences in every fix state, chassis sensors, noise statistics and the quantisation switch."""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
import pytest

from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.model.core import BRAKE_HOLD_SPEED_RADPS
from vdps_hil.model.effects import ImuKinematics, MeasurementEffect, make_effect
from vdps_hil.model.frames import dcm_global_to_vehicle
from vdps_hil.model.params import Mounting
from vdps_hil.sim.faults import FaultSet
from vdps_hil.sim.profiles import load_profile
from vdps_hil.sim.sampling import Block
from vdps_hil.sim.sensors import (GEOID_SEPARATION_M, VELOCITY_SIGMA_PER_POSITION_SIGMA, GnssModel, ImuModel,
                                  chassis_sensors, noise_budget_sigma)

MS = 1_000_000
PROFILE = load_profile("table1-susp1k")
ZERO = PROFILE.zero_noise()
MOUNT = Mounting(imu_lever_arm_m=(0.4, -0.2, 0.3), imu_rotation_rpy_rad=(0.02, -0.03, 0.05),
                 gnss_lever_arm_m=(0.3, 0.1, 0.85), gnss_attitude_baseline_m=1.5)


def random_block(rng, n, dt_ns=MS, start=0):
    return Block.build(np.arange(start, start + n), dt_ns,
                       specific_force=rng.normal(0, 3, (n, 3)) + [0, 0, 9.8],
                       rate=rng.normal(0, 0.5, (n, 3)), angular_accel=rng.normal(0, 2, (n, 3)),
                       pos=rng.normal(0, 100, (n, 3)), euler=rng.normal(0, 0.2, (n, 3)),
                       vel_b=rng.normal([20, 0, 0], 1, (n, 3)),
                       wheel_spin=rng.normal(60, 5, (n, 4)), susp=rng.normal(0, 0.01, (n, 4)),
                       steer=rng.normal(0, 0.5, n), drive_torque=rng.normal(0, 200, (n, 4)),
                       brake_torque=np.abs(rng.normal(0, 100, (n, 4))))


def test_noise_budget_sigma():
    assert noise_budget_sigma(0.0349, 0.01, True) == 0.0349
    assert noise_budget_sigma(0.0349, 0.01, False) == pytest.approx(math.sqrt(0.0349**2 - 0.01**2 / 12))
    assert noise_budget_sigma(0.0, 0.001, False) == 0.0


# ------------------------------------------------------------------------------------ IMU
def test_imu_specific_force_at_the_lever_arm_rotated_into_sensor_axes(rng):
    b = random_block(rng, 200)
    imu = ImuModel(ZERO.imu, MOUNT, (), seed=1, dt_ns=MS)
    out = imu.sample(b)
    r = np.array(MOUNT.imu_lever_arm_m)
    c = dcm_global_to_vehicle(*MOUNT.imu_rotation_rpy_rad)
    f_b = np.array([f + np.cross(wd, r) + np.cross(w, np.cross(w, r))
                    for f, w, wd in zip(b.specific_force, b.rate, b.angular_accel)])
    np.testing.assert_allclose(out.specific_force_mps2, f_b @ c.T, atol=1e-12)
    np.testing.assert_allclose(out.angular_rate_radps, b.rate @ c.T, atol=1e-12)
    assert out.k.tolist() == list(range(200)) and out.t_ns.tolist() == (np.arange(200) * MS).tolist()


class DoubleX(MeasurementEffect):
    """A test effect without a vectorised path: doubles the x specific force."""

    name = "double_x"
    FIELDS = ("specific_force_mps2_x",)

    def apply(self, fields, kin):
        out = dict(fields)
        out["specific_force_mps2_x"] *= 2.0
        return out


def test_imu_measurement_effects_equal_the_effects_own_formulas(rng):
    b = random_block(rng, 100)
    bias = make_effect("imu_bias", accel_bias_x_mps2=0.1, gyro_bias_z_radps=0.01)
    lever = make_effect("imu_lever_arm", lever_x_m=0.7, lever_z_m=-0.2)
    flat = dc.replace(MOUNT, imu_lever_arm_m=(0.0, 0.0, 0.0), imu_rotation_rpy_rad=(0.0, 0.0, 0.0))
    out = ImuModel(ZERO.imu, flat, (lever, bias, DoubleX()), seed=1, dt_ns=MS).sample(b)
    for i in range(len(b)):
        kin = ImuKinematics(i * 1e-3, tuple(b.specific_force[i]), tuple(b.rate[i]), tuple(b.angular_accel[i]))
        d = {f"specific_force_mps2_{a}": b.specific_force[i, j] for j, a in enumerate("xyz")}
        d.update({f"angular_rate_radps_{a}": b.rate[i, j] for j, a in enumerate("xyz")})
        d = DoubleX().apply(bias.apply(lever.apply(d, kin), kin), kin)
        np.testing.assert_allclose(out.specific_force_mps2[i],
                                   [d[f"specific_force_mps2_{a}"] for a in "xyz"], atol=1e-12)
        np.testing.assert_allclose(out.angular_rate_radps[i], [d[f"angular_rate_radps_{a}"] for a in "xyz"], atol=1e-12)


def test_scale_factor_and_misalignment_switch_keeps_the_noise_stream(rng):
    b = random_block(rng, 300)
    on = dc.replace(PROFILE.imu, scale_factor_ppm=2000.0, misalignment_rad=0.005)
    m_off, m_on = ImuModel(PROFILE.imu, MOUNT, (), 3, MS), ImuModel(on, MOUNT, (), 3, MS)
    assert not m_off.error_accel.any() and not m_off.error_gyro.any()
    e = m_on.error_accel
    assert np.all(np.abs(np.diag(e)) < 5 * 2000e-6) and np.diag(e).any()
    assert np.all(np.abs(e - np.diag(np.diag(e))) < 5 * 0.005)
    o_off, o_on = m_off.sample(b), m_on.sample(b)
    clean = ImuModel(ZERO.imu, MOUNT, (), 3, MS).sample(b)
    noise_off = o_off.specific_force_mps2 - clean.specific_force_mps2
    noise_on = o_on.specific_force_mps2 - clean.specific_force_mps2 @ (np.eye(3) + e).T
    np.testing.assert_allclose(noise_on, noise_off, atol=1e-12)
    w_expect = clean.angular_rate_radps @ (np.eye(3) + m_on.error_gyro).T
    np.testing.assert_allclose(o_on.angular_rate_radps - w_expect,
                               o_off.angular_rate_radps - clean.angular_rate_radps, atol=1e-12)


def test_imu_white_noise_sigma_and_gyro_spike(rng):
    n = 40_000
    b = Block.build(np.arange(n), MS, specific_force=np.tile([0.1, -0.2, 9.8], (n, 1)))
    out = ImuModel(PROFILE.imu, dc.replace(MOUNT, imu_lever_arm_m=(0, 0, 0), imu_rotation_rpy_rad=(0, 0, 0)),
                   (), 5, MS).sample(b)
    res_f = out.specific_force_mps2 - [0.1, -0.2, 9.8]
    # sigma of n normal draws: relative standard error 1/sqrt(2n) = 0.35 %; 2 % is > 5 of them
    np.testing.assert_allclose(res_f.std(axis=0), PROFILE.imu.accel_sigma_mps2, rtol=0.02)
    np.testing.assert_allclose(out.angular_rate_radps.std(axis=0), PROFILE.imu.gyro_sigma_radps, rtol=0.02)
    assert np.all(np.abs(res_f.mean(axis=0)) < 5 * PROFILE.imu.accel_sigma_mps2 / math.sqrt(n))
    fs = FaultSet(["gyro_spike:t_s=0.010,duration_s=0.003,axis=y,amplitude_degps=100"])
    spiked = ImuModel(ZERO.imu, MOUNT, (), 5, MS).sample(Block.build(np.arange(20), MS), fs)
    w = spiked.angular_rate_radps
    assert np.flatnonzero(w[:, 1]).tolist() == [10, 11, 12]
    np.testing.assert_allclose(w[10:13, 1], math.radians(100.0))


# ------------------------------------------------------------------------------------ GNSS
DT_GNSS = 200 * MS  # one step per 5 Hz epoch: synthetic blocks stay small


def test_gnss_antenna_position_velocity_and_attitude(rng):
    b = random_block(rng, 30, DT_GNSS)
    g = GnssModel(ZERO.gnss, MOUNT, 1, DT_GNSS)
    eps = g.sample(b)
    r = np.array(MOUNT.gnss_lever_arm_m)
    for i, ep in enumerate(eps):
        c = dcm_global_to_vehicle(*b.euler[i])
        p = b.pos[i] + c.T @ r
        lat, lon, h = DEFAULT_ORIGIN.to_geodetic(p)
        assert (ep.lat_deg, ep.lon_deg) == pytest.approx((lat, lon), abs=1e-12)
        assert ep.alt_msl_m == pytest.approx(h - GEOID_SEPARATION_M, abs=1e-6)
        v = c.T @ (b.vel_b[i] + np.cross(b.rate[i], r))
        assert ep.speed_mps == pytest.approx(math.hypot(v[0], v[1]), abs=1e-9)
        assert ep.course_rad == pytest.approx(math.atan2(v[1], v[0]), abs=1e-9)
        assert (ep.roll_rad, ep.pitch_rad) == pytest.approx(tuple(b.euler[i, :2]), abs=1e-12)
        assert math.remainder(ep.yaw_rad - b.euler[i, 2], 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
        assert ep.t_ns == i * DT_GNSS and ep.state == "ok"


def _enu_errors(model, n, rng):
    b = Block.build(np.arange(n), DT_GNSS, vel_b=np.tile([10.0, 0.0, 0.0], (n, 1)))
    eps = model.sample(b)
    r = np.array(MOUNT.gnss_lever_arm_m)
    return np.array([DEFAULT_ORIGIN.to_enu(e.lat_deg, e.lon_deg, e.alt_msl_m + GEOID_SEPARATION_M) - r
                     for e in eps]), eps


@pytest.mark.parametrize("tau_s", [0.0, 2.0])
def test_gnss_position_error_white_or_gauss_markov(tau_s, rng):
    prof = dc.replace(PROFILE.gnss, gauss_markov_tau_s=tau_s)
    err, eps = _enu_errors(GnssModel(prof, MOUNT, 11, DT_GNSS), 12_000, rng)
    sig = err.std(axis=0)
    # white: rel. SE 0.65 %; Gauss-Markov with a = 0.905: effective samples n (1 - a^2)/(1 + a^2),
    # rel. SE 2.1 %; tolerance 8 %
    np.testing.assert_allclose(sig, [1.0, 1.0, 3.0], rtol=0.08 if tau_s else 0.03)
    a = math.exp(-0.2 / tau_s) if tau_s else 0.0
    for k in range(3):
        e = err[:, k]
        rho = np.corrcoef(e[:-1], e[1:])[0, 1]
        assert rho == pytest.approx(a, abs=0.03)
    att = np.array([[ep.roll_rad, ep.pitch_rad] for ep in eps])
    np.testing.assert_allclose(att.std(axis=0), PROFILE.gnss.attitude_sigma_rad, rtol=0.03)
    v = np.array([[ep.speed_mps * math.cos(ep.course_rad), ep.speed_mps * math.sin(ep.course_rad)]
                  for ep in eps])
    np.testing.assert_allclose(v.std(axis=0), VELOCITY_SIGMA_PER_POSITION_SIGMA * 1.0, rtol=0.03)
    np.testing.assert_allclose(v.mean(axis=0), [10.0, 0.0], atol=0.003)


def _decode(lines):
    dec = NmeaDecoder()
    out = []
    for line in lines:
        assert line.endswith(b"\r\n")
        out += dec.feed_line(0, line)
    assert dec.counters["rejected"] == 0 and dec.counters["unsupported"] == 0
    return out


@pytest.mark.parametrize("layout", ["PASHR", "HPR", "PTNL_AVR"])
def test_gnss_sentences_in_every_fix_state(layout, rng):
    prof = dc.replace(ZERO.gnss, attitude_sentence=layout)
    g = GnssModel(prof, MOUNT, 1, DT_GNSS)
    fs = FaultSet(["gnss_outage:t_s=0.3,duration_s=0.4,reacquire_s=0.4"])
    b = random_block(rng, 8, DT_GNSS)
    eps = g.sample(b, fs)
    assert [e.state for e in eps] == ["ok", "ok", "lost", "lost", "reacquiring", "reacquiring", "ok", "ok"]
    for ep in eps:
        samples = _decode(g.sentences(ep, fs))
        kinds = [s.kind for s in samples]
        pos = samples[0].fields
        if ep.state == "lost":
            assert kinds == ["gnss_pos", "gnss_vel"]  # no attitude without a fix
            assert not samples[0].valid and not samples[1].valid
            assert "gnss_lat_deg" not in pos and pos["gnss_fix_quality"] == 0
            continue
        assert kinds == ["gnss_pos", "gnss_vel", "gnss_att"] and all(s.valid for s in samples)
        assert pos["gnss_fix_quality"] == (1 if ep.state == "reacquiring" else 4)
        assert pos["gnss_lat_deg"] == pytest.approx(ep.lat_deg, abs=1e-6 / 60 / 2 + 1e-12)
        assert pos["gnss_alt_m"] == pytest.approx(ep.alt_msl_m, abs=5e-4 + 1e-9)
        att = samples[2].fields
        assert math.remainder(att["gnss_yaw_rad"] - ep.yaw_rad, 2 * math.pi) == \
            pytest.approx(0, abs=math.radians(0.005) + 1e-9)
        assert att["gnss_pitch_rad"] == pytest.approx(ep.pitch_rad, abs=math.radians(0.005) + 1e-9)
        if "gnss_roll_rad" in att:  # HPR: a two-antenna layout, the decoder keeps the pitch
            assert att["gnss_roll_rad"] == pytest.approx(ep.roll_rad, abs=math.radians(0.005) + 1e-9)


def test_gnss_utc_from_the_simulated_epoch_and_clock_jump():
    g = GnssModel(ZERO.gnss, MOUNT, 1, DT_GNSS)
    t = (3600 + 2 * 60 + 3) * 10**9 + 500 * MS
    utc_s, date = g.utc(t)
    assert utc_s == pytest.approx(3723.5) and date.isoformat() == "2012-11-09"
    fs = FaultSet(["clock_jump:device=gnss,t_s=100,jump_s=-2.5"])
    assert g.utc(t, fs)[0] == pytest.approx(3721.0)
    assert g.utc(50 * 10**9, fs)[0] == pytest.approx(50.0)
    assert g.utc(86400 * 10**9 + 1)[1].isoformat() == "2012-11-10"


# ------------------------------------------------------------------------------------ chassis
def test_chassis_sensors_report_the_truth_they_name(rng):
    b = random_block(rng, 100)
    sensors = {s.name: s for s in chassis_sensors(ZERO, 1, MS)}
    t, v = sensors["tachometer"].sample(b)
    np.testing.assert_array_equal(v, b.wheel_spin)
    t, v = sensors["suspension"].sample(b)
    np.testing.assert_array_equal(v, b.susp)
    t, v = sensors["steering"].sample(b)
    np.testing.assert_array_equal(v[:, 0], b.steer[::10])
    assert t.tolist() == list(range(0, 100 * MS, 10 * MS))
    t, v = sensors["wheel_torque"].sample(b)
    rows = slice(0, 100, 10)
    sat = np.clip(b.wheel_spin[rows] / BRAKE_HOLD_SPEED_RADPS, -1, 1)
    np.testing.assert_allclose(v, b.drive_torque[rows] - b.brake_torque[rows] * sat)


@pytest.mark.parametrize("quantise", [False, True])
def test_chassis_noise_and_the_quantisation_switch(quantise, rng):
    prof = dc.replace(PROFILE, quantise_dbc=quantise)
    q = 0.01
    tach = [s for s in chassis_sensors(prof, 2, MS, {f"wheel_speed_radps_{i}": q for i in range(1, 5)})
            if s.name == "tachometer"][0]
    n = 30_000
    t, v = tach.sample(Block.build(np.arange(n), MS, wheel_spin=np.full((n, 4), 50.0)))
    sigma = PROFILE.tachometer.sigma_radps
    drawn = np.sqrt(sigma**2 - q**2 / 12) if not quantise else sigma
    np.testing.assert_allclose(tach.sigma_eff, drawn)
    np.testing.assert_allclose((v - 50.0).std(axis=0), drawn, rtol=0.02)
