"""Estimator pipeline on synthetic Table-1 sample streams (no simulator): accuracy, exact
replay of a live run, origin at the first fix, bad input counted not fatal, truth refused,
reduced sensor sets, per-sensor latency, NaN reset and re-initialisation, alpha-beta outputs."""

import dataclasses
import functools
import math

import numpy as np
import pytest

from vdps_hil.bus.samples import Sample
from vdps_hil.experiments import synthetic as syn
from vdps_hil.estimation.aiding_monitor import AidingChecks
from vdps_hil.estimation.ekf_config import EkfConfig, SensorSet
from vdps_hil.estimation.estimates import Estimate, Innovation
from vdps_hil.model.frames import dcm_gv
from vdps_hil.estimation.pipeline import EstimatorPipeline
from vdps_hil.estimation.pipeline_config import Latencies, PipelineConfig
from vdps_hil.estimation.states import STATE_NAMES, States
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.model.params import load_vehicle

VEH = load_vehicle("sedan-model")
MAN = syn.Maneuver(duration_s=20.0)
DEG = math.pi / 180


@functools.lru_cache(maxsize=None)
def _samples(seed=1, **variant):
    data = syn.make_sensor_data(MAN, VEH, seed=seed)
    return tuple(syn.to_samples(data, DEFAULT_ORIGIN, **variant))


def _run(samples, config=None, origin=DEFAULT_ORIGIN):
    p = EstimatorPipeline(VEH, config, origin=origin)
    out = []
    for s in samples:
        out.extend(p.handle(s))
    return p, out


def _errors(out):
    est = [o for o in out if isinstance(o, Estimate)]
    t = np.array([e.t_ns for e in est]) / 1e9
    x = np.array([e.x for e in est])
    e = x - syn.truth(MAN, t).x_full
    for i in (States.PSI_G, States.PSI_V):
        e[:, i] = (e[:, i] + math.pi) % (2 * math.pi) - math.pi
    return t, e, np.array([e.sigma for e in est])


def test_paper_sensor_set_accuracy_and_consistent_innovations():
    """Constant-road filter (the synthetic road is one plane): NIS / dof averages to 1 within
    0.2 for the 5 Hz GNSS kinds (75 epochs each) and within 0.6 for y1_sus (15 epochs)."""
    p, out = _run(_samples(), PipelineConfig(ekf=EkfConfig(road_angle_rw=1e-5)))
    t, e, s = _errors(out)
    sel = t >= 5.0
    assert np.hypot(*np.sqrt((e[sel, 0:2] ** 2).mean(0))) < 0.6
    assert np.sqrt((e[sel, 6:9] ** 2).mean(0)).max() < 0.15 * DEG
    assert np.abs(e[-1, 9:11]).max() < 0.1 * DEG  # road bank and grade
    assert (np.abs(e[sel, :11]) < 4 * s[sel, :11]).all()
    inn = [o for o in out if isinstance(o, Innovation)]
    for kind, dof, tol in (("gnss_pos", 3, 0.2), ("gnss_att", 3, 0.2), ("y1_sus", 2, 0.6)):
        nis = np.array([o.nis for o in inn if o.kind == kind and o.t_ns > 5e9])
        assert abs(nis.mean() / dof - 1.0) < tol, (kind, nis.mean())
    assert all(v == 0 for v in p.rejected().values())
    reps = p.observability_reports
    assert len(reps) == 1 and reps[0][2].rank == 11


def test_replay_reproduces_a_live_run_exactly():
    samples = _samples()[:40000]
    live, out_live = _run(samples)
    assert len(live.input_log) == len(samples)
    replayed, out_replay = EstimatorPipeline.replay(VEH, None, live.input_log, origin=DEFAULT_ORIGIN)
    assert len(out_live) == len(out_replay) > 1000
    assert all(repr(a) == repr(b) for a, b in zip(out_live, out_replay))
    assert repr(live.filtered()) == repr(replayed.filtered())


