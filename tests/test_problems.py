"""The four identification problems (eq 20-23), forces and moments, config and Identifier.

The synthetic data are built from eq 13-17 by an independent forward model written here
(vector cross products, rotation matrices, the vector Euler equation I wd + w x I w = M), not
by inverting the regressors under test."""

import dataclasses
import json
import math
import warnings

import numpy as np
import pytest

from vdps_hil.identification.problems import (
    PROBLEM_NAMES, PROBLEM_PARAMS, IdentConfigError, IdentInputs, Identifier, balanced_weighting,
    body_moments_nm, gravity_aux_mps2, inertia_regressor, load_ident_config, parse_ident_config,
    suspension_forces_n, DEFAULT_CONFIG_PATH)
from vdps_hil.identification.rls import WeightedRLS
from vdps_hil.model.frames import c_omega_inv
from vdps_hil.model.params import PARAM_NAMES, load_vehicle
from vdps_hil.units import GRAVITY_MPS2

MODEL = load_vehicle("sedan-model", "model")
# "True" parameters of the synthetic vehicle (test inputs, of the order of a mid-size sedan)
TRUE = dataclasses.replace(
    MODEL.params, mass_kg=1600.0, inertia_x_kgm2=550.0, inertia_y_kgm2=2400.0, inertia_z_kgm2=2700.0,
    tracking_stiffness_1_n=80000.0, tracking_stiffness_2_n=85000.0, tracking_stiffness_3_n=75000.0,
    tracking_stiffness_4_n=90000.0, cornering_stiffness_front_nprad=120000.0,
    cornering_stiffness_rear_nprad=170000.0)
G = GRAVITY_MPS2


def _weak_prior_config(**general):
    cfg = load_ident_config()
    probs = {n: dataclasses.replace(cfg.problem(n), prior_rel_sigma=1e6) for n in PROBLEM_NAMES}
    return dataclasses.replace(cfg, **probs, **general)


