"""Steering compliance: the implicit compliance equation is solved exactly, and the understeer
gradient rises by the analytic amount W_f K_c / g."""

import math

import pytest

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet, LinearTire, SteeringCompliance
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.simulator import Simulator
from vdps_hil.units import GRAVITY_MPS2 as G

SEDAN = load_vehicle("sedan-truth")


def test_compliance_equation_is_satisfied_exactly_with_linear_tires():
    kc = 2e-6
    m = Model(SEDAN, EffectSet([LinearTire(), SteeringCompliance(compliance_radpn=kc)]))
    x = m.design_state(20.0)
    x[7], x[11] = 0.3, 0.1  # some sideslip and yaw rate
    _, d = m.evaluate(x, Inputs(0.5), Env())
    from vdps_hil.model.stages import ackermann_angles
    d1, d2 = ackermann_angles(0.5 / SEDAN.geometry.steer_ratio, SEDAN.geometry.wheelbase_m,
                              SEDAN.geometry.track_half_front_m)
    fy = d["tire_force_lat_n_1"] + d["tire_force_lat_n_2"]
    assert d["road_wheel_angle_rad_1"] == pytest.approx(d1 - kc * fy, abs=1e-12)
    assert d["road_wheel_angle_rad_2"] == pytest.approx(d2 - kc * fy, abs=1e-12)


def _understeer_gradient(effects, steer=0.06, v=20.0):
    """K = (delta_m - L r / v_x) / a_y from a steady turn with the speed held by a PI."""
    st = {"i": 0.0, "t": 0.0}

    def src(t, x):
        e = v - x[6]
        st["i"] += e * (t - st["t"])
        st["t"] = t
        return Inputs(steer, (0.31 * (3000 * e + 600 * st["i"]) / 4,) * 4)
    sim = Simulator(SEDAN, inputs=src, effects=effects, initial_speed_mps=v, record_truth=False)
    sim.step_to(12.0)
    s = sim.snapshot()
    vx, r = s["vel_b_mps_x"], s["rate_b_radps_z"]
    ay = vx * r
    return (steer / SEDAN.geometry.steer_ratio - SEDAN.geometry.wheelbase_m * r / vx) / ay, sim


def test_compliance_raises_understeer_gradient_by_analytic_amount():
    """Delta K_us = W_f K_c / g [rad/(m/s^2)] (W_f static front axle load): within 3 %."""
    kc = 2e-6
    k0, sim = _understeer_gradient(EffectSet([LinearTire()]))
    k1, _ = _understeer_gradient(EffectSet([LinearTire(), SteeringCompliance(compliance_radpn=kc)]))
    wf = sim.model.static_load_n[0] + sim.model.static_load_n[1]
    expected = wf * kc / G
    assert k1 - k0 == pytest.approx(expected, rel=0.03)
    assert math.degrees(expected) * G == pytest.approx(1.0, abs=0.05)  # the default is about 1 deg/g


def test_regressor_first_order():
    e = SteeringCompliance()
    r = e.regressors({"cornering_stiffness_front_nprad": 120000.0, "front_lateral_force_n": 3000.0, "l_f_m": 1.2})
    assert r["lat"]["compliance_radpn"] == -120000.0 * 3000.0
    assert r["yaw"]["compliance_radpn"] == pytest.approx(1.2 * -120000.0 * 3000.0)
