"""Kinematic process model of the EKF (paper eq 7 with correction (d)) and the eq-4 geometry
with analytic partial derivatives.

Continuous model on the full state (``states.States``)::

    p_dot      = v                                            position, {g}        [m/s]
    v_dot      = (C_g^v)^T f_b + g_vec                        velocity, {g}        [m/s^2]
    a_g_dot    = C_omega^-1(phi_g, theta_g) w_b               [phi_g theta_g psi_g] [rad/s]
    phi_r_dot  = theta_r_dot = psi_v_dot = 0                  eq 6

==========  ========  ============================================================
symbol      unit      meaning
==========  ========  ============================================================
f_b         m/s^2     accelerometer specific force a - g in body axes (x fwd, y left, z up)
w_b         rad/s     gyro angular rate in body axes
g_vec       m/s^2     [0, 0, -g] in {g} (ENU). Correction (d): eq 7 feeds A^acc as if it were
                      the kinematic acceleration; a real accelerometer measures specific
                      force, so gravity is added here. ``gravity_mps2=0`` gives eq 7 literally.
C_g^v       -         eq 1, R(x, phi_g) R(y, theta_g) R(z, psi_g) (``frames.dcm_gv``)
C_omega^-1  -         inverse of C_omega consistent with eq 1 (``frames.c_omega_inv``)
==========  ========  ============================================================

Discrete step over dt with the mean IMU input of the interval (a cheap "mean-input" step: the
IMU is sampled at 1 kHz, the filter steps at the predict period, 10 ms by default)::

    a_mid = a_0 + dt/2 C_omega^-1(a_0) w      (midpoint for the Euler angles)
    a_1   = a_0 + dt   C_omega^-1(a_mid) w
    v_1   = v_0 + dt ( (C_0^T + C_1^T)/2 f + g_vec )    (trapezoid in the attitude)
    p_1   = p_0 + dt (v_0 + v_1)/2

With white sensor noise of standard deviation sigma per sample at the IMU rate f_imu, the mean of
N samples over dt = N/f_imu has variance sigma^2/N, i.e. a continuous white noise of power
spectral density q = sigma^2 / f_imu. The EKF uses Q_c = G diag(q_a, q_a, q_a, q_g, q_g, q_g) G^T
with G = d x_dot / d [f_b, w_b] (rows: velocity C^T, attitude C_omega^-1).

Eq 4 with psi_r = 0: C_r^v = C_g^v (C_g^r)^T, phi_v = atan2(C[1,2], C[2,2]),
theta_v = asin(C[0,2]), psi_v = atan2(C[0,1], C[0,0]). All partial derivatives are closed forms
(dR(x)/dphi = K_x R(x) etc.) and are tested against finite differences.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.model.frames import dcm_gv, dcm_gv_elements
from vdps_hil.units import GRAVITY_MPS2

_I3 = np.eye(3)


def _gv_partial_elements(phi: float, theta: float, psi: float) -> list[float]:
    """C_g^v, dC/dphi, dC/dtheta, dC/dpsi of eq 1: their 36 elements, row by row
    (``dcm_gv_partials``)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(psi), math.cos(psi)
    c = list(dcm_gv_elements(sf, cf, st, ct, sp, cp))
    return c + [0.0, 0.0, 0.0, *c[6:9], -c[3], -c[4], -c[5],
                -st * cp, -st * sp, ct, -sf * ct * cp, -sf * ct * sp, -sf * st, -cf * ct * cp, -cf * ct * sp, -cf * st,
                -ct * sp, ct * cp, 0.0, -c[4], c[3], 0.0, -c[7], c[6], 0.0]


def dcm_gv_partials(phi: float, theta: float, psi: float):
    """(C_g^v, dC/dphi, dC/dtheta, dC/dpsi) of eq 1.

    dC/dphi = K_x C with K_x = [[0,0,0],[0,0,1],[0,-1,0]] (rows: 0, C_2, -C_1);
    dC/dpsi = C K_z with K_z = [[0,1,0],[-1,0,0],[0,0,0]] (columns: -C_:1, C_:0, 0)."""
    return tuple(np.array(_gv_partial_elements(phi, theta, psi)).reshape(4, 3, 3))


def _gr_partial_elements(phi_r: float, theta_r: float) -> list[float]:
    """C_g^r, dC/dphi_r, dC/dtheta_r of eq 2: their 27 elements, row by row (``dcm_gr_partials``)."""
    sf, cf = math.sin(phi_r), math.cos(phi_r)
    st, ct = math.sin(theta_r), math.cos(theta_r)
    r1 = [-sf * st, cf, sf * ct]
    r2 = [-cf * st, -sf, cf * ct]
    return [ct, 0.0, st, *r1, *r2,
            0.0, 0.0, 0.0, *r2, -r1[0], -r1[1], -r1[2],
            -st, 0.0, ct, -sf * ct, 0.0, -sf * st, -cf * ct, 0.0, -cf * st]