def _forward(rng, k, true=TRUE, ackermann=True, pitch_scale=1.0, **override):
    """One consistent IdentInputs from random excitation and eq 13-17 with ``true``."""
    geo, r, iw = MODEL.geometry, MODEL.tire.rolling_radius_m, MODEL.tire.wheel_inertia_kgm2
    speed = rng.uniform(10.0, 30.0)
    yd, psid = rng.normal(0.0, 0.5), rng.normal(0.0, 0.2)
    g_aux = gravity_aux_mps2(rng.normal(0, 0.03), rng.normal(0, 0.03), rng.uniform(-math.pi, math.pi))
    h = rng.normal(0.0, 0.02, 4)
    hd = rng.normal(0.0, 0.1, 4)
    slip = rng.choice([-1.0, 1.0], 4) * rng.uniform(0.006, 0.05, 4)
    alpha = rng.normal(0.0, 0.03, 4)
    steer = rng.normal(0.0, 0.05)
    delta = np.array([steer * 1.08, steer * 0.93, 0.0, 0.0] if ackermann else [steer, steer, 0.0, 0.0])
    torque = rng.normal(0.0, 300.0, 4)
    omega = rng.normal(0.0, 0.3, 3) * np.array([1.0, pitch_scale, 1.0])
    vals = dict(slip=slip, alpha=alpha, delta=delta, h=h, hd=hd, omega=omega, speed=speed)
    vals.update(override)
    slip, alpha, delta, h, hd, omega, speed = (vals[n] for n in ("slip", "alpha", "delta", "h", "hd", "omega", "speed"))

    c_l = np.array(true.tracking_stiffness_n)
    c_a = np.array([true.cornering_stiffness_front_nprad] * 2 + [true.cornering_stiffness_rear_nprad] * 2) / 2
    f_wheel = np.stack([c_l * slip, c_a * alpha], axis=1)  # (F_a, F_b) per wheel
    f_body = np.array([[[math.cos(d), -math.sin(d)], [math.sin(d), math.cos(d)]] @ f for d, f in zip(delta, f_wheel)])
    wheel_acc = (torque - r * f_wheel[:, 0]) / iw
    m = true.mass_kg
    xdd = f_body[:, 0].sum() / m + g_aux[0] + yd * psid
    ydd = f_body[:, 1].sum() / m + g_aux[1] - speed * psid
    fz_body, fz_total = np.zeros(4), np.zeros(4)
    for i in range(4):
        ax = MODEL.front if i < 2 else MODEL.rear
        hs = ax.static_compression_m + h[i]
        k_s = ax.spring_c1_npm * math.exp(ax.spring_c2_per_m * (hs - ax.spring_c3_m))
        fz_body[i] = k_s * hs + ax.damper_nspm * hd[i]
        fz_total[i] = fz_body[i] + ax.unsprung_mass_kg * G
    zdd = fz_total.sum() / m + g_aux[2]
    moment = np.zeros(3)
    a_minus_g = np.array([f_body[:, 0].sum() / m, f_body[:, 1].sum() / m, 0.0])  # horizontal
    for i, ((x, y), fb, fz) in enumerate(zip(geo.corner_xy_m(), f_body, fz_body)):
        moment += np.cross([x, y, -geo.h_cg_m], [fb[0], fb[1], fz])  # strut + tire forces
        mu = (MODEL.front if i < 2 else MODEL.rear).unsprung_mass_kg  # unsprung d'Alembert force
        moment += np.cross([x, y, -(geo.h_cg_m - r) + h[i]], -mu * a_minus_g)
    inertia = np.diag([true.inertia_x_kgm2, true.inertia_y_kgm2, true.inertia_z_kgm2])
    omega_dot = np.linalg.solve(inertia, moment - np.cross(omega, inertia @ omega))
    return IdentInputs(
        t_ns=int(k * 10_000_000), xdd_a_mps2=xdd, ydd_a_mps2=ydd, zdd_a_mps2=zdd, xd_a_mps=speed,
        yd_a_mps=yd, psi_v_dot_radps=psid, gravity_aux_mps2=g_aux, omega_radps=tuple(omega),
        omega_dot_radps2=tuple(omega_dot), susp_deflection_m=tuple(h), susp_rate_mps=tuple(hd),
        wheel_speed_radps=tuple(speed * (1 + slip) / r), wheel_accel_radps2=tuple(wheel_acc),
        wheel_torque_nm=tuple(torque), slip_ratio=tuple(slip), slip_angle_rad=tuple(alpha),
        wheel_angle_rad=tuple(delta))


def _rel_err(params, true=TRUE):
    return {n: getattr(params, n) / getattr(true, n) - 1.0 for n in PARAM_NAMES}


@pytest.mark.parametrize("form", ["covariance", "sqrt_information"])
def test_exact_consistent_data_recover_all_ten_parameters_to_1e9(rng, form):
    # no noise, no forgetting, nontrivial Q (default config) and W (priors); weak prior
    ident = Identifier(MODEL, _weak_prior_config(form=form))
    for k in range(300):
        ident.update(_forward(rng, k))
    err = _rel_err(ident.params)
    assert max(abs(e) for e in err.values()) < 1e-9, err
    assert all(c.updates > 200 for c in ident.counters.values())
    assert ident.vehicle.params == ident.params and ident.vehicle.geometry == MODEL.geometry


def test_default_config_moves_every_parameter_from_prior_toward_truth(rng):
    # default prior (50 %) and weights: noise-free data, 500 samples (5 s at 100 Hz)
    ident = Identifier(MODEL)
    for k in range(500):
        ident.update(_forward(rng, k))
    prior_err = _rel_err(MODEL.params)
    err = _rel_err(ident.params)
    for n in PARAM_NAMES:
        assert abs(err[n]) < abs(prior_err[n]) / 5.0, (n, err[n], prior_err[n])


def test_paper_mean_steer_form_is_exact_for_equal_wheel_angles_and_biased_with_ackermann(rng):
    cfg = _weak_prior_config(steer_form="paper_mean")
    equal, acker = Identifier(MODEL, cfg), Identifier(MODEL, cfg)
    for k in range(300):
        equal.update(_forward(rng, k, ackermann=False))
        acker.update(_forward(rng, k, ackermann=True))
    names = PROBLEM_PARAMS["cornering"]
    assert max(abs(_rel_err(equal.params)[n]) for n in names) < 1e-9
    e = max(abs(_rel_err(acker.params)[n]) for n in names)
    assert 1e-6 < e < 0.05, e  # the mean-angle approximation of eq 22: small but not zero


