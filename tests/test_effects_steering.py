"""Steering compliance: the implicit compliance equation is solved exactly, and the understeer
gradient rises by the analytic amount W_f K_c / g. The steering-angle sensor's offset: what the
sensor reports, in the effect and in a simulated drive's steering sensor."""

import math

import pytest

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import REGISTRY, EffectConfigError, EffectSet, LinearTire, SteeringCompliance, SteeringOffset
from vdps_hil.model.effects.base import ImuKinematics
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


def test_steering_offset_adds_to_the_steering_reading_only():
    kin = ImuKinematics(0.0, (0.0, 0.0, 9.81), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    e = SteeringOffset(offset_rad=0.03)
    out = e.apply({"steer_wheel_angle_rad": 0.5, "specific_force_mps2_x": 1.0}, kin)
    assert out == {"steer_wheel_angle_rad": 0.5 + 0.03, "specific_force_mps2_x": 1.0}
    assert e.apply({"specific_force_mps2_x": 1.0}, kin) == {"specific_force_mps2_x": 1.0}
    assert e.regressors(kin) == {"steer_wheel_angle_rad": {"offset_rad": 1.0}}
    assert REGISTRY["steering_offset"] is SteeringOffset and SteeringOffset.family == "measurement"
    with pytest.raises(EffectConfigError):
        REGISTRY.make("steering_offset", offset_rad=float("nan"))


def test_a_simulated_steering_sensor_reads_the_wheel_angle_plus_the_offset():
    """A drive with the offset in the truth: the chassis steering sensor reports the truth's
    steering wheel angle plus 0.03 rad: against the same sensor without it (the same seeded
    noise), exactly 0.03 at every sample."""
    import numpy as np

    from vdps_hil.sim.profiles import load_profile
    from vdps_hil.sim.sampling import Block
    from vdps_hil.sim.sensors import chassis_sensors

    prof = load_profile("table1")
    sensors = chassis_sensors(prof, seed=3, dt_ns=1_000_000, effects=[SteeringOffset(offset_rad=0.03)])
    steer = next(s for s in sensors if s.name == "steering")
    plain = next(s for s in chassis_sensors(prof, seed=3, dt_ns=1_000_000) if s.name == "steering")

    n = np.arange(200)
    block = Block.build(n, 1_000_000, steer=np.linspace(-0.2, 0.4, 200))  # 1 kHz truth steps, 0.2 s
    t1, v1 = steer.sample(block)
    t0, v0 = plain.sample(block)
    assert len(t1) > 10 and np.array_equal(t1, t0)
    assert np.allclose(v1 - v0, 0.03, rtol=0, atol=1e-12)  # the same seeded noise on both
