"""Tests of vdps_hil.identification.feeder: estimates -> IdentInputs in the aux frame."""

from __future__ import annotations

import dataclasses as dc
import io
import math

import numpy as np
import pytest

from vdps_hil.estimation.estimates import Estimate, FilteredSignals
from vdps_hil.bus.samples import Sample
from vdps_hil.experiments.scoring import truth_at
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.identification.feeder import IdentFeeder
from vdps_hil.identification.config import load_ident_config
from vdps_hil.identification.problems import mass_regressor
from vdps_hil.model.frames import (compose_absolute, dcm_global_to_vehicle, decompose_vehicle, gravity_in_aux,
                                   skew)
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.record.decode import decode_recording
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.profiles import load_profile
from vdps_hil.units import GRAVITY_MPS2

G = GRAVITY_MPS2
MODEL = load_vehicle("sedan-model")


def estimate(t_ns=10_000_000, pos=(0, 0, 0), vel=(0, 0, 0), euler=(0, 0, 0), road=(0, 0)):
    """An Estimate from absolute quantities (psi_v and the vehicle angles by eq 4)."""
    phi_v, theta_v, psi_v = decompose_vehicle(*euler, *road)
    x = (*pos, *vel, *euler, *road, psi_v)
    return Estimate(t_ns, tuple(float(v) for v in x), (0.1,) * 12, (phi_v, theta_v, psi_v), (0.01,) * 3)


def filtered(rate=(0, 0, 0), accel=(0, 0, 0), wheels=(0,) * 4, steer=0.0, torque=(0,) * 4, susp=(0,) * 4):
    return FilteredSignals(0, tuple(map(float, rate)), tuple(map(float, accel)), tuple(map(float, wheels)),
                           (0.0,) * 4, tuple(map(float, susp)), (0.0,) * 4, tuple(map(float, torque)),
                           float(steer), {})


def imu(f, w=(0, 0, 0), t=0):
    return Sample(t, "imu", "imu", {"specific_force_mps2_x": f[0], "specific_force_mps2_y": f[1],
                                     "specific_force_mps2_z": f[2], "angular_rate_radps_x": w[0],
                                     "angular_rate_radps_y": w[1], "angular_rate_radps_z": w[2]})


def test_at_rest_on_a_level_road_gravity_balances_the_spring_forces():
    fd = IdentFeeder(MODEL)
    for _ in range(10):
        fd.observe(imu((0.0, 0.0, G)))
    inp = fd.inputs(estimate(), filtered())
    assert (inp.xdd_a_mps2, inp.ydd_a_mps2, inp.zdd_a_mps2) == pytest.approx((0, 0, 0), abs=1e-12)
    assert inp.gravity_aux_mps2 == pytest.approx((0.0, 0.0, -G), abs=1e-12)
    assert inp.slip_ratio == (0.0,) * 4 and inp.slip_angle_rad == (0.0,) * 4 and inp.wheel_angle_rad == (0.0,) * 4
    a = mass_regressor(inp, MODEL, load_ident_config()).a
    assert a[0, 0] == pytest.approx(G, abs=1e-12)  # eq 20: A = zdd_a - G_z


@pytest.mark.parametrize("bank,grade,heading", [(0.05, -0.03, 0.4), (-0.02, 0.04, -2.5), (0.0, 0.0, 1.0)])
def test_straight_at_constant_speed_on_a_banked_graded_road(bank, grade, heading):
    """Body parallel to the road, moving along its own x at 20 m/s: the aux-frame velocity is
    (20, 0, 0), every aux acceleration is 0 and G is eq 13's gravity; the accelerometer reads
    -g in body axes (specific force of a body at constant velocity)."""
    euler = compose_absolute(0.0, 0.0, heading, bank, grade)
    c = dcm_global_to_vehicle(*euler)
    v_g = c.T @ np.array([20.0, 0.0, 0.0])
    f_b = -(c @ np.array([0.0, 0.0, -G]))
    fd = IdentFeeder(MODEL)
    fd.observe(imu(f_b))
    inp = fd.inputs(estimate(vel=v_g, euler=euler, road=(bank, grade)), filtered(wheels=(20 / 0.31,) * 4))
    assert (inp.xd_a_mps, inp.yd_a_mps) == pytest.approx((20.0, 0.0), abs=1e-9)
    assert (inp.xdd_a_mps2, inp.ydd_a_mps2, inp.zdd_a_mps2) == pytest.approx((0, 0, 0), abs=1e-9)
    assert inp.gravity_aux_mps2 == pytest.approx(tuple(gravity_in_aux(bank, grade, heading, G)), abs=1e-12)
    assert inp.slip_ratio == pytest.approx((0.0,) * 4, abs=1e-12)
    assert inp.slip_angle_rad == pytest.approx((0.0,) * 4, abs=1e-12)