def _warmed_up(rng, n=100):
    ident = Identifier(MODEL)
    for k in range(n):
        ident.update(_forward(rng, k))
    return ident


def test_zero_slip_and_zero_steer_never_update_and_never_divide_by_zero(rng):
    ident = _warmed_up(rng)
    before, c0 = ident.params, ident.counters
    zeros4 = np.zeros(4)
    with np.errstate(all="raise"), warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in range(100, 150):
            inp = _forward(rng, k, slip=zeros4, alpha=zeros4, delta=zeros4, omega=np.zeros(3))
            inp = dataclasses.replace(inp, omega_dot_radps2=(0.0, 0.0, 0.0))
            ident.update(inp)
            assert ident.excited == {"mass": True, "tracking": False, "cornering": False, "inertia": False}
        _ = ident.sigmas, ident.identifiability, ident.converged
    for name in ("tracking", "cornering", "inertia"):
        assert ident.counters[name].updates == c0[name].updates
        assert ident.counters[name].not_excited == c0[name].not_excited + 50
        for n in PROBLEM_PARAMS[name]:
            assert getattr(ident.params, n) == getattr(before, n)


def test_dependent_problems_wait_for_their_upstream_problems(rng):
    ident = Identifier(MODEL)  # upstream_min_updates = 50 in the default config
    for k in range(49):
        ident.update(_forward(rng, k))
    assert ident.counters["cornering"].updates == 0 and ident.waiting_upstream["cornering"] == 49
    for k in range(49, 120):
        ident.update(_forward(rng, k))
    assert ident.counters["cornering"].updates > 0 and ident.counters["inertia"].updates > 0
    assert ident.waiting_upstream["inertia"] > ident.waiting_upstream["cornering"]


def test_a_never_excited_upstream_problem_delays_its_dependants_at_most_max_wait(rng):
    cfg = dataclasses.replace(load_ident_config(), upstream_max_wait=30)
    ident = Identifier(MODEL, cfg)
    for k in range(60):  # no wheel ever slips: tracking is never excited
        ident.update(_forward(rng, k, slip=np.zeros(4)))
    assert ident.counters["tracking"].updates == 0
    assert ident.waiting_upstream["cornering"] == 30 and ident.counters["cornering"].updates > 0


def test_low_speed_gates_the_slip_problems(rng):
    ident = _warmed_up(rng)
    c0 = ident.counters
    for k in range(100, 120):
        ident.update(_forward(rng, k, speed=1.0))
    assert ident.counters["mass"].updates == c0["mass"].updates + 20
    for name in ("tracking", "cornering", "inertia"):
        assert ident.counters[name].updates == c0[name].updates


def test_nan_inputs_are_skipped_and_counted(rng):
    ident = _warmed_up(rng)
    c0 = ident.counters
    inp = _forward(rng, 100)
    bad = dataclasses.replace(inp, slip_ratio=(math.nan,) + inp.slip_ratio[1:])
    ident.update(bad)
    c = ident.counters
    assert c["tracking"].nan_rows == 1 and c["tracking"].rows_used == c0["tracking"].rows_used + 3
    assert c["cornering"].nan_rows == 2 and c["inertia"].nan_rows >= 1  # b_3, b_4 use F_a,1
    assert c["mass"].updates == c0["mass"].updates + 1
    assert all(math.isfinite(v) for v in ident.params.as_dict().values())
    assert all(math.isfinite(v) for v in ident.sigmas.values())


def test_duplicate_or_out_of_order_inputs_are_refused(rng):
    ident = Identifier(MODEL)
    ident.update(_forward(rng, 5))
    ident.update(_forward(rng, 5))
    ident.update(_forward(rng, 4))
    assert ident.inputs_rejected == 2 and ident.counters["mass"].updates == 1


def test_identifier_refuses_a_truth_vehicle_file():
    with pytest.raises(ValueError, match="model vehicle"):
        Identifier(dataclasses.replace(MODEL, kind="truth"))