def test_origin_at_first_valid_fix():
    samples = list(_samples()[:3000])
    bad = Sample(0, "gnss", "gnss_pos", {"gnss_lat_deg": 24.0, "gnss_lon_deg": 121.0, "gnss_alt_m": 10.0,
                                         "gnss_fix_quality": 0.0})
    p, out = _run([bad] + samples, origin=None)
    first = next(s for s in samples if s.kind == "gnss_pos")
    assert p.origin.lat_deg == first.fields["gnss_lat_deg"] and p.origin.lon_deg == first.fields["gnss_lon_deg"]
    assert p.rejected()["gnss_pos"] == 1
    est = next(o for o in out if isinstance(o, Estimate))
    # the antenna is at the origin at the first fix: CG = -(C_g^v)^T l (|.| = |l|)
    assert abs(np.linalg.norm(est.x[0:3]) - np.linalg.norm(VEH.mounting.gnss_lever_arm_m)) < 1e-9


def test_bad_input_is_counted_never_fatal():
    good = list(_samples()[:5000])
    junk = [
        Sample(1_000_000_000, "imu", "imu", {"specific_force_mps2_x": math.nan}),
        Sample(1_000_000_001, "imu", "imu", {}, valid=False),
        Sample(1_000_000_002, "can.vdps", "suspension", {"susp_deflection_m_1": 0.0}),
        Sample(1_000_000_003, "gnss", "gnss_att", {}),
        Sample(1_000_000_004, "gnss", "gnss_vel", {"gnss_speed_mps": -3.0}),
        Sample(1_000_000_005, "can.vdps", "wheel_speed", {"wheel_speed_radps_1": math.inf}),
        Sample(1_000_000_006, "can.vdps", "wheel_torque", {}),
        Sample(1_000_000_007, "can.vdps", "steer", {"steer_wheel_angle_rad": math.nan}),
        Sample(1_000_000_008, "x", "something_else", {"a": 1.0}),
        Sample(1_000_000_009, "/truth/state", "truth_state", {"x": 0.0}),
    ]
    samples = sorted(good + junk, key=lambda s: s.t_ns)
    p, out = _run(samples)
    c = p.counters
    assert c["ignored"] == 1 and c["truth_ignored"] == 1 and c["invalid"] == 1
    rej = p.rejected()
    assert rej["imu"] == 2 and rej["suspension"] == 1 and rej["gnss_att"] == 1 and rej["gnss_vel"] == 1
    assert rej["wheel_speed"] == 1 and rej["wheel_torque"] == 1 and rej["steer"] == 1
    assert p.estimate() is not None and np.isfinite(p.estimate().x).all()


def test_truth_vehicle_file_refused():
    with pytest.raises(ValueError, match="model vehicle"):
        EstimatorPipeline(load_vehicle("sedan-truth"))


def test_esc_cluster_and_single_antenna_without_suspension():
    cfg = PipelineConfig(ekf=EkfConfig(sensors=SensorSet(imu="esc3", gnss="single_antenna", suspension=False)))
    p, out = _run(_samples(imu_fields="esc3", gnss="single_antenna", suspension=False), cfg)
    assert p.ekf.layout.n == 9
    t, e, s = _errors(out)
    sel = t >= 5.0
    assert np.hypot(*np.sqrt((e[sel, 0:2] ** 2).mean(0))) < 1.5
    assert np.sqrt((e[sel, States.PSI_G] ** 2).mean()) < 2.0 * DEG
    assert np.isfinite(np.array([o.x for o in out if isinstance(o, Estimate)])).all()
    assert p.counters["ekf"]["updates"]["gnss_vel"]["accepted"] > 90


def test_per_sensor_latency_compensated_by_the_history():
    """GNSS samples stamped 80 ms after measurement (and arriving in that order): with
    ``Latencies(gnss_s=0.08)`` the result matches the timely stream (< 2 cm); without, the
    position lags by ~ 25 m/s x 0.08 s."""
    timely = _samples()
    late = sorted((dataclasses.replace(s, t_ns=s.t_ns + 80_000_000) if s.kind.startswith("gnss") else s
                   for s in timely), key=lambda s: s.t_ns)
    p0, out0 = _run(timely)
    p1, out1 = _run(late, PipelineConfig(latencies=Latencies(gnss_s=0.08)))
    p2, out2 = _run(late)
    assert p1.counters["ekf"]["delayed_updates"] > 150
    e0, e1, e2 = p0.estimate(), p1.estimate(), p2.estimate()
    assert np.linalg.norm(np.subtract(e1.x[0:3], e0.x[0:3])) < 0.02
    t, err2, _ = _errors(out2)
    assert np.hypot(*np.sqrt((err2[t >= 5.0, 0:2] ** 2).mean(0))) > 1.0


