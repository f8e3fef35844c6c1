"""Process model of eq 7 with correction (d): DCM partials, Euler-rate partials, eq-4 Jacobian
and F = df/dx against central differences (tolerance 1e-6 absolute on O(1) entries); the
discrete mean-input step integrates exact IMU signals of a rigid-body motion."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from vdps_hil.estimation import kinematics as K
from vdps_hil.model import frames as fr
from vdps_hil.units import GRAVITY_MPS2

ang = st.floats(-3.0, 3.0)
tilt = st.floats(-1.2, 1.2)


def _num_jac(fun, x, h=1e-6):
    x = np.asarray(x, dtype=float)
    y0 = np.asarray(fun(x))
    j = np.empty((y0.size, x.size))
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = h
        j[:, i] = (np.asarray(fun(x + d)) - np.asarray(fun(x - d))).ravel() / (2 * h)
    return j


@settings(max_examples=40, deadline=None)
@given(ang, tilt, ang)
def test_dcm_and_partials(phi, theta, psi):
    c, d_f, d_t, d_p = K.dcm_gv_partials(phi, theta, psi)
    np.testing.assert_allclose(c, fr.dcm_global_to_vehicle(phi, theta, psi), atol=1e-14)
    h = 1e-6
    for d, k in ((d_f, 0), (d_t, 1), (d_p, 2)):
        a = np.array([phi, theta, psi])
        e = np.zeros(3)
        e[k] = h
        num = (fr.dcm_global_to_vehicle(*(a + e)) - fr.dcm_global_to_vehicle(*(a - e))) / (2 * h)
        np.testing.assert_allclose(d, num, atol=1e-8)


@settings(max_examples=40, deadline=None)
@given(tilt, tilt)
def test_road_dcm_and_normal(phi_r, theta_r):
    c, d_f, d_t = K.dcm_gr_partials(phi_r, theta_r)
    np.testing.assert_allclose(c, fr.dcm_global_to_road(phi_r, theta_r), atol=1e-14)
    n, n_f, n_t = K.road_normal(phi_r, theta_r)
    np.testing.assert_allclose(n, c[2], atol=1e-15)
    np.testing.assert_allclose(n_f, d_f[2], atol=1e-15)
    np.testing.assert_allclose(n_t, d_t[2], atol=1e-15)
    h = 1e-6
    road = fr.dcm_global_to_road
    np.testing.assert_allclose(d_f, (road(phi_r + h, theta_r) - road(phi_r - h, theta_r)) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(d_t, (road(phi_r, theta_r + h) - road(phi_r, theta_r - h)) / (2 * h), atol=1e-8)


@settings(max_examples=40, deadline=None)
@given(ang, tilt, st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_euler_rates_and_partials(phi, theta, w):
    r, r_f, r_t = K.euler_rates(phi, theta, w)
    np.testing.assert_allclose(r, fr.c_omega_inv(phi, theta) @ np.array(w), atol=1e-12)
    np.testing.assert_allclose(K.euler_rate_matrix(phi, theta), fr.c_omega_inv(phi, theta), atol=1e-14)
    num = _num_jac(lambda a: K.euler_rates(a[0], a[1], w)[0], [phi, theta])
    np.testing.assert_allclose(np.stack([r_f, r_t], axis=1), num, atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4), ang, st.floats(-0.3, 0.3), st.floats(-0.3, 0.3))
def test_vehicle_angles_eq4_and_jacobian(phi, theta, psi, phi_r, theta_r):
    a5 = np.array([phi, theta, psi, phi_r, theta_r])
    ang_v, jac = K.vehicle_angles_eq4(a5)
    np.testing.assert_allclose(ang_v, fr.decompose_vehicle(*a5), atol=1e-12)
    num = _num_jac(lambda a: K.vehicle_angles_eq4(a, False), a5)
    np.testing.assert_allclose(jac, num, atol=1e-7)
    np.testing.assert_allclose(K.road_relative_dcm(a5), fr.dcm_global_to_vehicle(phi, theta, psi)
                               @ fr.dcm_global_to_road(phi_r, theta_r).T, atol=1e-14)


def test_process_jacobian_against_finite_differences(rng):
    for _ in range(25):
        x = rng.normal(size=12) * np.array([100, 100, 10, 20, 20, 2, .4, .4, 3, .1, .1, 3])
        f = rng.normal(size=3) * 3 + np.array([0, 0, GRAVITY_MPS2])
        w = rng.normal(size=3) * 0.5
        F = K.process_jacobian(x, f, w)
        num = _num_jac(lambda xx: K.process_f(xx, f, w), x)
        np.testing.assert_allclose(F, num, atol=1e-6)
        F2, G = K.linearize(x, f, w)
        np.testing.assert_array_equal(F, F2)
        np.testing.assert_allclose(G, _num_jac(lambda u: K.process_f(x, u[:3], u[3:]), np.r_[f, w]), atol=1e-6)
        np.testing.assert_allclose(K.noise_input_matrix(x), G, atol=1e-15)


def test_gravity_correction_d():
    """At rest the accelerometer reads +g up: with (d) the velocity stays constant; eq 7 as
    printed (gravity 0) accelerates upwards at g."""
    x = np.zeros(12)
    x[6:9] = (0.1, -0.05, 1.0)
    f_rest = fr.dcm_gv(*x[6:9]) @ np.array([0.0, 0.0, GRAVITY_MPS2])
    np.testing.assert_allclose(K.process_f(x, f_rest, np.zeros(3))[3:6], 0.0, atol=1e-12)
    np.testing.assert_allclose(K.process_f(x, f_rest, np.zeros(3), gravity_mps2=0.0)[3:6], [0, 0, GRAVITY_MPS2],
                               atol=1e-12)


def test_transition_matches_expm(rng):
    x = rng.normal(size=12) * 0.3
    F = K.process_jacobian(x, np.array([1.0, -0.5, 9.9]), np.array([0.1, 0.2, 0.3]))
    dt = 0.01
    # the series stops at second order: the residual is O((|F| dt)^3)
    assert np.abs(K.transition(F, dt) - expm(F * dt)).max() < (np.abs(F).max() * dt) ** 3


def test_step_integrates_a_coordinated_turn_exactly():
    """Constant yaw rate r on a level road at speed V: body specific force [0, V r, g], gyro
    [0, 0, r]; after 20 s at 1 kHz the position is on the circle of radius V / r (error < 1 mm,
    heading error < 1e-9 rad)."""
    V, r, dt, n = 20.0, 0.2, 1e-3, 20000
    x = np.zeros(12)
    x[3] = V
    f, w = np.array([0.0, V * r, GRAVITY_MPS2]), np.array([0.0, 0.0, r])
    for _ in range(n):
        x = K.step(x, f, w, dt)
    t = n * dt
    rad = V / r
    np.testing.assert_allclose(x[0:2], [rad * math.sin(r * t), rad * (1 - math.cos(r * t))], atol=1e-3)
    np.testing.assert_allclose(x[3:5], [V * math.cos(r * t), V * math.sin(r * t)], atol=1e-4)
    assert abs(x[2]) < 1e-9 and abs(x[5]) < 1e-9
    assert abs(x[8] - r * t) < 1e-9


def test_vehicle_angles_eq4_is_bit_equal_to_one_matmul_per_product(rng):
    """The six 3 x 3 products of eq 4's angles and Jacobian, made in one (12 x 3) (9 x 3)^T
    matmul, equal the one-call-per-product form (C_g^v C_g^r^T and the partials) bit for bit."""
    for k in range(400):
        a5 = rng.uniform(-1, 1, 5) * np.array([0.5, 0.5, 3.1, 0.2, 0.2]) * (1e-3 if k % 4 == 0 else 1.0)
        cgv, dgv_f, dgv_t, dgv_p = K.dcm_gv_partials(*a5[:3])
        cgr, dgr_f, dgr_t = K.dcm_gr_partials(*a5[3:])
        c = cgv @ cgr.T
        dcs = (dgv_f @ cgr.T, dgv_t @ cgr.T, dgv_p @ cgr.T, cgv @ dgr_f.T, cgv @ dgr_t.T)
        s02 = max(-1.0, min(1.0, c[0, 2]))
        ang = [math.atan2(c[1, 2], c[2, 2]), math.asin(s02), math.atan2(c[0, 1], c[0, 0])]
        ct = math.sqrt(max(1e-300, 1.0 - s02 * s02))
        jac = [[(c[2, 2] * d[1, 2] - c[1, 2] * d[2, 2]) / (c[1, 2] ** 2 + c[2, 2] ** 2) for d in dcs],
               [d[0, 2] / ct for d in dcs],
               [(c[0, 0] * d[0, 1] - c[0, 1] * d[0, 0]) / (c[0, 0] ** 2 + c[0, 1] ** 2) for d in dcs]]
        ang_k, jac_k = K.vehicle_angles_eq4(a5)
        assert ang_k.tolist() == ang and jac_k.tolist() == jac
        assert K.vehicle_angles_eq4(a5, False).tolist() == ang