def test_reset_and_start_values(rng):
    ident = _warmed_up(rng)
    ident.reset("mass")
    assert ident.params.mass_kg == MODEL.params.mass_kg
    assert ident.params.inertia_x_kgm2 != MODEL.params.inertia_x_kgm2
    start = dataclasses.replace(MODEL.params, mass_kg=1500.0)
    ident.reset(start=start)
    assert ident.params == start and ident.counters["inertia"].updates == 0
    assert Identifier(MODEL, start=start).params == start


def test_status_is_json_and_converged_flags(rng):
    ident = Identifier(MODEL)
    assert not any(ident.converged.values())
    for k in range(300):
        ident.update(_forward(rng, k))
    doc = json.loads(json.dumps(ident.status()))
    assert set(doc["params"]) == set(PARAM_NAMES) == set(doc["sigmas"])
    assert doc["converged"]["mass"] is True  # noise-free data: sigma -> 0
    assert all(doc["identifiability"][p] > 0 for p in PROBLEM_NAMES)


@pytest.mark.parametrize("problem", ["cornering", "inertia"])
def test_upstream_sensitivity_of_b_matches_finite_differences(rng, problem):
    from vdps_hil.identification.problems import REGRESSORS
    cfg = load_ident_config()
    inp = _forward(rng, 0)
    names = Identifier.upstream_param_names(problem)
    base = REGRESSORS[problem](inp, MODEL, TRUE, cfg)
    assert base.db_dup.shape == (base.b.shape[0], len(names))
    for j, n in enumerate(names):
        step = 1e-3 * getattr(TRUE, n)
        moved = REGRESSORS[problem](inp, MODEL, dataclasses.replace(TRUE, **{n: getattr(TRUE, n) + step}), cfg)
        assert np.allclose((moved.b - base.b) / step, base.db_dup[:, j], rtol=1e-6, atol=1e-9), n


def test_sigmas_include_the_uncertainty_of_upstream_estimates(rng):
    ident = Identifier(MODEL)
    for k in range(200):
        ident.update(_forward(rng, k))
    own = ident.problem("inertia").parameter_covariance
    total = ident.covariances["inertia"]
    assert np.all(np.diag(total) >= np.diag(own))
    assert np.any(np.diag(total) > np.diag(own))
    assert ident.sigmas["inertia_z_kgm2"] == pytest.approx(math.sqrt(total[2, 2]))


# ----------------------------------------------------- consistency with the physics core
def _core_inputs(rng, k):
    """A random state of the physics core (truth variant, level road, body parallel to the
    road, linear tire) and the IdentInputs that a perfect estimator would give for it."""
    from vdps_hil.model.core import Env, Inputs, Model
    veh = MODEL.with_params(**TRUE.as_dict())
    model = Model(veh, unsprung_dof=True)
    x = model.design_state(speed_mps=rng.uniform(10.0, 30.0))
    x[7] = rng.normal(0.0, 0.5)  # lateral velocity
    x[9:12] = rng.normal(0.0, 0.3, 3)  # body rates
    x[12:16] = [x[6] / r * (1.0 + rng.normal(0.0, 0.02)) for r in model.rolling_radius_m]  # slip
    x[16:20] = rng.normal(0.0, 0.004, 4)  # H (small: the body height is not re-trimmed)
    x[20:24] = rng.normal(0.0, 0.1, 4)
    u = Inputs(steer_wheel_angle_rad=rng.normal(0.0, 0.5), wheel_torque_nm=tuple(rng.normal(0.0, 300.0, 4)))
    _, d = model.evaluate(x, u, Env())
    assert all(d[f"normal_load_n_{i}"] > 0 for i in range(1, 5))  # no wheel lifted
    vx, vy, wz = x[6], x[7], x[11]
    w4 = lambda stem: tuple(d[f"{stem}_{i}"] for i in range(1, 5))  # noqa: E731
    inp = IdentInputs(
        t_ns=k + 1, xdd_a_mps2=d["accel_b_mps2_x"] + vy * wz, ydd_a_mps2=d["accel_b_mps2_y"] - vx * wz,
        zdd_a_mps2=d["accel_b_mps2_z"], xd_a_mps=vx, yd_a_mps=vy, psi_v_dot_radps=wz,
        gravity_aux_mps2=gravity_aux_mps2(0.0, 0.0, x[5]), omega_radps=tuple(x[9:12]),
        omega_dot_radps2=tuple(d[f"angular_accel_b_radps2_{a}"] for a in "xyz"),
        susp_deflection_m=w4("susp_deflection_m"), susp_rate_mps=w4("susp_deflection_rate_mps"),
        wheel_speed_radps=tuple(x[12:16]), wheel_accel_radps2=w4("wheel_accel_radps2"),
        wheel_torque_nm=w4("wheel_torque_nm"), slip_ratio=w4("slip_ratio"),
        slip_angle_rad=w4("slip_angle_rad"), wheel_angle_rad=w4("road_wheel_angle_rad"))
    return inp, veh, np.array([d[f"moment_b_nm_{a}"] for a in "xyz"])