def test_steady_turn_has_constant_aux_velocity_components():
    """Flat steady turn, speed v, yaw rate r: the accelerometer reads the centripetal v r on y;
    eq 13's xdd_a - yd_a psid and ydd_a + xd_a psid equal the inertial acceleration, so the
    aux-frame component derivatives vanish and psid_v = r."""
    v, r, psi = 15.0, 0.3, 0.7
    fd = IdentFeeder(MODEL)
    fd.observe(imu((0.0, v * r, G)))
    inp = fd.inputs(estimate(vel=(v * math.cos(psi), v * math.sin(psi), 0.0), euler=(0.0, 0.0, psi)),
                    filtered(rate=(0.0, 0.0, r)))
    assert inp.psi_v_dot_radps == pytest.approx(r, abs=1e-12)
    assert (inp.xd_a_mps, inp.yd_a_mps) == pytest.approx((v, 0.0), abs=1e-9)
    assert (inp.xdd_a_mps2, inp.ydd_a_mps2, inp.zdd_a_mps2) == pytest.approx((0, 0, 0), abs=1e-9)
    # no side slip at the CG: the rear-right wheel centre (x_r, -t_r) moves with v + w x r_w =
    # (v + r t_r, r x_r), so alpha_3 = -atan(r x_r / (v + r t_r)) (core definition)
    x_r, t_r = -MODEL.geometry.l_r_m, MODEL.geometry.track_half_rear_m
    assert inp.slip_angle_rad[2] == pytest.approx(-math.atan(r * x_r / (v + r * t_r)), rel=1e-9)


def test_imu_rotation_and_lever_arm_are_undone():
    rpy = (0.02, -0.03, 0.05)
    arm = (0.4, -0.2, 0.3)
    veh = dc.replace(MODEL, mounting=dc.replace(MODEL.mounting, imu_rotation_rpy_rad=rpy, imu_lever_arm_m=arm))
    w, wd = np.array([0.1, -0.05, 0.4]), np.array([0.5, 0.2, -1.0])
    f_cg = np.array([0.7, 3.1, G])
    f_at_arm = f_cg + np.cross(wd, arm) + np.cross(w, np.cross(w, arm))
    f_sensor = dcm_global_to_vehicle(*rpy) @ f_at_arm  # body -> sensor
    fd, ref = IdentFeeder(veh), IdentFeeder(MODEL)
    fd.observe(imu(f_sensor))
    ref.observe(imu(f_cg))
    est, flt = estimate(), filtered(rate=w, accel=wd)
    a, b = fd.inputs(est, flt), ref.inputs(est, flt)
    assert (a.xdd_a_mps2, a.ydd_a_mps2, a.zdd_a_mps2) == pytest.approx((b.xdd_a_mps2, b.ydd_a_mps2, b.zdd_a_mps2),
                                                                      abs=1e-12)
    assert skew(w) @ np.array(arm) == pytest.approx(np.cross(w, arm))


def test_missing_data_gives_nan_inputs_not_errors():
    fd = IdentFeeder(MODEL)
    assert fd.inputs(None, filtered()) is None
    inp = fd.inputs(estimate(), filtered(rate=(math.nan,) * 3, wheels=(math.nan,) * 4, steer=math.nan))
    assert math.isnan(inp.xdd_a_mps2)  # no IMU sample since the last call
    assert all(math.isnan(v) for v in inp.slip_ratio)
    assert fd.counters["no_imu"] == 1 and fd.counters["incomplete"] == 1
    esc = imu((0.3, 0.1, math.nan))  # an ESC cluster has no f_z: g is substituted
    fd.observe(esc)
    assert fd.inputs(estimate(), filtered()).zdd_a_mps2 == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="model vehicle"):
        IdentFeeder(load_vehicle("sedan-truth"))