def test_nan_reset_then_reinitialised_from_the_next_fix():
    samples = _samples()[:30000]
    p = EstimatorPipeline(VEH, origin=DEFAULT_ORIGIN)
    for k, s in enumerate(samples):
        p.handle(s)
        if k == 15000:
            p.ekf.reset("nan")
    c = p.counters["ekf"]
    assert c["nan_resets"] == 1 and c["initializations"] == 2
    assert p.ekf.initialized


def test_alpha_beta_outputs_for_the_identifier():
    samples = list(_samples())
    samples.append(Sample(samples[-1].t_ns, "can.vdps", "wheel_torque",
                          {f"wheel_torque_nm_{i}": 10.0 * i for i in range(1, 5)}))
    samples.append(Sample(samples[-1].t_ns, "can.vdps", "steer", {"steer_wheel_angle_rad": 0.3}))
    p, _ = _run(samples)
    f = p.filtered()
    tr = syn.truth(MAN, np.array([f.t_ns / 1e9]))
    w_speed = np.linalg.norm(tr.x_full[0, 3:6]) / VEH.tire.rolling_radius_m
    assert np.abs(np.array(f.wheel_speed_radps) - w_speed).max() < 0.05
    np.testing.assert_allclose(f.angular_rate_radps, tr.omega_b[0], atol=0.01)
    # angular acceleration: the truth delayed by the reported derivative lag (~64 ms at 5 Hz)
    lag = f.lags_s["angular_accel"]
    assert abs(lag - 0.0632) < 1e-3
    tr_lag = syn.truth(MAN, np.array([f.t_ns / 1e9 - lag]))
    np.testing.assert_allclose(f.angular_accel_radps2, tr_lag.omega_dot_b[0], atol=0.05)
    assert f.wheel_torque_nm == (10.0, 20.0, 30.0, 40.0) and f.steer_wheel_angle_rad == 0.3
    assert all(math.isfinite(v) for v in f.susp_rate_mps)


def _imu_in_sensor_frame(samples, rot_rpy=(0.0, 0.0, 0.0), arm=(0.0, 0.0, 0.0)):
    """Re-express the IMU samples as a sensor mounted with rotation ``rot_rpy`` (body ->
    sensor) at lever arm ``arm`` from the CG (truth rotational kinematics of the manoeuvre)."""
    c_bs = dcm_gv(*rot_rpy)
    imu = [s for s in samples if s.kind == "imu"]
    tr = syn.truth(MAN, np.array([s.t_ns for s in imu]) / 1e9 - 0.5e-3)
    arm = np.asarray(arm, dtype=float)
    f = np.array([[s.fields[f"specific_force_mps2_{a}"] for a in "xyz"] for s in imu])
    w = np.array([[s.fields[f"angular_rate_radps_{a}"] for a in "xyz"] for s in imu])
    wt, wd = tr.omega_b[: len(imu)], tr.omega_dot_b[: len(imu)]
    f = f + np.cross(wd, arm) + np.cross(wt, np.cross(wt, arm))  # all samples at once, row by row
    f, w = f @ c_bs.T, w @ c_bs.T
    moved = iter([dataclasses.replace(s, fields={**{f"specific_force_mps2_{a}": float(v) for a, v in zip("xyz", fk)},
                                                 **{f"angular_rate_radps_{a}": float(v) for a, v in zip("xyz", wk)}})
                  for s, fk, wk in zip(imu, f, w)])
    return [next(moved) if s.kind == "imu" else s for s in samples]