def test_moments_and_all_four_equations_agree_with_the_physics_core(rng):
    from vdps_hil.identification.problems import REGRESSORS, moments_from_inputs
    cfg = dataclasses.replace(load_ident_config(), mass_form="sprung")
    for k in range(5):
        inp, veh, m_core = _core_inputs(rng, k)
        assert np.allclose(moments_from_inputs(veh, TRUE, inp), m_core, rtol=1e-10, atol=1e-8)
        for name in PROBLEM_NAMES:
            reg = REGRESSORS[name](inp, veh, TRUE, cfg)
            x = np.array([getattr(TRUE, n) for n in PROBLEM_PARAMS[name]])
            assert np.allclose(reg.a @ x, reg.b, rtol=1e-10, atol=1e-8), name
        # eq 20 as printed books m_u g where the core's unsprung masses weigh m_u (zdd_a - G_z)
        paper = REGRESSORS["mass"](inp, veh, TRUE, load_ident_config())
        a = inp.zdd_a_mps2 - inp.gravity_aux_mps2[2]
        assert paper.a[0, 0] * TRUE.mass_kg - paper.b[0] == pytest.approx(
            veh.unsprung_mass_total_kg * (a - G), rel=1e-6, abs=1e-6)


# ------------------------------------------------------------------- forces and moments
def test_static_suspension_forces_balance_and_leave_no_moment():
    zeros = np.zeros(4)
    total = suspension_forces_n(MODEL, zeros, zeros)
    body = suspension_forces_n(MODEL, zeros, zeros, include_unsprung_weight=False)
    assert np.allclose(total - body, [MODEL.axle(i).unsprung_mass_kg * G for i in range(4)])
    # the springs were sized to carry a 1440 kg sprung mass at design ride height (model file)
    m_sprung = body.sum() / G
    assert m_sprung == pytest.approx(1440.0, rel=2e-3)
    m = body_moments_nm(MODEL.geometry, body, zeros, zeros)
    assert abs(m[0]) < 1e-9 and abs(m[1]) < 0.01 * body.sum() * 0.01  # < 1 % of F x 1 cm
    assert m[2] == 0.0


def test_moment_signs_brake_dive_and_outward_roll():
    zeros = np.zeros(4)
    # braking (F_x < 0 at the ground): nose-down moment -> pitch (nose-up positive) rate < 0
    m = body_moments_nm(MODEL.geometry, zeros, np.full(4, -2000.0), zeros)
    assert m[1] > 0
    theta_dot = (c_omega_inv(0.0, 0.0) @ np.array([0.0, m[1] / 2400.0, 0.0]))[1]
    assert theta_dot < 0
    # left turn (F_y > 0 at the ground): the body rolls right side down (phi positive)
    m = body_moments_nm(MODEL.geometry, zeros, zeros, np.full(4, 2000.0))
    assert m[0] > 0
    # more lateral force at the front: yaw to the left (M_z > 0)
    assert body_moments_nm(MODEL.geometry, zeros, zeros, [1000.0, 1000.0, 0.0, 0.0])[2] > 0


