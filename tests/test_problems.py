"""The four identification problems (eq 20-23): the regressors' steer forms and upstream
sensitivities, all four equations and the moments against the physics core, and the row
weighting of Table 3 (synthetic inputs: ``ident_forward``)."""

import dataclasses
import math

import numpy as np
import pytest

from ident_forward import MODEL, TRUE, G, forward, rel_err, weak_prior_config
from vdps_hil.identification.config import PROBLEM_NAMES, PROBLEM_PARAMS, load_ident_config
from vdps_hil.identification.identifier import Identifier
from vdps_hil.identification.inputs import IdentInputs, gravity_aux_mps2
from vdps_hil.identification.problems import balanced_weighting, inertia_regressor
from vdps_hil.identification.rls import WeightedRLS


def test_paper_mean_steer_form_is_exact_for_equal_wheel_angles_and_biased_with_ackermann(rng):
    cfg = weak_prior_config(steer_form="paper_mean")
    equal, acker = Identifier(MODEL, cfg), Identifier(MODEL, cfg)
    for k in range(300):
        equal.update(forward(rng, k, ackermann=False))
        acker.update(forward(rng, k, ackermann=True))
    names = PROBLEM_PARAMS["cornering"]
    assert max(abs(rel_err(equal.params)[n]) for n in names) < 1e-9
    e = max(abs(rel_err(acker.params)[n]) for n in names)
    assert 1e-6 < e < 0.05, e  # the mean-angle approximation of eq 22: small but not zero


@pytest.mark.parametrize("problem", ["cornering", "inertia"])
def test_upstream_sensitivity_of_b_matches_finite_differences(rng, problem):
    from vdps_hil.identification.problems import REGRESSORS
    cfg = load_ident_config()
    inp = forward(rng, 0)
    names = Identifier.upstream_param_names(problem)
    base = REGRESSORS[problem](inp, MODEL, TRUE, cfg)
    assert base.db_dup.shape == (base.b.shape[0], len(names))
    for j, n in enumerate(names):
        step = 1e-3 * getattr(TRUE, n)
        moved = REGRESSORS[problem](inp, MODEL, dataclasses.replace(TRUE, **{n: getattr(TRUE, n) + step}), cfg)
        assert np.allclose((moved.b - base.b) / step, base.db_dup[:, j], rtol=1e-6, atol=1e-9), n


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


def test_the_cornering_yaw_row_is_the_core_yaw_balance_and_weighs_the_axles(rng):
    """The optional third row of eq 22 (``yaw_row_config``): exact on physics-core states with the
    true parameters; a split of the same axle-force sum (C_f + C_r kept) leaves it unbalanced;
    a config with two q entries has no yaw row."""
    from vdps_hil.experiments.ident_study import yaw_row_config
    from vdps_hil.identification.problems import cornering_regressor
    cfg = yaw_row_config()
    x = np.array([TRUE.cornering_stiffness_front_nprad, TRUE.cornering_stiffness_rear_nprad])
    for k in range(5):
        inp, veh, _ = _core_inputs(rng, k)
        r = cornering_regressor(inp, veh, TRUE, cfg)
        assert r.a.shape == (3, 2) and r.db_dup.shape == (3, 5)
        assert np.allclose(r.b - r.a @ x, 0.0, atol=1e-8 * max(1.0, np.max(np.abs(r.b))))
        moved = x + np.array([0.1, -0.1]) * x[0]
        assert abs(r.b[2] - r.a[2] @ moved) > 1e-3 * abs(r.a[2] @ x) > 0.0
        assert cornering_regressor(inp, veh, TRUE, load_ident_config()).a.shape == (2, 2)


def test_moments_and_all_four_equations_agree_with_the_physics_core(rng):
    from vdps_hil.identification.forces import moments_from_inputs
    from vdps_hil.identification.problems import REGRESSORS
    cfg = dataclasses.replace(load_ident_config(), mass_form="sprung")
    for k in range(5):
        inp, veh, m_core = _core_inputs(rng, k)
        assert np.allclose(moments_from_inputs(veh, TRUE, inp), m_core, rtol=1e-10, atol=1e-8)
        for name in PROBLEM_NAMES:
            reg = REGRESSORS[name](inp, veh, TRUE, cfg)
            x = np.array([getattr(TRUE, n) for n in PROBLEM_PARAMS[name]])
            assert np.allclose(reg.a @ x, reg.b, rtol=1e-10, atol=1e-8), name
        # eq 20 as printed books m_u g where the core's unsprung masses weigh m_u (zdd_a - G_z)
        paper = REGRESSORS["mass"](inp, veh, TRUE, dataclasses.replace(load_ident_config(), mass_form="paper"))
        a = inp.zdd_a_mps2 - inp.gravity_aux_mps2[2]
        assert paper.a[0, 0] * TRUE.mass_kg - paper.b[0] == pytest.approx(
            veh.unsprung_mass_total_kg * (a - G), rel=1e-6, abs=1e-6)


# ------------------------------------------------------------- Table 3 (weighting, section 8)
def _inertia_rows(rng, n, pitch_scale):
    rows = []
    for k in range(n):
        inp = forward(rng, k, pitch_scale=pitch_scale)
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