def dcm_gr_partials(phi_r: float, theta_r: float):
    """(C_g^r, dC/dphi_r, dC/dtheta_r) of eq 2 with psi_r = 0: C_g^r = R(x, phi_r) R(y, theta_r).

    Row 3 of C_g^r is the road normal in {g}: n = [-cos(phi_r) sin(theta_r), -sin(phi_r),
    cos(phi_r) cos(theta_r)]."""
    return tuple(np.array(_gr_partial_elements(phi_r, theta_r)).reshape(3, 3, 3))


def road_normal(phi_r: float, theta_r: float):
    """(n, dn/dphi_r, dn/dtheta_r): the road plane normal in {g}, row 3 of C_g^r (eq 2)."""
    sf, cf = math.sin(phi_r), math.cos(phi_r)
    st, ct = math.sin(theta_r), math.cos(theta_r)
    return (np.array([-cf * st, -sf, cf * ct]), np.array([sf * st, -cf, -sf * ct]),
            np.array([-cf * ct, 0.0, -cf * st]))


def _euler_rate_values(phi: float, theta: float, wx: float, wy: float, wz: float) -> tuple[float, float, float]:
    """C_omega^-1(phi, theta) w as three floats (``euler_rates``)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    a = sf * wy + cf * wz
    return wx - st / ct * a, -cf * wy + sf * wz, a / ct


def euler_rates(phi: float, theta: float, w) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """([phi', theta', psi'] = C_omega^-1(phi, theta) w, d/dphi, d/dtheta).

    C_omega^-1 w = [w_x - tan(theta) a, -cos(phi) w_y + sin(phi) w_z, a / cos(theta)] with
    a = sin(phi) w_y + cos(phi) w_z (``frames.c_omega_inv``)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    wx, wy, wz = float(w[0]), float(w[1]), float(w[2])
    a = sf * wy + cf * wz
    b = cf * wy - sf * wz
    t = st / ct
    rates = np.array(_euler_rate_values(phi, theta, wx, wy, wz))
    d_phi = np.array([-t * b, a, b / ct])
    d_theta = np.array([-a / (ct * ct), 0.0, a * st / (ct * ct)])
    return rates, d_phi, d_theta


def euler_rate_matrix(phi: float, theta: float) -> np.ndarray:
    """C_omega^-1(phi, theta) (same as ``frames.c_omega_inv``, kept local for speed)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    return np.array([[1.0, -st * sf / ct, -st * cf / ct], [0.0, -cf, sf], [0.0, sf / ct, cf / ct]])


def vehicle_angles_eq4(a5, with_jacobian: bool = True):
    """Eq 4 with psi_r = 0: five angles (phi_g, theta_g, psi_g, phi_r, theta_r) ->
    (phi_v, theta_v, psi_v) [rad], and the 3 x 5 Jacobian if asked."""
    gv = _gv_partial_elements(float(a5[0]), float(a5[1]), float(a5[2]))  # C_g^v and its partials
    gr = _gr_partial_elements(float(a5[3]), float(a5[4]))  # C_g^r and its partials
    # every product of a 3 x 3 block of gv with one of gr transposed in one matmul, (12 x 3)
    # (9 x 3)^T: each element is the three-term dot product of one BLAS call per 3 x 3 product,
    # bit for bit (tests/test_kinematics.py); block (i, j) of d = gv_i gr_j^T starts at 27 i + 3 j
    # of the flat 12 x 9 result. The scalar formulas below on plain floats (the same IEEE
    # operations as on numpy scalars, without their per-element overhead: a hot path)
    d = (np.fromiter(gv, float, 36).reshape(12, 3) @ np.fromiter(gr, float, 27).reshape(9, 3).T).reshape(108).tolist()
    c00, c01, c02, c12, c22 = d[0], d[1], d[2], d[11], d[20]
    c02 = max(-1.0, min(1.0, c02))
    ang = np.array([math.atan2(c12, c22), math.asin(c02), math.atan2(c01, c00)])
    if not with_jacobian:
        return ang
    n_phi = c12 ** 2 + c22 ** 2
    n_psi = c00 ** 2 + c01 ** 2
    ct = math.sqrt(max(1e-300, 1.0 - c02 * c02))
    rows: tuple[list, list, list] = ([], [], [])
    for k in (27, 54, 81, 3, 6):  # d(C_r^v)/d(phi_g, theta_g, psi_g, phi_r, theta_r): blocks (1..3, 0), (0, 1..2)
        d00, d01, d02, d12, d22 = d[k], d[k + 1], d[k + 2], d[k + 11], d[k + 20]
        rows[0].append((c22 * d12 - c12 * d22) / n_phi)
        rows[1].append(d02 / ct)
        rows[2].append((c00 * d01 - c01 * d00) / n_psi)
    return ang, np.array(rows)


def road_relative_dcm(a5) -> np.ndarray:
    """C_r^v = C_g^v (C_g^r)^T (eq 4, psi_r = 0) from the five angles."""
    return dcm_gv(float(a5[0]), float(a5[1]), float(a5[2])) @ dcm_gr_partials(float(a5[3]), float(a5[4]))[0].T


# --------------------------------------------------------------------------------------------
# process model on the full 12-state vector


def process_f(x, f_b, w_b, gravity_mps2: float = GRAVITY_MPS2) -> np.ndarray:
    """Continuous x_dot = f(x, u) of eq 7 with correction (d) (``gravity_mps2 = 0``: eq 7 as
    printed). Full 12-state vector; psi_v and the road angles have zero rate (eq 6)."""
    x = np.asarray(x, dtype=float)
    c = dcm_gv(x[6], x[7], x[8])
    rates = euler_rates(x[6], x[7], w_b)[0]
    xd = np.zeros(12)
    xd[0:3] = x[3:6]
    xd[3:6] = c.T @ np.asarray(f_b, dtype=float)
    xd[5] -= gravity_mps2
    xd[6:9] = rates
    return xd


def process_jacobian(x, f_b, w_b) -> np.ndarray:
    """F = d f / d x (12 x 12), analytic. Independent of the gravity switch."""
    return linearize(x, f_b, w_b)[0]


def noise_input_matrix(x) -> np.ndarray:
    """G = d f / d [f_b, w_b] (12 x 6): velocity rows C^T, attitude rows C_omega^-1."""
    G = np.zeros((12, 6))
    G[3:6, 0:3] = dcm_gv(x[6], x[7], x[8]).T
    G[6:9, 3:6] = euler_rate_matrix(x[6], x[7])
    return G


def step(x, f_b, w_b, dt_s: float, gravity_mps2: float = GRAVITY_MPS2) -> np.ndarray:
    """One discrete mean-input step (midpoint attitude, trapezoid velocity; module docstring).
    Returns the new full state; angles are not wrapped here."""
    x = np.asarray(x, dtype=float)
    fb = np.asarray(f_b, dtype=float)
    # the 3 x 3 product in numpy, the element-wise formulas on plain floats (the same IEEE
    # operations as numpy's on 3-vectors, without their overhead: once per predict)
    px, py, pz, vx, vy, vz, phi, theta, psi = x[:9].tolist()
    w = (float(w_b[0]), float(w_b[1]), float(w_b[2]))
    h = 0.5 * dt_s
    r0 = _euler_rate_values(phi, theta, *w)
    rm = _euler_rate_values(phi + h * r0[0], theta + h * r0[1], *w)  # at the midpoint attitude
    a1 = (phi + dt_s * rm[0], theta + dt_s * rm[1], psi + dt_s * rm[2])
    c0 = dcm_gv(phi, theta, psi)
    c1 = dcm_gv(*a1)
    ax, ay, az = ((c0.T + c1.T) @ fb).tolist()
    acc = (0.5 * ax, 0.5 * ay, 0.5 * az - gravity_mps2)
    v1 = (vx + dt_s * acc[0], vy + dt_s * acc[1], vz + dt_s * acc[2])
    out = x.copy()
    out[:9] = (px + h * (vx + v1[0]), py + h * (vy + v1[1]), pz + h * (vz + v1[2]), *v1, *a1)
    return out


def transition(F: np.ndarray, dt_s: float) -> np.ndarray:
    """Phi = I + F dt + (F dt)^2 / 2 (second-order series of expm(F dt))."""
    fd = F * dt_s
    phi = fd @ fd
    phi *= 0.5
    phi += fd
    phi.flat[::phi.shape[0] + 1] += 1.0  # the diagonal
    return phi


def linearize(x, f_b, w_b) -> tuple[np.ndarray, np.ndarray]:
    """(F = d f / d x, G = d f / d [f_b, w_b]) at x, sharing the trigonometry (hot path)."""
    c, d_f, d_t, d_p = dcm_gv_partials(x[6], x[7], x[8])
    _, r_f, r_t = euler_rates(x[6], x[7], w_b)
    fb = np.asarray(f_b, dtype=float)
    F = np.zeros((12, 12))
    F[0, 3] = F[1, 4] = F[2, 5] = 1.0
    F[3:6, 6] = d_f.T @ fb
    F[3:6, 7] = d_t.T @ fb
    F[3:6, 8] = d_p.T @ fb
    F[6:9, 6] = r_f
    F[6:9, 7] = r_t
    G = np.zeros((12, 6))
    G[3:6, 0:3] = c.T
    G[6:9, 3:6] = euler_rate_matrix(x[6], x[7])
    return F, G