def test_body_moments_equal_the_cross_product(rng):
    fs, fx, fy = rng.normal(0, 3000, 4), rng.normal(0, 3000, 4), rng.normal(0, 3000, 4)
    want = sum(np.cross([x, y, -MODEL.geometry.h_cg_m], [a, b, c])
               for (x, y), a, b, c in zip(MODEL.geometry.corner_xy_m(), fx, fy, fs))
    assert np.allclose(body_moments_nm(MODEL.geometry, fs, fx, fy), want, rtol=1e-12, atol=1e-9)


def test_eq14_floor_on_extension():
    # wheel hanging: the spring extended past its free length; K H + m_u g is floored at zero
    f = suspension_forces_n(MODEL, np.full(4, -0.5), np.zeros(4))
    assert np.allclose(f, 0.0, atol=1e-9)


# ------------------------------------------------------------- Table 3 (weighting, section 8)
def _inertia_rows(rng, n, pitch_scale):
    rows = []
    for k in range(n):
        inp = _forward(rng, k, pitch_scale=pitch_scale)
        reg = inertia_regressor(inp, MODEL, TRUE, load_ident_config())
        rows.append((reg.a, reg.b))
    return rows


def test_balanced_weighting_raises_the_minimum_eigenvalue(rng):
    rows = _inertia_rows(rng, 200, pitch_scale=0.2)
    rms = np.sqrt(np.mean([np.sum(a * a, axis=1) for a, _ in rows], axis=0))
    q_uniform = np.full(3, 0.125)
    q_bal = balanced_weighting(rms, total=float(np.sum(q_uniform ** 2)))
    assert np.sum(q_bal ** 2) == pytest.approx(np.sum(q_uniform ** 2))
    lam = {}
    for name, q in (("uniform", q_uniform), ("balanced", q_bal)):
        r = WeightedRLS([715.0, 1680.0, 3510.0], [1.0] * 3, q, [1.0] * 3)
        for a, b in rows:
            r.update(a, b)
        lam[name] = r.identifiability
    assert lam["balanced"] > 1.2 * lam["uniform"], lam


def test_table3_convergence_time_grows_as_the_weighting_shrinks(rng):
    # Table 3: W4 = I, Q4 = q I, q in {0.625, 0.125, 0.025, 0.005}; the paper's P(0) is not
    # printed; P(0) = I (prior sd 1 kg m^2) reproduces its orders of magnitude. Noise-free, 100 Hz.
    rows = _inertia_rows(rng, 1500, pitch_scale=0.2)
    x_true = np.array([TRUE.inertia_x_kgm2, TRUE.inertia_y_kgm2, TRUE.inertia_z_kgm2])
    x0 = np.array([715.0, 1680.0, 3510.0])
    times, lams = [], []
    for q in (0.625, 0.125, 0.025, 0.005):
        r = WeightedRLS(x0, [1.0] * 3, [q] * 3, [1.0] * 3)
        t90 = np.full(3, np.inf)  # first time the error is within 10 % of the prior error
        for k, (a, b) in enumerate(rows):
            r.update(a, b)
            done = np.abs(r.x - x_true) <= 0.1 * np.abs(x0 - x_true)
            t90 = np.where(done & np.isinf(t90), (k + 1) * 0.01, t90)
        times.append(t90)
        lams.append(r.identifiability)
    times = np.array(times)
    for j in range(3):
        finite = times[np.isfinite(times[:, j]), j]
        assert np.all(np.diff(finite) > 0), times[:, j]  # slower for smaller q
    assert np.all(np.isfinite(times[0])) and np.all(np.isinf(times[-1]))
    assert np.all(np.diff(lams) < 0)  # min eigenvalue falls with q, as Table 3


# ---------------------------------------------------------------------------- config
def test_default_config_loads():
    cfg = load_ident_config()
    assert cfg.form == "covariance" and cfg.bounds_factor == (0.3, 3.0)
    assert len(cfg.tracking.q) == 4 and len(cfg.inertia.excitation_min) == 3