# ------------------------------------------------------- issue 17: mass form, strut axis, load gate
def test_the_shipped_mass_form_is_unbiased_when_the_rolled_body_brings_a_below_g():
    # a corner: the body rolls by phi outwards, so the specific force along the struts is
    # f_z = g cos(phi) - a_y sin(phi) < g; the struts carry m_s f_z (CommonRoad's multibody exactly)
    from vdps_hil.identification.problems import mass_regressor
    veh = MODEL
    phi, a_y = 0.1, 7.5
    f_z = G * math.cos(phi) - a_y * math.sin(phi)
    m_u = veh.unsprung_mass_total_kg
    m_s = TRUE.mass_kg - m_u
    h = _deflection_for_strut_sum(veh, m_s * f_z)
    inp = forward(np.random.default_rng(3), 0, h=h, hd=np.zeros(4))
    inp = dataclasses.replace(inp, zdd_a_mps2=f_z + inp.gravity_aux_mps2[2])
    cfg = load_ident_config()
    assert cfg.mass_form == "sprung"
    reg = mass_regressor(inp, veh, cfg)
    assert reg.b[0] / reg.a[0, 0] == pytest.approx(TRUE.mass_kg, rel=1e-9)
    paper = mass_regressor(inp, veh, dataclasses.replace(cfg, mass_form="paper"))
    # eq 20 as printed: m_tot + m_u (g - f_z) / f_z, +0.8 % here (CommonRoad's circle: +0.37 %)
    assert paper.b[0] / paper.a[0, 0] - TRUE.mass_kg == pytest.approx(m_u * (G - f_z) / f_z, rel=1e-6)


def _deflection_for_strut_sum(veh, total_n):
    """Equal deflections whose strut forces (K_s (static + H), no damping) sum to total_n."""
    from vdps_hil.model.spring_law import suspension_forces_n
    from scipy.optimize import brentq
    return np.full(4, brentq(lambda x: float(np.sum(suspension_forces_n(veh, (x,) * 4, (0.0,) * 4,
                                                                        include_unsprung_weight=False))) - total_n,
                             -0.2, 0.2, xtol=1e-14))


def test_the_mass_regressor_carries_the_strut_axis_term_m_s_theta_f_x(rng):
    from vdps_hil.identification.problems import mass_regressor
    inp = forward(rng, 0)
    assert mass_regressor(inp, MODEL, load_ident_config()).structure is None  # no f_b, no angles
    inp = dataclasses.replace(inp, specific_force_b_mps2=(3.0, 0.0, 9.8), vehicle_angles_rad=(0.0, 0.02))
    reg = mass_regressor(inp, MODEL, load_ident_config(), TRUE)
    m_s = TRUE.mass_kg - MODEL.unsprung_mass_total_kg
    assert reg.structure[0] == pytest.approx(m_s * 0.02 * 3.0, rel=1e-12)


def test_the_load_gate_refuses_a_wheel_away_from_its_static_load_and_counts_it(rng):
    from vdps_hil.identification.problems import tracking_regressor
    from vdps_hil.model.spring_law import suspension_forces_n
    fz0 = suspension_forces_n(MODEL, (0.0,) * 4, (0.0,) * 4)
    k_front = MODEL.front.spring_c1_npm  # linear spring of the model file near the design height
    h = np.array([-0.3 * fz0[0] / k_front, 0.0, 0.0, 0.0])  # wheel 1 unloaded by ~30 %
    inp = forward(rng, 0, h=h, hd=np.zeros(4), slip=np.full(4, 0.02), speed=20.0)
    cfg = load_ident_config()
    assert math.isinf(cfg.tracking.load_band)  # shipped: off (ident_study, tuning seed 101: see default.toml)
    assert tracking_regressor(inp, MODEL, cfg).rows.all()
    gated = dataclasses.replace(cfg, tracking=dataclasses.replace(cfg.tracking, load_band=0.1))
    reg = tracking_regressor(inp, MODEL, gated)
    fz = suspension_forces_n(MODEL, tuple(h), (0.0,) * 4)
    assert fz[0] / fz0[0] - 1.0 < -0.1
    assert reg.rows.tolist() == [False, True, True, True] and reg.row_gates == {"load transfer": 1}


def test_the_tracking_regressor_carries_the_load_transfer_term(rng):
    # a load-proportional tire (Magic Formula K_x = p_kx1 F_z) puts A_ii C_i (F_z,i / F_z0,i - 1)
    # more into b_i: exactly what b holds when the wheel's force is C_i F_z,i / F_z0,i lambda_i
    from vdps_hil.identification.problems import load_ratio, tracking_regressor
    from vdps_hil.model.spring_law import suspension_forces_n
    h = np.array([-0.02, 0.01, 0.015, -0.005])
    inp = forward(rng, 0, h=h, hd=np.zeros(4), slip=np.array([0.02, -0.01, 0.03, 0.015]), speed=20.0)
    ratio = suspension_forces_n(MODEL, tuple(h), (0.0,) * 4) / suspension_forces_n(MODEL, (0.0,) * 4, (0.0,) * 4)
    assert np.allclose(load_ratio(inp, MODEL), ratio, rtol=1e-12)
    reg = tracking_regressor(inp, MODEL, load_ident_config(), TRUE)
    c = np.array(TRUE.tracking_stiffness_n)
    b_load = reg.b + np.diag(reg.a) * c * (ratio - 1.0)  # the same wheels with the load-scaled tire
    assert np.allclose(b_load - np.diag(reg.a) * c, reg.structure, rtol=1e-9, atol=1e-9)
    assert np.all(np.abs(reg.structure) > 0.0)