def test_imu_mounting_rotation_and_lever_arm_from_the_model_file():
    base = list(_samples())
    p0, _ = _run(base)
    rot = (0.02, -0.03, 0.05)
    veh_rot = dataclasses.replace(VEH, mounting=dataclasses.replace(VEH.mounting, imu_rotation_rpy_rad=rot))
    p1 = EstimatorPipeline(veh_rot, origin=DEFAULT_ORIGIN)
    for s in _imu_in_sensor_frame(base, rot_rpy=rot):
        p1.handle(s)
    np.testing.assert_allclose(p1.estimate().x, p0.estimate().x, atol=1e-6)
    arm = (0.8, 0.3, -0.2)
    veh_arm = dataclasses.replace(VEH, mounting=dataclasses.replace(VEH.mounting, imu_lever_arm_m=arm))
    p2 = EstimatorPipeline(veh_arm, origin=DEFAULT_ORIGIN)
    out2 = []
    for s in _imu_in_sensor_frame(base, arm=arm):
        out2.extend(p2.handle(s))
    t, e, _ = _errors(out2)
    assert np.hypot(*np.sqrt((e[t >= 5.0, 0:2] ** 2).mean(0))) < 0.6
    assert np.sqrt((e[t >= 5.0, 3:6] ** 2).mean(0)).max() < 0.15


def test_output_types_serialise():
    p, out = _run(_samples()[:6000])
    est = next(o for o in out if isinstance(o, Estimate))
    inn = next(o for o in out if isinstance(o, Innovation))
    assert est.get(States.THETA_R) == est.get("theta_r_rad") == est.x[10]
    assert est.sigma_of("x_g_m") == est.sigma[0] > 0
    d = est.to_json()
    assert set(d["state"]) == set(STATE_NAMES) and set(d["vehicle_angles_rad"]) == {"phi_v", "theta_v", "psi_v"}
    j = inn.to_json()
    assert j["kind"] in {"gnss_pos", "gnss_att", "y1_sus", "y2_sus_rate"} and j["dof"] == len(j["innovation"])
    with pytest.raises(ValueError):
        PipelineConfig(predict_period_s=0.0)


# ---------------------------------------------------------------------------------------------
# real-car extensions: wheel speed, non-holonomic constraint, IMU bias states, re-acquisition

REAL_ROWS = dict(gyro_bias=True, accel_bias=True, wheel_speed=True, wheel_scale_state=True, nonholonomic=True)
ESC_SET = SensorSet(imu="esc3", gnss="single_antenna", suspension=False)
BIAS_GZ, BIAS_AX = 0.4 * DEG, 0.15  # injected ESC yaw-rate [rad/s] and ACCEL_X [m/s^2] biases
OUTAGE = (18.0, 28.0)


@functools.lru_cache(maxsize=None)
def _esc_outage_samples():
    """30 s ESC-cluster drive (yaw rate, a_x, a_y; single antenna; wheel speeds from a tyre 1 %
    larger than the model file's radius) with constant biases and a 10 s GNSS outage."""
    man = syn.Maneuver(duration_s=30.0)
    data = syn.make_sensor_data(man, VEH, seed=3, gnss_outage_s=OUTAGE,
                                wheel_radius_m=VEH.tire.rolling_radius_m * 1.01)
    out = []
    for s in syn.to_samples(data, DEFAULT_ORIGIN, imu_fields="esc3", gnss="single_antenna", suspension=False):
        if s.kind == "imu":
            f = dict(s.fields)
            f["angular_rate_radps_z"] += BIAS_GZ
            f["specific_force_mps2_x"] += BIAS_AX
            s = dataclasses.replace(s, fields=f)
        out.append(s)
    return man, tuple(out)


def _outage_end(man, out):
    est = [o for o in out if isinstance(o, Estimate)]
    t = np.array([e.t_ns for e in est]) / 1e9
    k = int(np.searchsorted(t, OUTAGE[1] - 0.01))
    x, s = np.array(est[k].x), np.array(est[k].sigma)
    tr = syn.truth(man, np.array([t[k]])).x_full[0]
    return float(np.hypot(*(x[0:2] - tr[0:2]))), float(np.hypot(*s[0:2])), \
        float(np.hypot(*x[3:5]) - np.hypot(*tr[3:5]))