@pytest.mark.parametrize("mutation,msg", [
    (lambda s: s.replace('form = "covariance"', 'form = "magic"'), "form"),
    (lambda s: s.replace("forgetting = 1.0", "forgetting = 1.5", 1), "forgetting"),
    (lambda s: s.replace("q = [0.005]", "q = [0.005, 1.0]"), "list of 1"),
    (lambda s: s.replace("q = [0.005]", "q = [-1.0]"), "positive"),
    (lambda s: s.replace("[general]", "[general]\nbogus = 1"), "unknown key"),
    (lambda s: s.replace("schema_version = 1", "schema_version = 7"), "schema_version"),
    (lambda s: s.replace("bounds_factor = [0.3, 3.0]", "bounds_factor = [1.3, 3.0]"), "lo < 1 < hi"),
    (lambda s: s + "\n[[[", "malformed TOML"),
])
def test_bad_configs_give_one_line_errors(mutation, msg):
    text = mutation(DEFAULT_CONFIG_PATH.read_text())
    with pytest.raises(IdentConfigError, match=msg) as e:
        parse_ident_config(text, "bad.toml")
    assert "\n" not in str(e.value)


def test_p0_scaled_option_sets_the_papers_initial_covariance():
    text = DEFAULT_CONFIG_PATH.read_text().replace(
        "[inertia]                        # eq 23: x = [I_x, I_y, I_z]; b in N m\n",
        "[inertia]\np0_scaled = 4.0\n").replace(
        'q = [0.01, 0.01, 0.01]\nw = "prior"', "q = [0.01, 0.01, 0.01]\nw = [1.0, 1.0, 1.0]")
    cfg = parse_ident_config(text)
    assert cfg.inertia.p0_scaled == 4.0 and cfg.inertia.w == (1.0, 1.0, 1.0)
    ident = Identifier(MODEL, cfg)
    assert np.allclose(ident.problem("inertia").covariance_scaled, 4.0 * np.eye(3))


def test_ident_inputs_validate_shapes():
    inp = _forward(np.random.default_rng(0), 0)
    with pytest.raises(ValueError, match="slip_ratio"):
        dataclasses.replace(inp, slip_ratio=(0.0, 0.0))
    with pytest.raises(TypeError, match="t_ns"):
        dataclasses.replace(inp, t_ns=0.5)


# ------------------------------------------- "measured" roll/pitch moments (moment_form)
def _tilted_core_inputs(rng, k, roll_v, pitch_v, tire_scale=1.0):
    """A core state (truth variant, level road, linear tire) with the body rolled/pitched over
    the road by (roll_v, pitch_v) and suspension deflections consistent with that tilt, and the
    IdentInputs a perfect estimator gives, with the specific force and road-relative angles."""
    from vdps_hil.model.core import Env, Inputs, Model
    from vdps_hil.model.frames import dcm_global_to_vehicle
    veh = MODEL.with_params(**TRUE.as_dict())
    model = Model(veh, unsprung_dof=True)
    x = model.design_state(speed_mps=rng.uniform(15.0, 30.0))
    _, d0 = model.evaluate(x, Inputs(), Env())  # untilted wheel-centre heights
    x[3], x[4] = roll_v, pitch_v
    x[7] = rng.normal(0.0, 0.3)
    x[9:12] = rng.normal(0.0, 0.2, 3)
    x[12:16] = [x[6] / r * (1.0 + rng.normal(0.0, 0.01)) for r in model.rolling_radius_m]
    u = Inputs(steer_wheel_angle_rad=rng.normal(0.0, 0.5), wheel_torque_nm=tuple(rng.normal(0.0, 300.0, 4)))
    # deflections that keep each wheel centre at its untilted height over the road (+ noise)
    n = dcm_global_to_vehicle(roll_v, pitch_v, 0.0) @ np.array([0.0, 0.0, 1.0])
    xy = np.array(veh.geometry.corner_xy_m())
    zw0 = -(veh.geometry.h_cg_m - veh.tire.rolling_radius_m)
    hw0 = np.array([d0[f"wheel_centre_height_m_{i}"] for i in range(1, 5)])
    h_cg = d0["height_cg_above_road_m"]
    x[16:20] = (hw0 - h_cg - n[0] * xy[:, 0] - n[1] * xy[:, 1]) / n[2] - zw0 + rng.normal(0.0, 0.002, 4)
    x[20:24] = rng.normal(0.0, 0.05, 4)
    _, d = model.evaluate(x, u, Env())
    assert all(d[f"normal_load_n_{i}"] > 0 for i in range(1, 5))
    vx, vy, wz = x[6], x[7], x[11]
    acc = np.array([d[f"accel_b_mps2_{a}"] for a in "xyz"])
    f_b = acc - dcm_global_to_vehicle(x[3], x[4], x[5]) @ np.array([0.0, 0.0, -G])
    w4 = lambda stem: tuple(d[f"{stem}_{i}"] for i in range(1, 5))  # noqa: E731
    inp = IdentInputs(
        t_ns=k + 1, xdd_a_mps2=acc[0] + vy * wz, ydd_a_mps2=acc[1] - vx * wz, zdd_a_mps2=acc[2],
        xd_a_mps=vx, yd_a_mps=vy, psi_v_dot_radps=wz, gravity_aux_mps2=gravity_aux_mps2(0.0, 0.0, x[5]),
        omega_radps=tuple(x[9:12]), omega_dot_radps2=tuple(d[f"angular_accel_b_radps2_{a}"] for a in "xyz"),
        susp_deflection_m=w4("susp_deflection_m"), susp_rate_mps=w4("susp_deflection_rate_mps"),
        wheel_speed_radps=tuple(x[12:16]), wheel_accel_radps2=w4("wheel_accel_radps2"),
        wheel_torque_nm=w4("wheel_torque_nm"), slip_ratio=w4("slip_ratio"),
        slip_angle_rad=tuple(tire_scale * a for a in w4("slip_angle_rad")), wheel_angle_rad=w4("road_wheel_angle_rad"),
        specific_force_b_mps2=tuple(f_b), vehicle_angles_rad=(roll_v, pitch_v))
    return inp, veh, np.array([d[f"moment_b_nm_{a}"] for a in "xyz"])