# ----------------------------------------------------------------- against the simulator's truth
@pytest.fixture(scope="module")
def zero_noise_paper():
    buf = io.BytesIO()
    Drive("paper", profile=load_profile("table1-susp1k").zero_noise(), seed=2, duration_s=4.0).run(buf)
    buf.seek(0)
    r = RecordingReader(buf)
    truth = {t: d["values"] for _, t, d in r.iter_messages(["/truth/state"])}  # test harness only
    return r, truth


def _truth_estimate(tv):
    keys = ("pos_e_m", "pos_n_m", "pos_u_m", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u", "roll_g_rad",
            "pitch_g_rad", "yaw_g_rad", "road_bank_rad", "road_grade_rad", "yaw_v_rad")
    x = tuple(float(tv[k]) for k in keys)
    return Estimate(int(tv["t_ns"]), x, (0.0,) * 12, (tv["roll_v_rad"], tv["pitch_v_rad"], tv["yaw_v_rad"]),
                    (0.0,) * 3)


def _truth_filtered(tv):
    v = lambda stem, n: tuple(float(tv[f"{stem}_{i}"]) for i in n)  # noqa: E731
    return FilteredSignals(int(tv["t_ns"]), v("rate_b_radps", "xyz"), v("angular_accel_b_radps2", "xyz"),
                           v("wheel_speed_radps", "1234"), v("wheel_accel_radps2", "1234"),
                           v("susp_deflection_m", "1234"), v("susp_deflection_rate_mps", "1234"),
                           v("wheel_torque_nm", "1234"), float(tv["steer_wheel_angle_rad"]), {})


def test_core_definitions_reproduce_the_simulators_slips_and_wheel_angles(zero_noise_paper):
    """Fed the truth state, the feeder's slips (the core's reduced-model kinematics) match the
    truth simulator's (unsprung DOF: the wheel centre also moves with H_dot); measured max
    differences 3.4e-5 (slip ratio) and 2.2e-4 rad (slip angle)."""
    _, truth = zero_noise_paper
    fd = IdentFeeder(MODEL)
    dl, da, dd = [], [], []
    for t, tv in sorted(truth.items()):
        if t < 500_000_000:
            continue
        fd.observe(imu([tv[f"specific_force_b_mps2_{a}"] for a in "xyz"]))
        inp = fd.inputs(_truth_estimate(tv), _truth_filtered(tv))
        dl += [inp.slip_ratio[i] - tv[f"slip_ratio_{i + 1}"] for i in range(4)]
        da += [inp.slip_angle_rad[i] - tv[f"slip_angle_rad_{i + 1}"] for i in range(4)]
        dd += [inp.wheel_angle_rad[i] - tv[f"road_wheel_angle_rad_{i + 1}"] for i in range(4)]
    assert max(map(abs, dl)) < 1e-4 and max(map(abs, da)) < 5e-4 and max(map(abs, dd)) < 1e-9