def test_wheel_speed_nhc_and_bias_states_through_a_gnss_outage():
    """ESC cluster + single antenna + wheel speeds, biased yaw rate (0.4 deg/s) and ACCEL_X
    (0.15 m/s^2), tyre 1 % larger than the model file says. The real-car rows and states
    estimate the biases (within 0.05 deg/s, 0.03 m/s^2 and 3 sigma) and the wheel-speed scale
    (k_w = 1/1.01 - 1 within 0.002) before the outage; at the end of the 10 s outage the position
    error is < 2.5 m and < 3 sigma, < 30 % of the plain filter's, and the speed error < 0.1 m/s."""
    man, samples = _esc_outage_samples()
    p0, out0 = _run(samples, PipelineConfig(ekf=EkfConfig(sensors=ESC_SET)))
    p1, out1 = _run(samples, PipelineConfig(ekf=EkfConfig(sensors=ESC_SET, **REAL_ROWS)))
    e0, _, _ = _outage_end(man, out0)
    e1, s1, ds1 = _outage_end(man, out1)
    aug = p1.augmented_state()
    assert set(aug) == {"gyro_bias_z_radps", "accel_bias_x_mps2", "accel_bias_y_mps2", "wheel_speed_scale"}
    for name, truth, tol in (("gyro_bias_z_radps", BIAS_GZ, 0.05 * DEG), ("accel_bias_x_mps2", BIAS_AX, 0.03),
                             ("wheel_speed_scale", 1 / 1.01 - 1, 0.002)):
        v, s = aug[name]
        assert abs(v - truth) < tol and abs(v - truth) < 3 * s, (name, v, s)
    assert e1 < 2.5 and e1 < 3 * s1 and e1 < 0.3 * e0, (e1, s1, e0)
    assert abs(ds1) < 0.1
    c = p1.counters["ekf"]["updates"]
    assert c["wheel_speed"]["accepted"] > 250 and c["nhc"]["accepted"] > 100
    assert c["wheel_speed"]["gated"] == 0 and c["nhc"]["gated"] == 0
    assert p0.ekf.layout.n == 9 and p1.ekf.layout.n == 13


def test_wheel_outliers_and_hard_braking_are_left_out():
    """A locked front-right wheel for 2 s is dropped from the mean (counted, the update still
    made from the other three); a 0.2 s spike of all four wheels (|wheel accel| > 4 m/s^2) skips
    the updates; nothing is gated and the speed stays within 0.1 m/s of the truth."""
    man, samples = _esc_outage_samples()
    out = []
    for s in samples:
        t = s.t_ns / 1e9
        if s.kind == "wheel_speed" and 5.0 <= t < 7.0:
            s = dataclasses.replace(s, fields={**s.fields, "wheel_speed_radps_2": 0.0})
        elif s.kind == "wheel_speed" and 9.0 <= t < 9.2:
            s = dataclasses.replace(s, fields={k: v * 1.2 for k, v in s.fields.items()})
        out.append(s)
    p, res = _run(out, PipelineConfig(ekf=EkfConfig(sensors=ESC_SET, **REAL_ROWS)))
    c = p.counters
    assert c["wheel_outliers"] >= 15 and c["wheel_accel_skipped"] >= 1
    assert c["ekf"]["updates"]["wheel_speed"]["gated"] == 0
    t, e, _ = _errors(res)
    sel = (t > 4.0) & (t < OUTAGE[0])
    speed_err = np.hypot(*(np.array([o.x for o in res if isinstance(o, Estimate)])[sel, 3:5].T)) \
        - np.hypot(*syn.truth(man, t[sel]).x_full[:, 3:5].T)
    assert np.abs(speed_err).max() < 0.1