def test_measured_moment_form_matches_the_core_with_the_body_tilted_over_the_road(rng):
    """Body rolled 2 deg and pitched 1 deg over the road (deflections up to 5 cm): the measured
    M_x, M_y (first order in the angles and deflections; one lever arm for the summed tire
    forces) are within 4 % of the core's moment magnitude (measured: up to 3.2 % in these
    strongly tilted random states; on the paper's drive with the simulator's deflections I_x came
    out -0.4 %), and they do not depend on the tire stiffnesses: 10 % larger
    slip angles (as a 10 % stiffness error) leave them unchanged while the stiffness form moves."""
    from vdps_hil.identification.problems import moments_from_inputs
    for k in range(6):
        inp, veh, m_core = _tilted_core_inputs(rng, k, math.radians(2.0), math.radians(1.0))
        meas = moments_from_inputs(veh, TRUE, inp, "measured")
        stiff = moments_from_inputs(veh, TRUE, inp, "stiffness")
        scale = float(np.max(np.abs(m_core[:2])))
        assert np.all(np.abs(meas[:2] - m_core[:2]) <= 0.04 * scale), (meas, m_core)
        assert meas[2] == stiff[2]  # yaw: the stiffness form in both
        seed = 100 + k
        inp1, _, _ = _tilted_core_inputs(np.random.default_rng(seed), k, math.radians(2.0), math.radians(1.0), 1.0)
        inp2, _, _ = _tilted_core_inputs(np.random.default_rng(seed), k, math.radians(2.0), math.radians(1.0), 1.1)
        assert np.allclose(moments_from_inputs(veh, TRUE, inp2, "measured")[:2],
                           moments_from_inputs(veh, TRUE, inp1, "measured")[:2], rtol=0, atol=1e-9)
        assert not np.allclose(moments_from_inputs(veh, TRUE, inp2, "stiffness")[:2],
                               moments_from_inputs(veh, TRUE, inp1, "stiffness")[:2], rtol=0, atol=1.0)


def test_moment_form_config_key_is_optional_and_checked():
    text = DEFAULT_CONFIG_PATH.read_text()
    assert load_ident_config().moment_form == "measured"
    assert parse_ident_config(text.replace('moment_form = "measured"', "")).moment_form == "stiffness"
    with pytest.raises(IdentConfigError, match="moment_form"):
        parse_ident_config(text.replace('moment_form = "measured"', 'moment_form = "nope"'))
