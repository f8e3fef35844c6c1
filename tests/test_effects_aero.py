"""Aerodynamic effects: drag force and regressor, drag coast-down against the analytic
solution, crosswind side force and yaw moment entering the dynamics at the centre of pressure."""

import math

import pytest

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import AeroDrag, Crosswind, EffectSet, make_effect
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.simulator import Simulator

SEDAN = load_vehicle("sedan-truth")


def test_drag_force_and_regressor():
    d = AeroDrag(cda_m2=0.7)
    fx = d.body_wrench((25.0, 0.0, 0.0), (0, 0, 0), (25.0, 0.0, 0.0))[0]
    assert fx == pytest.approx(-0.5 * 1.225 * 0.7 * 625.0)
    reg = d.regressors({"air_vel_b_mps_x": 25.0, "air_vel_b_mps_y": 0.0})
    assert reg["long"]["cda_m2"] * 0.7 == pytest.approx(fx, rel=1e-12)


def test_drag_only_coast_down_is_analytic():
    """Drag only: m_eff dv/dt = -b' v^2 -> v = v0 / (1 + b v0 t), b = 1/2 rho CdA / m_eff.
    Within 1 % over 20 s (CdA 0.7 m^2, from 30 m/s)."""
    d = AeroDrag()
    m_eff = SEDAN.params.mass_kg + 4 * SEDAN.tire.wheel_inertia_kgm2 / SEDAN.tire.rolling_radius_m ** 2
    b = 0.5 * d.air_density_kgpm3 * d.cda_m2 / m_eff
    sim = Simulator(SEDAN, inputs=Inputs(), effects=EffectSet([d]), initial_speed_mps=30.0)
    sim.run(20.0)
    for s in sim.truth[::200]:
        assert s["vel_b_mps_x"] == pytest.approx(30.0 / (1 + b * 30.0 * s["t_s"]), rel=0.01)
    assert sim.truth[-1]["vel_b_mps_x"] < 27.0


def test_crosswind_wrench_and_regressors():
    w = Crosswind()
    assert w.wind_enu_mps() == pytest.approx((0.0, 10.0, 0.0), abs=1e-12)
    air = (25.0, -10.0, 0.0)  # car driving east, wind toward north: air comes from the right
    fx, fy, fz, mx, my, mz = w.body_wrench((25.0, 0, 0), (0, 0, 0), air)
    expect = -0.5 * 1.225 * 5.0 * math.hypot(25.0, 10.0) * -10.0
    assert fy == pytest.approx(expect) and fy > 0  # pushed to the left (north)
    assert mz == pytest.approx(0.5 * fy)  # centre of pressure ahead: yaws the nose away from the wind
    reg = w.regressors({"air_vel_b_mps_x": 25.0, "air_vel_b_mps_y": -10.0})
    assert reg["lat"]["side_force_area_m2"] * 5.0 == pytest.approx(fy)
    assert reg["yaw"]["side_force_area_m2"] * 5.0 == pytest.approx(mz)


def test_crosswind_initial_response_is_side_force_over_mass_and_moment_over_inertia():
    """Straight at 25 m/s east, 10 m/s wind toward north: at t = 0 the lateral acceleration is
    a_y = F_y / m_tot and the yaw acceleration (x_cp F_y + 2 m_u (l_r - l_f) a_y) / I_z exactly
    (the tires carry no lateral force yet; the unsprung masses at the axles translate with the
    CG); the car then drifts north and yaws left."""
    w = Crosswind()
    m = Model(SEDAN, EffectSet([w]))
    x = m.design_state(25.0)
    raw = {}
    xd = m.f(x, Inputs(), Env(), raw)
    fy = w.body_wrench(None, None, (25.0, -10.0, 0.0))[1]
    assert raw["_acc_b"][1] == pytest.approx(fy / SEDAN.params.mass_kg, rel=1e-12)
    ay = fy / SEDAN.params.mass_kg
    g = SEDAN.geometry
    mz = 0.5 * fy + 2 * SEDAN.front.unsprung_mass_kg * (g.l_r_m - g.l_f_m) * ay
    assert xd[11] == pytest.approx(mz / SEDAN.params.inertia_z_kgm2, rel=1e-12)
    sim = Simulator(SEDAN, inputs=Inputs(), effects=EffectSet([w]), initial_speed_mps=25.0)
    sim.run(2.0)
    end = sim.truth[-1]
    assert end["pos_n_m"] > 0.5 and end["yaw_g_rad"] > 0.0


def test_wind_enters_drag_through_air_velocity():
    """A 10 m/s headwind raises the drag force by (35/25)^2."""
    d = make_effect("aero_drag")
    m = Model(SEDAN, EffectSet([d]))
    x = m.design_state(25.0)
    out = []
    for wind in ((0.0, 0.0, 0.0), (-10.0, 0.0, 0.0)):
        raw = {}
        m.f(x, Inputs(), Env(wind_enu_mps=wind), raw)
        out.append(raw["_force_b"][0])
    assert out[1] / out[0] == pytest.approx((35.0 / 25.0) ** 2, rel=1e-9)
