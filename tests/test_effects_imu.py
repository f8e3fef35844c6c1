"""IMU measurement effects: biases, and the lever arm against the exact kinematics of a point on
a rigid body in uniform circular motion (1e-9)."""

import math

import numpy as np
import pytest

from vdps_hil.model.core import Inputs
from vdps_hil.model.effects import EffectSet, ImuBias, ImuKinematics, ImuLeverArm
from vdps_hil.model.frames import c_omega, dcm_global_to_vehicle
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.simulator import Simulator
from vdps_hil.units import GRAVITY_MPS2 as G

SEDAN = load_vehicle("sedan-truth")
F = ("specific_force_mps2_x", "specific_force_mps2_y", "specific_force_mps2_z")
W = ("angular_rate_radps_x", "angular_rate_radps_y", "angular_rate_radps_z")


def _fields(kin):
    return {**dict(zip(F, kin.specific_force_mps2)), **dict(zip(W, kin.angular_rate_radps)), "imu_temperature_c": 25.0}


def test_bias_at_rest_reads_gravity_plus_bias():
    sim = Simulator(SEDAN, inputs=Inputs(), effects=EffectSet())
    kin = sim.kinematics()
    b = ImuBias()
    out = b.apply(_fields(kin), kin)
    assert out["specific_force_mps2_z"] == pytest.approx(G + 0.05, rel=1e-12)
    assert out["specific_force_mps2_x"] == pytest.approx(0.05, abs=1e-12)
    assert out["angular_rate_radps_y"] == pytest.approx(math.radians(0.1), abs=1e-15)
    assert out["imu_temperature_c"] == 25.0  # other fields pass through
    reg = b.regressors(kin)
    assert reg["specific_force_mps2_y"] == {"accel_bias_y_mps2": 1.0}


def test_lever_arm_on_an_exact_steady_circle():
    """Rigid body yawing at Omega about the vertical through c, with constant roll, pitch and
    sideslip: every point's acceleration is -Omega^2 (horizontal offset from c). The effect's
    f_imu = f_cg + omega_dot x r + omega x (omega x r) matches it to 1e-9."""
    omega_z, radius = 0.4, 50.0
    phi, theta, beta = 0.05, -0.02, 0.03
    c = np.array([0.0, radius, 0.0])
    p_cg = np.array([0.0, 0.0, 0.55])
    psi = beta  # heading tangent to the circle (east) plus a sideslip rotation
    cgv = dcm_global_to_vehicle(phi, theta, psi)
    omega_b = c_omega(phi, theta) @ np.array([0.0, 0.0, omega_z])
    g_g = np.array([0.0, 0.0, -G])

    def accel_g(p):
        d = p - c
        d[2] = 0.0
        return -omega_z ** 2 * d

    f_cg = cgv @ (accel_g(p_cg.copy()) - g_g)
    kin = ImuKinematics(0.0, tuple(f_cg), tuple(omega_b), (0.0, 0.0, 0.0))
    for r in ((0.5, 0.0, 0.0), (1.2, -0.4, 0.8), (-2.0, 0.7, -0.3)):
        e = ImuLeverArm(lever_x_m=r[0], lever_y_m=r[1], lever_z_m=r[2])
        out = e.apply(_fields(kin), kin)
        p_imu = p_cg + cgv.T @ np.array(r)
        expect = cgv @ (accel_g(p_imu) - g_g)
        got = np.array([out[k] for k in F])
        assert np.max(np.abs(got - expect)) < 1e-9
        reg = e.regressors(kin)
        lin = np.array([sum(reg[k][n] * v for n, v in zip(("lever_x_m", "lever_y_m", "lever_z_m"), r)) for k in F])
        assert np.max(np.abs(f_cg + lin - expect)) < 1e-9
        assert out["angular_rate_radps_z"] == kin.angular_rate_radps[2]


def test_lever_arm_on_simulated_steady_circle():
    """On a simulated steady circle (omega_dot about 0) the longitudinal reading of an IMU 1 m
    ahead of the CG differs from the CG's by the centripetal term -(omega_y^2 + omega_z^2) * 1 m
    (within 2 %)."""
    sim = Simulator(SEDAN, inputs=Inputs(0.8, (180.0,) * 4), initial_speed_mps=12.0, record_truth=False)
    sim.step_to(10.0)
    kin = sim.kinematics()
    out = ImuLeverArm(lever_x_m=1.0, lever_y_m=0.0, lever_z_m=0.0).apply(_fields(kin), kin)
    wx, wy, wz = kin.angular_rate_radps
    dx = out["specific_force_mps2_x"] - kin.specific_force_mps2[0]
    assert dx == pytest.approx(-(wy * wy + wz * wz), rel=0.02)
