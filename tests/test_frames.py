"""Eq 1-5 and C_omega: orthonormality, eq 4 round trips, Euler round trips, C_omega against
the DCM kinematics Cdot = -[omega x] C (finite differences, tolerance 1e-7)."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.model import frames as fr
from vdps_hil.units import GRAVITY_MPS2

ang = st.floats(min_value=-math.pi + 1e-3, max_value=math.pi - 1e-3)
tilt = st.floats(min_value=-1.4, max_value=1.4)  # inside the valid pitch range
small = st.floats(min_value=-0.5, max_value=0.5)


@given(ang, tilt, ang)
def test_dcm_orthonormal(phi, theta, psi):
    c = fr.dcm_global_to_vehicle(phi, theta, psi)
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(c) - 1.0) < 1e-12


@given(ang, tilt, ang)
def test_euler_round_trip(phi, theta, psi):
    got = fr.euler_ypr_from_dcm(fr.dcm_global_to_vehicle(phi, theta, psi))
    np.testing.assert_allclose(got, (phi, theta, psi), atol=1e-9)


@given(tilt, ang, ang)
def test_road_angles_round_trip(phi_r, theta_r, psi_r):
    got = fr.road_angles_from_dcm(fr.dcm_global_to_road(phi_r, theta_r, psi_r))
    np.testing.assert_allclose(got, (phi_r, theta_r, psi_r), atol=1e-9)


@given(small, small, ang, small, small)
def test_eq4_compose_decompose(phi_v, theta_v, psi_v, phi_r, theta_r):
    g = fr.compose_absolute(phi_v, theta_v, psi_v, phi_r, theta_r)
    np.testing.assert_allclose(fr.decompose_vehicle(*g, phi_r, theta_r), (phi_v, theta_v, psi_v), atol=1e-9)
    np.testing.assert_allclose(fr.decompose_road(*g, phi_v, theta_v, psi_v)[:2], (phi_r, theta_r), atol=1e-9)


@settings(max_examples=50)
@given(ang, tilt, ang, st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_c_omega_matches_dcm_kinematics(phi, theta, psi, rates):
    a, ad, h = np.array([phi, theta, psi]), np.array(rates), 1e-6
    c = fr.dcm_global_to_vehicle(*a)
    cd = (fr.dcm_global_to_vehicle(*(a + ad * h)) - fr.dcm_global_to_vehicle(*(a - ad * h))) / (2 * h)
    w_skew = -cd @ c.T  # Cdot = -[w x] C for C = C_g^v and w in body axes
    w = np.array([w_skew[2, 1], w_skew[0, 2], w_skew[1, 0]])
    np.testing.assert_allclose(fr.c_omega(phi, theta) @ ad, w, atol=1e-7)
    np.testing.assert_allclose(fr.c_omega_inv(phi, theta) @ fr.c_omega(phi, theta), np.eye(3), atol=1e-9)


def test_dcm_batch_equals_eq1():
    rng = np.random.default_rng(1)
    a = rng.uniform(-1, 1, (5, 3))
    c = fr.dcm_gv_batch(a[:, 0], a[:, 1], a[:, 2])
    for k in range(5):
        assert np.allclose(c[k], fr.dcm_global_to_vehicle(*a[k]), atol=1e-12)


def test_sign_conventions_physical():
    # pitch nose up: the vehicle x axis (row 0 of C_g^v) points up for theta > 0
    assert fr.dcm_global_to_vehicle(0.0, 0.1, 0.0)[0, 2] > 0
    # roll right side down: the vehicle y axis (left) points up for phi > 0
    assert fr.dcm_global_to_vehicle(0.1, 0.0, 0.0)[1, 2] > 0
    # yaw CCW from East: psi = pi/2 points x north
    np.testing.assert_allclose(fr.dcm_global_to_vehicle(0, 0, math.pi / 2)[0], [0, 1, 0], atol=1e-12)


def test_gravity_on_paper_road():
    # bank +2 deg (right edge low) pulls to the right (-y); grade -2 deg (downhill) pushes forward
    g = fr.gravity_in_aux(math.radians(2), math.radians(-2), 0.0, GRAVITY_MPS2)
    assert g[0] > 0 and g[1] < 0
    np.testing.assert_allclose(np.linalg.norm(g), GRAVITY_MPS2, rtol=1e-12)
    np.testing.assert_allclose(g[0], GRAVITY_MPS2 * math.sin(math.radians(2)), rtol=1e-12)


def test_eq5_suspension_attitude():
    lf, lr, t = 1.2, 1.5, 0.79
    # all four compressed 1 cm: body 1 cm lower, level
    z, th, ph = fr.suspension_to_road_attitude([0.01] * 4, lf, lr, t, t)
    assert math.isclose(z, -0.01 * (lr + lf) / (lf + lr), abs_tol=1e-15) and th == 0 and ph == 0
    # front compressed: nose down -> theta < 0; right side compressed: right down -> phi > 0
    assert fr.suspension_to_road_attitude([0.01, 0.01, 0, 0], lf, lr, t, t)[1] < 0
    assert fr.suspension_to_road_attitude([0, 0.01, 0.01, 0], lf, lr, t, t)[2] > 0
    # exact geometry: rigid rotation by theta about the CG
    th0 = 0.02
    s = math.sin(th0)  # nose up: front rises lf*s, rear sinks lr*s; compression = -(rise)
    h = [-lf * s, -lf * s, lr * s, lr * s]
    assert math.isclose(fr.suspension_to_road_attitude(h, lf, lr, t, t)[1], th0, rel_tol=1e-12)