def test_the_chain_gives_the_identifier_what_the_truth_would(zero_noise_paper):
    """Zero-noise sensors through decode -> system -> feeder vs the feeder fed the truth (at the
    estimates' times); the tolerances are about twice the RMS differences the chain reaches
    (measured: xd 1.9 mm/s, yd 4.6 mm/s, zdd 0.002 and ydd 0.014 m/s^2, psid 0.4 mrad/s, slip
    1.1e-4, alpha 0.19 mrad, G 0.002 m/s^2)."""
    reader, truth = zero_noise_paper
    cfg = SystemConfig.for_profile(1000.0, 0.001, predict=False)
    system = VdpsSystem(MODEL, cfg, origin=DEFAULT_ORIGIN)
    got = []
    orig = system.feeder.inputs

    def spy(est, flt):
        inp = orig(est, flt)
        got.append(inp)
        return inp
    system.feeder.inputs = spy
    for s in decode_recording(reader):
        system.handle(s)
    ref = IdentFeeder(MODEL)
    diffs = {k: [] for k in ("xd", "yd", "zdd", "ydd", "psid", "slip", "alpha", "G")}
    for a in got:
        tv = truth_at(truth, a.t_ns)  # estimates are not all on the 100 Hz truth grid
        if a.t_ns < 1_000_000_000 or tv is None:
            continue
        ref.observe(imu([tv[f"specific_force_b_mps2_{x}"] for x in "xyz"], t=a.t_ns))
        b = ref.inputs(_truth_estimate(tv), _truth_filtered(tv))
        diffs["xd"].append(a.xd_a_mps - b.xd_a_mps)
        diffs["yd"].append(a.yd_a_mps - b.yd_a_mps)
        diffs["zdd"].append(a.zdd_a_mps2 - b.zdd_a_mps2)
        diffs["ydd"].append(a.ydd_a_mps2 - b.ydd_a_mps2)
        diffs["psid"].append(a.psi_v_dot_radps - b.psi_v_dot_radps)
        diffs["slip"] += [x - y for x, y in zip(a.slip_ratio, b.slip_ratio)]
        diffs["alpha"] += [x - y for x, y in zip(a.slip_angle_rad, b.slip_angle_rad)]
        diffs["G"] += [x - y for x, y in zip(a.gravity_aux_mps2, b.gravity_aux_mps2)]
    assert len(diffs["xd"]) > 250
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in diffs.items()}
    assert rms["xd"] < 0.005 and rms["yd"] < 0.01  # m/s
    assert rms["zdd"] < 0.005 and rms["ydd"] < 0.03  # m/s^2
    assert rms["psid"] < 0.001  # rad/s
    assert rms["slip"] < 3e-4 and rms["alpha"] < 5e-4
    assert rms["G"] < 0.004  # m/s^2: road angles within ~0.4 mrad


def test_vertical_struts_uses_the_body_z_specific_force_aux_the_road_normal():
    """Rolled body in a turn: A = zdd_a - G_z of eq 20 is f_z (body, along the struts) with
    "struts" and the road-normal component of the specific force with "aux"."""
    from vdps_hil.identification.feeder import FeederConfig

    phi_v = 0.04
    euler = compose_absolute(phi_v, 0.0, 0.3, 0.0, 0.0)
    f_b = np.array([0.0, 4.0, G])
    est = estimate(vel=(10.0, 0.0, 0.0), euler=euler)
    out = {}
    for mode in ("struts", "aux"):
        fd = IdentFeeder(MODEL, FeederConfig(vertical=mode))
        fd.observe(imu(f_b))
        inp = fd.inputs(est, filtered())
        out[mode] = inp.zdd_a_mps2 - inp.gravity_aux_mps2[2]
    c_va = dcm_global_to_vehicle(*euler).T  # flat road: aux z = global z
    assert out["struts"] == pytest.approx(G, abs=1e-12)
    assert out["aux"] == pytest.approx((c_va @ f_b)[2], abs=1e-12)
    assert out["aux"] - out["struts"] == pytest.approx(4.0 * math.sin(phi_v) + G * (math.cos(phi_v) - 1), abs=1e-9)
    with pytest.raises(ValueError, match="vertical"):
        FeederConfig(vertical="up")