def test_reacquires_after_persistent_gating():
    """From 10 s on every fix is 40 m east of the truth (a jump the filter gates). With the
    re-acquisition rule alone (``reacquire_after_gated=5``, inflation off): after five gated fixes
    position, velocity and yaw are reset to the fixes (counted once), later fixes are accepted
    and the estimate follows the shifted fixes (< 1.5 m off them at the end)."""
    shifted = _shifted_fixes()
    p, out = _run(shifted, PipelineConfig(reacquire_after_gated=5, aiding_checks=AidingChecks(inflate_after_gated=0)))
    c = p.counters
    assert c["reacquisitions"] == 1 and c["ekf"]["reacquisitions"] == 1 and c["inflations"] == 0
    inn = [o for o in out if isinstance(o, Innovation) and o.kind == "gnss_pos"]
    statuses = [o.status for o in inn if o.t_ns >= 10e9]
    assert statuses[:5] == ["gated"] * 5 and all(s == "accepted" for s in statuses[5:])
    t, e, _ = _errors(out)
    assert abs(e[-1, 0] - 40.0) < 1.5 and abs(e[-1, 1]) < 1.5
    with pytest.raises(ValueError):
        PipelineConfig(reacquire_after_gated=-1)
    p_off, _ = _run(shifted, PipelineConfig(aiding_checks=AidingChecks(inflate_after_gated=0)))
    assert p_off.counters["reacquisitions"] == 0 and p_off.rejected()["ekf.gnss_pos"] > 40  # locked out


def _shifted_fixes():
    shifted = []
    for s in _samples():
        if s.kind == "gnss_pos" and s.t_ns >= 10_000_000_000:
            east = DEFAULT_ORIGIN.to_geodetic(np.array([40.0, 0.0, 0.0]))[1] - DEFAULT_ORIGIN.lon_deg
            s = dataclasses.replace(s, fields={**s.fields, "gnss_lon_deg": s.fields["gnss_lon_deg"] + east})
        shifted.append(s)
    return shifted


def test_default_gate_cannot_lock_the_filter_out_of_its_fixes():
    """Issue 20 (the gate's lock-out): the same 40 m jump with the defaults. The aiding monitor
    inflates the position after the third gated fix in a row and accepts it (``aiding_monitor``):
    the estimate follows the fixes (< 1.5 m at the end) and no later fix is gated. (Before, the
    default gated every fix to the end of the drive.)"""
    p, out = _run(_shifted_fixes())
    assert p.counters["inflations"] >= 1
    statuses = [o.status for o in out if isinstance(o, Innovation) and o.kind == "gnss_pos" and o.t_ns >= 11e9]
    assert statuses and all(s == "accepted" for s in statuses)
    t, e, _ = _errors(out)
    assert abs(e[-1, 0] - 40.0) < 1.5 and abs(e[-1, 1]) < 1.5


def test_separate_gnss_velocity_latency():
    """Speed/course samples measured 0.1 s before the positions (a receiver whose velocities lag,
    as the RTK drive's .pos): ``Latencies(gnss_vel_s=0.1)`` matches the timely stream (< 2 cm),
    one shared latency does not."""
    base = _samples(imu_fields="esc3", gnss="single_antenna", suspension=False)[:60000]
    cfg = dict(ekf=EkfConfig(sensors=ESC_SET))
    late = sorted((dataclasses.replace(s, t_ns=s.t_ns + 100_000_000) if s.kind == "gnss_vel" else s for s in base),
                  key=lambda s: s.t_ns)
    p0, _ = _run(base, PipelineConfig(**cfg))
    p1, _ = _run(late, PipelineConfig(latencies=Latencies(gnss_vel_s=0.1), **cfg))
    p2, _ = _run(late, PipelineConfig(**cfg))
    assert Latencies(gnss_s=0.2).gnss_vel_effective_s == 0.2
    d1 = np.linalg.norm(np.subtract(p1.estimate().x[0:6], p0.estimate().x[0:6]))
    d2 = np.linalg.norm(np.subtract(p2.estimate().x[0:6], p0.estimate().x[0:6]))
    assert d1 < 0.02 < d2