def test_the_roll_row_carries_the_normal_load_tilt_as_its_structure_term(rng):
    # the measured moment form's r n_b,y sum F_z (the normal loads over a body rolled on its
    # suspension): the term a roll-axis-joint model (CommonRoad's) does not have
    from vdps_hil.identification.forces import road_normal_body
    from vdps_hil.model.spring_law import suspension_forces_n
    inp = forward(rng, 0)
    assert inertia_regressor(inp, MODEL, TRUE, load_ident_config()).structure is None  # no f_b, no angles
    inp = dataclasses.replace(inp, specific_force_b_mps2=(0.5, 4.0, 9.7), vehicle_angles_rad=(0.05, -0.01))
    reg = inertia_regressor(inp, MODEL, TRUE, load_ident_config())
    fz = float(np.sum(suspension_forces_n(MODEL, inp.susp_deflection_m, inp.susp_rate_mps)))
    tilt = MODEL.tire.rolling_radius_m * road_normal_body(0.05, -0.01)[1] * fz
    assert reg.structure[0] == pytest.approx(tilt, rel=1e-12) and abs(tilt) > 0.01 * MODEL.params.mass_kg * G * 0.344
    assert reg.structure[1] == reg.structure[2] == 0.0


def test_stale_suspension_refuses_the_roll_and_pitch_rows_and_holds_i_x_i_y_in_the_yaw_row(rng):
    """``problems.suspension_gate``: with suspension samples further apart (or older) than
    ``suspension_max_interval_s`` the roll and pitch rows (M_x, M_y hold the strut forces) are
    refused and counted; the yaw row then takes I_x, I_y at their current values (its gyroscopic
    term moved into b), so the row still holds for the true inertias. Fresh or unknown
    (None: inputs built by hand): the regressor is unchanged."""
    cfg = load_ident_config()
    assert cfg.suspension_max_interval_s == 0.02
    inp = forward(rng, 1)
    base = inertia_regressor(inp, MODEL, TRUE, cfg)
    for fresh in (None, 0.001, 0.02):
        reg = inertia_regressor(dataclasses.replace(inp, susp_interval_s=fresh), MODEL, TRUE, cfg)
        assert np.array_equal(reg.a, base.a) and np.array_equal(reg.b, base.b) and reg.row_gates is None
    stale = inertia_regressor(dataclasses.replace(inp, susp_interval_s=1.0), MODEL, TRUE, cfg)
    assert not stale.rows[0] and not stale.rows[1] and stale.rows[2] == base.rows[2]
    assert stale.row_gates == {"suspension too slow": int(base.rows[0]) + int(base.rows[1])}
    assert stale.a[2, 0] == stale.a[2, 1] == 0.0 and stale.a[2, 2] == base.a[2, 2]
    x = np.array([TRUE.inertia_x_kgm2, TRUE.inertia_y_kgm2, TRUE.inertia_z_kgm2])
    assert stale.a[2] @ x == pytest.approx(stale.b[2], rel=1e-9)  # the yaw balance with the true inertias
    assert base.a[2] @ x == pytest.approx(base.b[2], rel=1e-9)
    # no suspension at all (NaN deflections, no interval): the roll and pitch rows are left to the
    # RLS's NaN guard (counted there as NaN rows, not as this gate), the yaw row is the same as above
    none = inertia_regressor(dataclasses.replace(inp, susp_interval_s=math.inf, susp_deflection_m=(math.nan,) * 4),
                             MODEL, TRUE, cfg)
    assert none.row_gates is None and not np.isfinite(none.b[:2]).any()
    assert none.a[2, 0] == none.a[2, 1] == 0.0 and none.b[2] == pytest.approx(stale.b[2], rel=1e-12)
    # the mass row (static weight) is not gated
    from vdps_hil.identification.problems import mass_regressor
    m = mass_regressor(dataclasses.replace(inp, susp_interval_s=1.0), MODEL, cfg)
    assert m.rows[0] and m.row_gates is None


def test_the_used_rows_are_the_excited_finite_ones_made_once():
    from vdps_hil.identification.problems import Regressor
    a = np.array([[1.0, 2.0], [np.nan, 1.0], [1.0, 1.0], [1.0, 1.0]])
    reg = Regressor(a, np.array([1.0, 1.0, np.inf, 2.0]), np.array([True, True, True, False]))
    assert reg.used == (True, False, False, False)
    assert reg.used is reg.used and reg == Regressor(reg.a, reg.b, reg.rows)  # a cache, not a field
