"""Rolling resistance: wheel torque law, regressor, and the analytic coast-down (constant
deceleration f_r g m / m_eff)."""

import pytest

from vdps_hil.model.core import Inputs
from vdps_hil.model.effects import EffectSet, RollingResistance
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.simulator import Simulator
from vdps_hil.units import GRAVITY_MPS2 as G

SEDAN = load_vehicle("sedan-truth")


def test_torque_law_and_regressor():
    rr = RollingResistance(coefficient=0.012)
    assert rr.wheel_torque(0, 80.0, 4000.0, 0.31) == pytest.approx(-0.012 * 0.31 * 4000.0)
    assert rr.wheel_torque(0, -80.0, 4000.0, 0.31) == pytest.approx(0.012 * 0.31 * 4000.0)
    assert rr.wheel_torque(0, 0.0, 4000.0, 0.31) == 0.0  # continuous at standstill
    q = {}
    for i in range(1, 5):
        q.update({f"rolling_radius_m_{i}": 0.31, f"normal_load_n_{i}": 4000.0 + i, f"wheel_speed_radps_{i}": 50.0})
    reg = rr.regressors(q)
    for i in range(1, 5):
        assert reg[f"wheel_{i}"]["coefficient"] * 0.012 == pytest.approx(rr.wheel_torque(i - 1, 50.0, 4000.0 + i, 0.31))


def test_rolling_resistance_coast_down_is_linear():
    """Rolling resistance only, level road: dv/dt = -f_r g m / m_eff (constant) within 1 %."""
    rr = RollingResistance()
    m = SEDAN.params.mass_kg
    m_eff = m + 4 * SEDAN.tire.wheel_inertia_kgm2 / SEDAN.tire.rolling_radius_m ** 2
    decel = rr.coefficient * G * m / m_eff
    sim = Simulator(SEDAN, inputs=Inputs(), effects=EffectSet([rr]), initial_speed_mps=20.0)
    sim.run(20.0)
    for s in sim.truth[100::200]:
        assert s["vel_b_mps_x"] == pytest.approx(20.0 - decel * s["t_s"], rel=0.01)
    # the road's longitudinal force on each tire is -f_r F_z in steady rolling
    s = sim.truth[-1]
    for i in range(1, 5):
        assert s[f"tire_force_long_n_{i}"] == pytest.approx(
            -rr.coefficient * s[f"normal_load_n_{i}"] - SEDAN.tire.wheel_inertia_kgm2 * s[f"wheel_accel_radps2_{i}"] / 0.31,
            rel=1e-3)
