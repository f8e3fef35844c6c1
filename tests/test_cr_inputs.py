"""Tests of ``vdps_hil.sim.cr_inputs``: the dead-beat steering servo (sign, one-step lag, the
package's rate and angle limits), wheel torques -> acceleration (our brake law, the package's
power limit, no reversing) and the per-wheel split the truth records (property: the applied
torques always sum to m R_w u2, brakes are magnitudes)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.model.core import Inputs
from vdps_hil.sim.cr_inputs import InputMapping
from vdps_hil.sim.cr_model import load_parameters

H = 1e-3  # step [s]


def mapping(set_id=1, ratio=16.0):
    return InputMapping(load_parameters(set_id), ratio)


def test_steering_is_dead_beat_with_the_package_sign():
    m = mapping()
    ci = m.map(Inputs(0.0032), 0.0, 20.0, (0.0,) * 4, H)  # 0.0032 rad at the wheel = 0.2 mrad road wheel, left
    assert ci.road_wheel_angle_cmd_rad == pytest.approx(-0.0002)  # the package steers right-positive
    assert ci.steer_rate_radps == pytest.approx(-0.2)  # reaches the command in one step
    assert not ci.steer_limited
    held = m.map(Inputs(0.0032), -0.0002, 20.0, (0.0,) * 4, H)
    assert held.steer_rate_radps == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("set_id", [1, 3])
def test_steering_rate_and_angle_limits_are_the_packages(set_id):
    p = load_parameters(set_id)
    m = mapping(set_id)
    fast = m.map(Inputs(1.0), 0.0, 20.0, (0.0,) * 4, H)
    assert fast.steer_rate_radps == pytest.approx(p.steering.v_min) and fast.steer_limited
    at_stop = m.map(Inputs(-30.0), p.steering.max, 20.0, (0.0,) * 4, H)
    assert at_stop.steer_rate_radps == 0.0 and at_stop.steer_limited


def test_torques_give_the_acceleration_of_the_whole_mass_and_the_packages_split():
    p1, p3 = load_parameters(1), load_parameters(3)
    spins = (50.0,) * 4
    d1 = mapping(1).map(Inputs(0.0, (100.0,) * 4), 0.0, 15.0, spins, H)
    assert d1.accel_mps2 == pytest.approx(400.0 / (p1.m * p1.R_w))
    assert d1.wheel_torque_nm == pytest.approx((200.0, 200.0, 0.0, 0.0))  # set 1: front drive (T_se = 1)
    assert d1.brake_torque_nm == (0.0,) * 4
    d3 = mapping(3).map(Inputs(0.0, (100.0,) * 4), 0.0, 15.0, spins, H)
    assert d3.wheel_torque_nm == pytest.approx((0.0, 0.0, 200.0, 200.0))  # set 3: rear drive (T_se = 0)
    b1 = mapping(1).map(Inputs(0.0, (0.0,) * 4, (250.0,) * 4), 0.0, 15.0, spins, H)
    assert b1.accel_mps2 == pytest.approx(-1000.0 / (p1.m * p1.R_w))
    assert b1.wheel_torque_nm == pytest.approx((-380.0, -380.0, -120.0, -120.0))  # T_sb = 0.76
    assert b1.brake_torque_nm == pytest.approx((380.0, 380.0, 120.0, 120.0))
    b3 = mapping(3).map(Inputs(0.0, (0.0,) * 4, (250.0,) * 4), 0.0, 15.0, spins, H)
    assert sum(b3.wheel_torque_nm[:2]) == pytest.approx(-1000.0 * p3.T_sb)


def test_our_brake_law_the_power_limit_and_no_reversing():
    p = load_parameters(1)
    m = mapping(1)
    slow = m.map(Inputs(0.0, (0.0,) * 4, (400.0,) * 4), 0.0, 0.3, (1.0,) * 4, H)
    assert slow.accel_mps2 == pytest.approx(-4 * 400.0 * 0.5 / (p.m * p.R_w))  # sat(1 / 2) = 0.5
    fast = m.map(Inputs(0.0, (2000.0,) * 4), 0.0, 25.0, (70.0,) * 4, H)
    assert fast.accel_limited
    assert fast.accel_mps2 == pytest.approx(p.longitudinal.a_max * p.longitudinal.v_switch / 25.0)
    stopped = m.map(Inputs(0.0, (-50.0,) * 4), 0.0, 0.0, (0.0,) * 4, H)
    assert stopped.accel_mps2 == 0.0 and stopped.wheel_torque_nm == (0.0,) * 4


@settings(max_examples=200, deadline=None)
@given(drive=st.lists(st.floats(-800, 800), min_size=4, max_size=4),
       brake=st.lists(st.floats(0, 3000), min_size=4, max_size=4),
       spin=st.lists(st.floats(0, 120), min_size=4, max_size=4),
       speed=st.floats(0, 45), steer=st.floats(-10, 10), delta=st.floats(-0.9, 0.9),
       set_id=st.sampled_from([1, 3]))
def test_applied_torques_sum_to_m_r_u2_and_brakes_are_magnitudes(drive, brake, spin, speed, steer, delta, set_id):
    p = load_parameters(set_id)
    ci = mapping(set_id).map(Inputs(steer, tuple(drive), tuple(brake)), delta, speed, tuple(spin), H)
    assert math.isfinite(ci.accel_mps2) and abs(ci.accel_mps2) <= p.longitudinal.a_max + 1e-9
    assert sum(ci.wheel_torque_nm) == pytest.approx(p.m * p.R_w * ci.accel_mps2, rel=1e-9, abs=1e-6)
    assert all(b >= 0.0 for b in ci.brake_torque_nm)
    assert abs(ci.steer_rate_radps) <= p.steering.v_max + 1e-12
    assert ci.u == [ci.steer_rate_radps, ci.accel_mps2]