def test_steering_and_torques_are_extrapolated_to_the_estimate_time():
    """100 Hz CAN inputs held between frames lag by up to a period; the feeder carries them to the
    estimate's instant from their last two samples (a ramp exactly; at most 50 ms ahead)."""
    from dataclasses import replace

    from vdps_hil.identification.feeder import FeederConfig

    def ramp_feeder(cfg=None):
        fd = IdentFeeder(MODEL, cfg)
        for k, t in enumerate((1_000_500_000, 1_010_500_000)):  # frames 0.5 ms after the 10 ms grid
            fd.observe(Sample(t, "can", "steer", {"steer_wheel_angle_rad": 0.1 + 0.01 * k}))
            fd.observe(Sample(t, "can", "wheel_torque", {f"wheel_torque_nm_{i}": 100.0 * i + 10.0 * k
                                                          for i in range(1, 5)}))
        fd.observe(imu((0.0, 0.0, GRAVITY_MPS2), t=1_020_000_000))
        return fd

    held = filtered(wheels=(80.0,) * 4, steer=0.11, torque=(110.0, 210.0, 310.0, 410.0))
    est = estimate(t_ns=1_020_000_000, vel=(25.0, 0.0, 0.0))
    inp = ramp_feeder().inputs(est, held)
    frac = (1_020_000_000 - 1_010_500_000) / 10_000_000
    assert inp.wheel_torque_nm == pytest.approx(tuple(100.0 * i + 10.0 + 10.0 * frac for i in range(1, 5)), abs=1e-9)
    d_ex = inp.wheel_angle_rad[0]
    off = ramp_feeder(replace(FeederConfig(), extrapolate_inputs=False)).inputs(est, held)
    assert off.wheel_torque_nm == pytest.approx((110.0, 210.0, 310.0, 410.0))
    # the front wheel angle follows the extrapolated steering (0.11 + 0.0095), not the held 0.11
    assert d_ex > off.wheel_angle_rad[0]
    ratio = MODEL.geometry.steer_ratio
    assert (d_ex - off.wheel_angle_rad[0]) == pytest.approx(0.01 * frac / ratio, rel=0.05)
    # too old: the held values
    late = ramp_feeder().inputs(estimate(t_ns=1_100_000_000, vel=(25.0, 0.0, 0.0)), held)
    assert late.wheel_torque_nm == pytest.approx((110.0, 210.0, 310.0, 410.0))


def _susp(t, h=0.01):
    return Sample(t, "can", "suspension", {f"susp_deflection_m_{i}": h for i in range(1, 5)})


def test_the_suspension_interval_is_the_longer_of_the_sampling_interval_and_the_age():
    """``susp_interval_s`` (the strut-force rows' gate, ``problems.suspension_gate``): inf before
    two suspension samples; then max(last interval, age of the newest at the estimate's time).
    Invalid, all-NaN and repeated samples do not count."""
    fd = IdentFeeder(MODEL)
    fd.observe(imu((0.0, 0.0, G), t=1_000_000_000))
    fd.observe(_susp(1_000_000_000))
    assert fd.inputs(estimate(t_ns=1_000_000_000), filtered()).susp_interval_s == math.inf
    fd.observe(_susp(1_001_000_000))  # 1 kHz
    assert fd.inputs(estimate(t_ns=1_001_000_000), filtered()).susp_interval_s == pytest.approx(0.001)
    assert fd.inputs(estimate(t_ns=1_006_000_000), filtered()).susp_interval_s == pytest.approx(0.005)  # age
    fd.observe(_susp(1_001_000_000))  # repeated stamp
    fd.observe(_susp(1_002_000_000, h=math.nan))  # no deflection
    fd.observe(Sample(1_003_000_000, "can", "suspension", dict(_susp(0).fields), valid=False))
    assert fd.inputs(estimate(t_ns=1_001_000_000), filtered()).susp_interval_s == pytest.approx(0.001)
    fd.observe(_susp(2_001_000_000))  # 1 Hz (Table 1 as printed)
    assert fd.inputs(estimate(t_ns=2_001_000_000), filtered()).susp_interval_s == pytest.approx(1.0)


def test_frames_are_bit_equal_to_the_frames_module_products(rng):
    """``_frames`` (the three rotation chains in stacked matmuls) gives C_g^v, C_g^a and G of
    ``frames.dcm_global_to_vehicle``, ``dcm_road_to_aux @ dcm_global_to_road`` and
    ``inputs.gravity_aux_mps2`` bit for bit."""
    from vdps_hil.identification.feeder import _frames
    from vdps_hil.identification.inputs import gravity_aux_mps2
    from vdps_hil.model.frames import dcm_global_to_road, dcm_road_to_aux

    for _ in range(300):
        a = rng.uniform(-1, 1, 6) * np.array([0.3, 0.3, 3.1, 0.1, 0.1, 3.1])
        c_gv, c_ga, grav = _frames(*a)
        assert np.array_equal(c_gv, dcm_global_to_vehicle(*a[:3]))
        assert np.array_equal(c_ga, dcm_road_to_aux(a[5]) @ dcm_global_to_road(a[3], a[4]))
        assert grav == gravity_aux_mps2(a[3], a[4], a[5])
