"""Physics core: equilibrium, energy-free kinematics, analytic speed/coast-down, bicycle circle,
low-speed braking. Tolerances are the issue's acceptance figures unless stated."""

import math

import pytest

from vdps_hil.model.core import Env, Inputs, Model, StateLayout
from vdps_hil.model.effects import EffectSet, LinearTire, make_effect
from vdps_hil.model.frames import c_omega_inv, dcm_global_to_vehicle
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.simulator import Simulator
from vdps_hil.units import GRAVITY_MPS2 as G

SEDAN = load_vehicle("sedan-truth")


def test_state_layout_named_slices():
    full, red = StateLayout(True), StateLayout(False)
    assert full.size == 24 and red.size == 16
    assert full.pos_g == slice(0, 3) and full.euler_g == slice(3, 6) and full.vel_b == slice(6, 9)
    assert full.rate_b == slice(9, 12) and full.wheel_spin == slice(12, 16)
    assert full.susp_defl == slice(16, 20) and full.susp_defl_rate == slice(20, 24)
    assert not hasattr(red, "susp_defl")
    assert len(full.names) == 24 and full.names[12] == "wheel_speed_radps_1"


@pytest.mark.parametrize("dof", [True, False])
def test_static_equilibrium_springs_balance_weight(dof):
    """Level road, standstill, started at design ride height: the springs carry the weight within
    0.1 % and design ride height is the equilibrium (deflection < 0.1 mm)."""
    sim = Simulator(SEDAN, inputs=Inputs(), effects=EffectSet(), unsprung_dof=dof,
                    initial_state=Model(SEDAN, unsprung_dof=dof).design_state(0.0))
    sim.step_to(2.0)
    s = sim.snapshot()
    m_s, m_tot = SEDAN.sprung_mass_kg, SEDAN.params.mass_kg
    springs = sum(s[f"susp_force_n_{i}"] for i in range(1, 5))
    loads = sum(s[f"normal_load_n_{i}"] for i in range(1, 5))
    assert loads == pytest.approx(m_tot * G, rel=1e-3)
    if dof:
        assert springs == pytest.approx(m_s * G, rel=1e-3)
    for i in range(1, 5):
        assert abs(s[f"susp_deflection_m_{i}"]) < 1e-4
    assert abs(s["accel_b_mps2_z"]) < 1e-6 and abs(s["roll_v_rad"]) < 1e-9


def test_design_state_is_exact_equilibrium_of_f():
    for dof in (True, False):
        m = Model(SEDAN, unsprung_dof=dof)
        xd = m.f(m.design_state(0.0), Inputs(), Env())
        assert max(abs(v) for v in xd) < 1e-9


def test_kinematic_rows_match_frames_module():
    """Position and Euler-angle rates use C_g^v and C_omega^-1 of model.frames."""
    m = Model(SEDAN)
    x = m.design_state(20.0)
    x[3:6] = [0.05, -0.03, 0.7]
    x[6:12] = [20.0, 0.4, -0.1, 0.02, -0.03, 0.15]
    xd = m.f(x, Inputs(), Env())
    c = dcm_global_to_vehicle(*x[3:6])
    assert xd[0:3] == pytest.approx(list(c.T @ x[6:9]), abs=1e-12)
    assert xd[3:6] == pytest.approx(list(c_omega_inv(x[3], x[4]) @ x[9:12]), abs=1e-12)


def test_gravity_on_a_banked_graded_road_matches_eq13():
    """Body parallel to the road: g in body axes equals eq 13's [G_x, G_y, G_z]; the trimmed
    state on bank + grade has zero vertical/roll/pitch acceleration."""
    from vdps_hil.model.frames import gravity_in_aux
    env = Env(math.radians(2.0), math.radians(-2.0))
    m = Model(SEDAN)
    x = m.design_state(0.0, env, heading_rad=0.3)
    raw = {}
    m.f(x, Inputs(), env, raw)
    g_aux = gravity_in_aux(env.bank_rad, env.grade_rad, 0.3, G)
    assert raw["_g_b"] == pytest.approx(list(g_aux), abs=1e-12)
    xt = m.trim_state(25.0, env)
    xd = m.f(xt, Inputs(), env)
    assert max(abs(v) for v in (xd[8], xd[9], xd[10], *xd[20:24])) < 1e-7


def _drag_rr_effects():
    return EffectSet([make_effect("aero_drag"), make_effect("rolling_resistance")])


def test_speed_hold_with_analytic_drag_and_rolling_resistance_torque():
    """Constant torque = r (1/2 rho CdA v^2 + f_r m g) / 4 per wheel keeps 25 m/s within
    0.05 m/s over 60 s."""
    eff = _drag_rr_effects()
    d, rr = eff["aero_drag"], eff["rolling_resistance"]
    v0, r = 25.0, SEDAN.tire.rolling_radius_m
    force = 0.5 * d.air_density_kgpm3 * d.cda_m2 * v0 ** 2 + rr.coefficient * SEDAN.params.mass_kg * G
    sim = Simulator(SEDAN, inputs=Inputs(0.0, (r * force / 4,) * 4), effects=eff, initial_speed_mps=v0,
                    record_truth=False)
    worst = 0.0
    while sim.t_s < 60.0 - 1e-9:
        sim.step_to(sim.t_s + 0.5)
        worst = max(worst, abs(sim.x[6] - v0))
    assert worst < 0.05