def test_wheel_speed_half_frames_are_not_rejects():
    """The chassis bus carries the four wheel speeds in two frames (front, rear): each half is a
    good sample, not a reject; a half with a bad value and a sample with no wheel speed are.
    The filtered wheel speeds equal those of the same values in four-wheel samples."""
    rng = np.random.default_rng(4)
    halves, wholes = [], []
    for k in range(200):
        t = 1_000_000 * k
        w = (20.0 + 0.01 * k + 0.02 * rng.standard_normal(4)).tolist()
        halves += [Sample(t, "can.vdps", "wheel_speed", {"wheel_speed_radps_1": w[0], "wheel_speed_radps_2": w[1],
                                                         "seq_counter": float(k % 256)}),
                   Sample(t, "can.vdps", "wheel_speed", {"wheel_speed_radps_3": w[2], "wheel_speed_radps_4": w[3],
                                                         "seq_counter": float(k % 256)})]
        wholes.append(Sample(t, "can.vdps", "wheel_speed", dict(zip(
            [f"wheel_speed_radps_{i}" for i in range(1, 5)], w))))
    p_half, _ = _run(halves)
    p_whole, _ = _run(wholes)
    assert p_half.rejected()["wheel_speed"] == 0
    assert p_half.filtered().wheel_speed_radps == p_whole.filtered().wheel_speed_radps
    assert p_half.filtered().wheel_accel_radps2 == p_whole.filtered().wheel_accel_radps2
    bad = [Sample(200_000_000, "can.vdps", "wheel_speed", {"wheel_speed_radps_3": math.nan, "wheel_speed_radps_4": 1.0}),
           Sample(201_000_000, "can.vdps", "wheel_speed", {"seq_counter": 3.0})]
    p_bad, _ = _run(halves + bad)
    assert p_bad.rejected()["wheel_speed"] == 2


def _imu_late_by_chunks(samples, chunk_ns=5_000_000):
    """Live arrival order: the IMU's samples come in read chunks, each after the other sensors'
    samples of its window (a serial read window late), everything else on time."""
    def key(s):
        if s.kind == "imu":
            return ((s.t_ns // chunk_ns + 1) * chunk_ns, 1)
        return (s.t_ns, 0)
    return sorted(samples, key=key)


def test_measurements_wait_for_the_imu_up_to_their_time():
    """A measurement that arrives before the IMU samples up to its time is held until they have
    arrived: the IMU-late arrival order gives exactly the outputs of the time order (measurements
    first at equal times). Without the hold (imu_hold_s = 0) the filter advances on a stale IMU
    mean and the estimates differ."""
    samples = list(_samples()[:12000])
    in_time = sorted(samples, key=lambda s: (s.t_ns, s.kind == "imu"))
    late = _imu_late_by_chunks(samples)
    assert late != in_time
    p_ref, out_ref = _run(in_time)
    p_late, out_late = _run(late)
    out_late += p_late.finish()
    assert p_late.counters["held"] >= 50 and p_late.counters["hold_expired"] == 0
    inn = lambda out: [(o.t_ns, o.kind, o.status, o.innovation) for o in out if isinstance(o, Innovation)]
    assert len(inn(out_ref)) > 50 and inn(out_late) == inn(out_ref)
    assert p_late.estimate() == p_ref.estimate()
    p_old, out_old = _run(late, PipelineConfig(imu_hold_s=0.0))
    assert p_old.counters["held"] == 0
    assert max(abs(a - b) for a, b in zip(p_old.estimate().x, p_ref.estimate().x)) > 1e-6


def test_held_measurements_are_released_when_the_imu_stops():
    """The IMU stops at 4 s: the GNSS and suspension samples after it wait at most imu_hold_s of
    sample time, then go on (counted), so the filter still takes the GNSS updates; what is held
    at the end of the input goes with finish()."""
    samples = [s for s in _samples()[:12000] if not (s.kind == "imu" and s.t_ns > 4_000_000_000)]
    last = max(i for i, s in enumerate(samples) if s.kind == "gnss_pos")
    p, out = _run(samples[:last + 1], PipelineConfig(imu_hold_s=0.05))
    c = p.counters
    assert c["hold_expired"] >= 15 and c["holding"] >= 1
    assert [o for o in out if isinstance(o, Innovation) and o.kind == "gnss_pos" and o.t_ns > 4.5e9]
    tail = p.finish()
    assert p.counters["holding"] == 0 and p.counters["hold_expired"] == c["hold_expired"]
    assert any(isinstance(o, Innovation) and o.kind == "gnss_pos" for o in tail)