def test_coast_down_matches_analytic_solution():
    """m_eff dv/dt = -(f_r m g + 1/2 rho CdA v^2), m_eff = m + 4 I_w / r^2:
    v(t) = sqrt(a/b) tan(atan(v0 sqrt(b/a)) - sqrt(a b) t). Within 1 % over 30 s."""
    eff = _drag_rr_effects()
    d, rr = eff["aero_drag"], eff["rolling_resistance"]
    m, r, iw = SEDAN.params.mass_kg, SEDAN.tire.rolling_radius_m, SEDAN.tire.wheel_inertia_kgm2
    m_eff = m + 4 * iw / r ** 2
    a = rr.coefficient * m * G / m_eff
    b = 0.5 * d.air_density_kgpm3 * d.cda_m2 / m_eff
    v0 = 30.0
    sim = Simulator(SEDAN, inputs=Inputs(), effects=eff, initial_speed_mps=v0)
    sim.run(30.0)
    for s in sim.truth[::100]:
        t = s["t_s"]
        v_an = math.sqrt(a / b) * math.tan(math.atan(v0 * math.sqrt(b / a)) - math.sqrt(a * b) * t)
        assert s["vel_b_mps_x"] == pytest.approx(v_an, rel=0.01)
    assert sim.truth[-1]["vel_b_mps_x"] < 0.75 * v0  # it did slow down substantially


def _speed_pi(v_target, steer, kp=3000.0, ki=600.0):
    state = {"i": 0.0, "t": 0.0}

    def src(t, x):
        e = v_target - x[6]
        state["i"] += e * (t - state["t"])
        state["t"] = t
        force = kp * e + ki * state["i"]
        return Inputs(steer, (0.31 * force / 4,) * 4)
    return src


def test_steady_circle_matches_linear_bicycle_yaw_rate():
    """Linear tire, 20 m/s, small steer (a_y about 1.6 m/s^2): yaw rate = v delta / (L + K v^2)
    with K = m_f / C_f - m_r / C_r (axle static loads / g) within 2 %."""
    v, steer = 20.0, 0.06
    sim = Simulator(SEDAN, inputs=_speed_pi(v, steer), effects=EffectSet([LinearTire()]),
                    initial_speed_mps=v, record_truth=False)
    sim.step_to(12.0)
    s = sim.snapshot()
    m = sim.model
    wf, wr = m.static_load_n[0] + m.static_load_n[1], m.static_load_n[2] + m.static_load_n[3]
    p = SEDAN.params
    K = wf / G / p.cornering_stiffness_front_nprad - wr / G / p.cornering_stiffness_rear_nprad
    L = SEDAN.geometry.wheelbase_m
    delta = steer / SEDAN.geometry.steer_ratio
    vx = s["vel_b_mps_x"]
    r_bicycle = vx * delta / (L + K * vx ** 2)
    assert abs(s["angular_accel_b_radps2_z"]) < 1e-3  # steady
    assert s["rate_b_radps_z"] == pytest.approx(r_bicycle, rel=0.02)
    assert max(abs(s[f"slip_angle_rad_{i}"]) for i in range(1, 5)) < 0.02  # small slip


def test_braking_to_a_stop_keeps_slip_finite_and_stays_stopped():
    """Brake 800 N m per wheel from 20 m/s on a level road: the car stops (|v| < 0.05 m/s),
    never reverses, slip stays finite (|kappa| <= 1.5) and no wheel spins backwards."""
    sim = Simulator(SEDAN, inputs=Inputs(0.0, (0.0,) * 4, (800.0,) * 4),
                    effects=EffectSet([make_effect("magic_formula_tire", **SEDAN.effects["magic_formula_tire"])]),
                    initial_speed_mps=20.0)
    sim.run(8.0)
    for s in sim.truth:
        assert all(math.isfinite(s[f"slip_ratio_{i}"]) and abs(s[f"slip_ratio_{i}"]) <= 1.5 for i in range(1, 5))
        assert s["vel_b_mps_x"] > -0.05
        assert all(s[f"wheel_speed_radps_{i}"] > -0.5 for i in range(1, 5))
    end = sim.truth[-1]
    assert abs(end["vel_b_mps_x"]) < 0.05
    t_stop = next(s["t_s"] for s in sim.truth if s["vel_b_mps_x"] < 0.05)
    assert 2.5 < t_stop < 5.0  # 20 m/s at about 6 m/s^2


def test_reduced_model_lift_off_clamp_eq14():
    """Reduced model: a corner pulled up beyond the eq 14 clamp has zero normal load."""
    m = Model(SEDAN, unsprung_dof=False)
    x = m.design_state(0.0)
    x[3] = 0.25  # roll 14 deg right side down: the left corners rise far
    _, d = m.evaluate(x, Inputs(), Env())
    assert d["normal_load_n_1"] == 0.0 and d["normal_load_n_4"] == 0.0
    assert d["normal_load_n_2"] > 0.0 and d["normal_load_n_3"] > 0.0


def test_truth_model_lift_off_is_tire_deflection():
    """Truth model: normal load = k_t * tire deflection, zero when the wheel centre is above the
    free radius."""
    m = Model(SEDAN, unsprung_dof=True)
    x = m.design_state(0.0)
    x[2] += 0.05  # lift the whole car 5 cm: tires (static deflection 1.7 cm) leave the road
    _, d = m.evaluate(x, Inputs(), Env())
    assert all(d[f"normal_load_n_{i}"] == 0.0 for i in range(1, 5))
    x[2] -= 0.06
    _, d = m.evaluate(x, Inputs(), Env())
    kt = SEDAN.tire.vertical_stiffness_npm
    for i in range(1, 5):
        defl = m.tire_free_radius_m[i - 1] - d[f"wheel_centre_height_m_{i}"]
        assert d[f"normal_load_n_{i}"] == pytest.approx(kt * defl, rel=1e-12)


def test_max_stable_step_covers_one_millisecond():
    m = Model(SEDAN)
    tau = SEDAN.tire.wheel_inertia_kgm2 * 5.0 / (SEDAN.tire.rolling_radius_m ** 2 * 80000.0)
    assert m.wheel_spin_tau_floor_s == pytest.approx(tau)
    assert m.max_stable_step_s > 1e-3


def test_regressors_reproduce_linear_effect_contributions_on_simulated_data():
    """On a simulated coast-down snapshot, each linear effect's regressors times its parameters
    equal its contribution as the core applied it: drag force (long) and rolling-resistance
    torques (wheel_i)."""
    eff = _drag_rr_effects()
    sim = Simulator(SEDAN, inputs=Inputs(0.3), effects=eff, initial_speed_mps=25.0, env=Env(wind_enu_mps=(3.0, -4.0, 0.0)))
    sim.step_to(2.0)
    s = sim.snapshot()
    q = sim.model.regressor_quantities(s)
    d, rr = eff["aero_drag"], eff["rolling_resistance"]
    drag = d.body_wrench(None, None, (s["air_vel_b_mps_x"], s["air_vel_b_mps_y"], s["air_vel_b_mps_z"]))[0]
    assert d.regressors(q)["long"]["cda_m2"] * d.cda_m2 == pytest.approx(drag, rel=1e-12)
    for i in range(1, 5):
        assert rr.regressors(q)[f"wheel_{i}"]["coefficient"] * rr.coefficient == pytest.approx(
            s[f"effect_wheel_torque_nm_{i}"], rel=1e-12)


def test_state_from_named_parts():
    m = Model(SEDAN, unsprung_dof=False)
    x = m.state_from((1, 2, 3), (0.1, 0.0, 0.5), (20, 0, 0), (0, 0, 0.1), (64.5,) * 4)
    assert len(x) == m.layout.size == 16 and x[m.layout.euler_g][2] == 0.5
    assert len(Model(SEDAN).state_from((0,) * 3, (0,) * 3, (0,) * 3, (0,) * 3, (0,) * 4)) == 24


@pytest.mark.parametrize("compiled", [True, False])
def test_corner_kinematics_are_evaluates_named_slips_and_wheel_angles(compiled):
    """``Model.corner_kinematics`` (the identifier's feeder) returns exactly ``evaluate``'s
    ``slip_ratio_i``, ``slip_angle_rad_i`` and ``road_wheel_angle_rad_i``, compiled core or not,
    on a cornering, braking state with the wheels spinning at different speeds."""
    model = Model(load_vehicle("sedan-model", "model"), unsprung_dof=False)
    if not compiled:
        model.f = model.f_python
    x = model.design_state(speed_mps=18.0)
    x[7], x[9], x[11] = 0.3, 0.05, 0.25
    x[12:16] = [55.0, 56.5, 57.5, 58.0]
    u, env = Inputs(steer_wheel_angle_rad=0.9), Env(0.02, -0.01)
    slip, alpha, delta = model.corner_kinematics(x, u, env)
    _, d = model.evaluate(x, u, env)
    assert slip == tuple(d[f"slip_ratio_{i}"] for i in range(1, 5))
    assert alpha == tuple(d[f"slip_angle_rad_{i}"] for i in range(1, 5))
    assert delta == tuple(d[f"road_wheel_angle_rad_{i}"] for i in range(1, 5))
    assert delta[0] > delta[1] > 0.0 and delta[2:] == (0.0, 0.0) and min(abs(v) for v in slip) > 1e-3
