"""Compiled kernels of the EKF's predict (hand-specialised numeric kernels, ``vdps_hil.jit``):
the geometry of eq 1, 2 and 4 with their partial derivatives, the discrete process model and
the covariance propagation, on plain float64 arrays with explicit loops.

Reference: the numpy functions of :mod:`vdps_hil.estimation.kinematics` (``dcm_gv_partials``,
``dcm_gr_partials``, ``road_normal``, ``vehicle_angles_eq4``, ``step``, ``linearize``,
``transition``) and ``ekf_reference.propagate_reference``; ``tests/test_ekf_kernels.py`` holds
each kernel equal to them within 1e-12 (relative to the largest element) and the compiled
kernels bit-equal to their own Python form (``py_func``). The formulas are those of the
reference, term for term; only the small matrix products are loops (a fixed summation order
instead of BLAS), which moves the estimates in their last bits.

Predict (``propagate``), with the filter layout as arrays (``layout_arrays``)::

    x_e  = E_sel x                              (extended 19-vector, psi_v of eq 4 not needed)
    f_b  = f - b_a,  w_b = w - b_g              (bias states, when carried)
    F, G = d x_dot / d x, d x_dot / d [f, w]    (``linearize``; bias columns -G, ``ekf``)
    x   <- step(x_e, f_b, w_b, dt)              (``kinematics.step``)
    Phi  = I + F dt + (F dt)^2 / 2
    Q_c  = G diag(q_u) G^T + diag(q_rw),   Q_d = (Phi Q_c Phi^T + Q_c) dt / 2
    P   <- sym(Phi P Phi^T + Q_d)

Layout arrays: ``idx`` (n,) extended index of each filter state; ``pos`` (19,) filter position
of each extended state or -1; ``flags`` (4,) = (n_kinematic, psi_v is a state, road angles
estimated, augmented); ``yaw`` the filter positions wrapped to [-pi, pi).
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.jit import kernel
from vdps_hil.model.frames import dcm_gv_elements

__all__ = ["N_EXT", "dcm_gv_partials_k", "dcm_gr_partials_k", "expand_k", "layout_arrays", "linearize_k",
           "propagate", "road_normal_k", "step_k", "vehicle_angles_eq4_k", "warm", "wrap_yaw"]

N_EXT = 19
_PI = math.pi
_TWO_PI = 2.0 * math.pi

_dcm = kernel()(dcm_gv_elements)  # eq 1, written once in model.frames, compiled here


def layout_arrays(layout) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(idx, pos, flags, yaw) of a ``states.StateLayout`` (module docstring)."""
    idx = layout.full_index.astype(np.int64)
    pos = np.full(N_EXT, -1, dtype=np.int64)
    pos[idx] = np.arange(idx.shape[0])
    flags = np.array([layout.n_kinematic, int(layout.psi_v_state), int(layout.road_estimated),
                      int(layout.augmented)], dtype=np.int64)
    yaw = np.array([i for i, s in enumerate(idx) if s in (8, 11)], dtype=np.int64)
    return idx, pos, flags, yaw


# ------------------------------------------------------------------------------ geometry
@kernel()
def dcm_gv_partials_k(phi, theta, psi, out):
    """``kinematics.dcm_gv_partials`` into ``out`` (4, 3, 3): C_g^v, dC/dphi, dC/dtheta, dC/dpsi."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(psi), math.cos(psi)
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = _dcm(sf, cf, st, ct, sp, cp)
    c = out[0]
    c[0, 0], c[0, 1], c[0, 2] = c00, c01, c02
    c[1, 0], c[1, 1], c[1, 2] = c10, c11, c12
    c[2, 0], c[2, 1], c[2, 2] = c20, c21, c22
    d = out[1]  # K_x C: rows 0, C_2, -C_1
    d[0, 0], d[0, 1], d[0, 2] = 0.0, 0.0, 0.0
    d[1, 0], d[1, 1], d[1, 2] = c20, c21, c22
    d[2, 0], d[2, 1], d[2, 2] = -c10, -c11, -c12
    d = out[2]
    d[0, 0], d[0, 1], d[0, 2] = -st * cp, -st * sp, ct
    d[1, 0], d[1, 1], d[1, 2] = -sf * ct * cp, -sf * ct * sp, -sf * st
    d[2, 0], d[2, 1], d[2, 2] = -cf * ct * cp, -cf * ct * sp, -cf * st
    d = out[3]  # C K_z: columns -C_:1, C_:0, 0
    d[0, 0], d[0, 1], d[0, 2] = -ct * sp, ct * cp, 0.0
    d[1, 0], d[1, 1], d[1, 2] = -c11, c10, 0.0
    d[2, 0], d[2, 1], d[2, 2] = -c21, c20, 0.0


@kernel()
def dcm_gr_partials_k(phi_r, theta_r, out):
    """``kinematics.dcm_gr_partials`` into ``out`` (3, 3, 3): C_g^r, dC/dphi_r, dC/dtheta_r."""
    sf, cf = math.sin(phi_r), math.cos(phi_r)
    st, ct = math.sin(theta_r), math.cos(theta_r)
    c = out[0]
    c[0, 0], c[0, 1], c[0, 2] = ct, 0.0, st
    c[1, 0], c[1, 1], c[1, 2] = -sf * st, cf, sf * ct
    c[2, 0], c[2, 1], c[2, 2] = -cf * st, -sf, cf * ct
    d = out[1]
    d[0, 0], d[0, 1], d[0, 2] = 0.0, 0.0, 0.0
    d[1, 0], d[1, 1], d[1, 2] = c[2, 0], c[2, 1], c[2, 2]
    d[2, 0], d[2, 1], d[2, 2] = -c[1, 0], -c[1, 1], -c[1, 2]
    d = out[2]
    d[0, 0], d[0, 1], d[0, 2] = -st, 0.0, ct
    d[1, 0], d[1, 1], d[1, 2] = -sf * ct, 0.0, -sf * st
    d[2, 0], d[2, 1], d[2, 2] = -cf * ct, 0.0, -cf * st


@kernel()
def road_normal_k(phi_r, theta_r, out):
    """``kinematics.road_normal`` into ``out`` (3, 3): n, dn/dphi_r, dn/dtheta_r."""
    sf, cf = math.sin(phi_r), math.cos(phi_r)
    st, ct = math.sin(theta_r), math.cos(theta_r)
    out[0, 0], out[0, 1], out[0, 2] = -cf * st, -sf, cf * ct
    out[1, 0], out[1, 1], out[1, 2] = sf * st, -cf, -sf * ct
    out[2, 0], out[2, 1], out[2, 2] = -cf * ct, 0.0, -cf * st


@kernel()
def _mul_bt3(a, b, out):
    """out = a @ b^T for 3 x 3 arrays."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@kernel()
def vehicle_angles_eq4_k(a0, a1, a2, a3, a4, ang, jac):
    """``kinematics.vehicle_angles_eq4``: the five angles (phi_g, theta_g, psi_g, phi_r,
    theta_r) -> ``ang`` (3,) = (phi_v, theta_v, psi_v) and ``jac`` (3, 5)."""
    gv = np.empty((4, 3, 3))
    gr = np.empty((3, 3, 3))
    dcm_gv_partials_k(a0, a1, a2, gv)
    dcm_gr_partials_k(a3, a4, gr)
    c = np.empty((3, 3))
    _mul_bt3(gv[0], gr[0], c)
    c00, c01, c02, c12, c22 = c[0, 0], c[0, 1], c[0, 2], c[1, 2], c[2, 2]
    c02 = max(-1.0, min(1.0, c02))
    ang[0] = math.atan2(c12, c22)
    ang[1] = math.asin(c02)
    ang[2] = math.atan2(c01, c00)
    n_phi = c12 ** 2 + c22 ** 2
    n_psi = c00 ** 2 + c01 ** 2
    ct = math.sqrt(max(1e-300, 1.0 - c02 * c02))
    d = np.empty((3, 3))
    for k in range(5):
        if k < 3:
            _mul_bt3(gv[1 + k], gr[0], d)
        else:  # C_g^v (dC_g^r)^T
            _mul_bt3(gv[0], gr[k - 2], d)
        jac[0, k] = (c22 * d[1, 2] - c12 * d[2, 2]) / n_phi
        jac[1, k] = d[0, 2] / ct
        jac[2, k] = (c00 * d[0, 1] - c01 * d[0, 0]) / n_psi


@kernel()
def expand_k(x, idx, pos, flags, xe, E):
    """``StateLayout.expand(x, ext=True)``: filter vector -> extended 19-vector ``xe`` and
    E = d x_e / d x (19 x n); psi_v from eq 4 unless it is a filter state."""
    n = x.shape[0]
    for i in range(N_EXT):
        xe[i] = 0.0
        for j in range(n):
            E[i, j] = 0.0
    for j in range(n):
        xe[idx[j]] = x[j]
        E[idx[j], j] = 1.0
    if flags[1] == 0:
        ang = np.empty(3)
        jac = np.empty((3, 5))
        vehicle_angles_eq4_k(xe[6], xe[7], xe[8], xe[9], xe[10], ang, jac)
        nang = 5 if flags[2] != 0 else 3
        for k in range(nang):
            E[11, pos[6 + k]] = jac[2, k]
        xe[11] = ang[2]


# ------------------------------------------------------------------------------ process model
@kernel()
def _euler_rates(phi, theta, wx, wy, wz):
    """C_omega^-1(phi, theta) w (``kinematics._euler_rate_values``)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    a = sf * wy + cf * wz
    return wx - st / ct * a, -cf * wy + sf * wz, a / ct


@kernel()
def step_k(x, fb, wb, dt, g, out):
    """``kinematics.step`` of the first 12 states of ``x`` into ``out`` (12,) (angles not
    wrapped; states 9..11 copied)."""
    px, py, pz, vx, vy, vz, phi, theta, psi = x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8]
    w0, w1, w2 = wb[0], wb[1], wb[2]
    h = 0.5 * dt
    r0 = _euler_rates(phi, theta, w0, w1, w2)
    rm = _euler_rates(phi + h * r0[0], theta + h * r0[1], w0, w1, w2)
    a1 = (phi + dt * rm[0], theta + dt * rm[1], psi + dt * rm[2])
    c0 = _dcm(math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta), math.sin(psi), math.cos(psi))
    c1 = _dcm(math.sin(a1[0]), math.cos(a1[0]), math.sin(a1[1]), math.cos(a1[1]), math.sin(a1[2]),
              math.cos(a1[2]))
    f0, f1, f2 = fb[0], fb[1], fb[2]
    # (C0^T + C1^T) f: column i of C0 + C1 dotted with f
    ax = (c0[0] + c1[0]) * f0 + (c0[3] + c1[3]) * f1 + (c0[6] + c1[6]) * f2
    ay = (c0[1] + c1[1]) * f0 + (c0[4] + c1[4]) * f1 + (c0[7] + c1[7]) * f2
    az = (c0[2] + c1[2]) * f0 + (c0[5] + c1[5]) * f1 + (c0[8] + c1[8]) * f2
    acc0, acc1, acc2 = 0.5 * ax, 0.5 * ay, 0.5 * az - g
    v1x, v1y, v1z = vx + dt * acc0, vy + dt * acc1, vz + dt * acc2
    out[0], out[1], out[2] = px + h * (vx + v1x), py + h * (vy + v1y), pz + h * (vz + v1z)
    out[3], out[4], out[5] = v1x, v1y, v1z
    out[6], out[7], out[8] = a1[0], a1[1], a1[2]
    out[9], out[10], out[11] = x[9], x[10], x[11]


@kernel()
def linearize_k(x, fb, wb, F, G):
    """``kinematics.linearize``: F (12 x 12) and G (12 x 6) at the first 12 states of ``x``."""
    gv = np.empty((4, 3, 3))
    dcm_gv_partials_k(x[6], x[7], x[8], gv)
    phi, theta = x[6], x[7]
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    wy, wz = wb[1], wb[2]
    a = sf * wy + cf * wz
    b = cf * wy - sf * wz
    t = st / ct
    F[:, :] = 0.0
    G[:, :] = 0.0
    F[0, 3] = 1.0
    F[1, 4] = 1.0
    F[2, 5] = 1.0
    for k in range(3):  # F[3:6, 6 + k] = dC_k^T f
        d = gv[1 + k]
        for i in range(3):
            F[3 + i, 6 + k] = d[0, i] * fb[0] + d[1, i] * fb[1] + d[2, i] * fb[2]
    F[6, 6], F[7, 6], F[8, 6] = -t * b, a, b / ct
    F[6, 7], F[7, 7], F[8, 7] = -a / (ct * ct), 0.0, a * st / (ct * ct)
    c = gv[0]
    for i in range(3):
        for j in range(3):
            G[3 + i, j] = c[j, i]
    G[6, 3], G[6, 4], G[6, 5] = 1.0, -st * sf / ct, -st * cf / ct
    G[7, 3], G[7, 4], G[7, 5] = 0.0, -cf, sf
    G[8, 3], G[8, 4], G[8, 5] = 0.0, sf / ct, cf / ct


# ------------------------------------------------------------------------------ predict
@kernel()
def _matmul(a, b, out):
    n, m, p = a.shape[0], a.shape[1], b.shape[1]
    for i in range(n):
        for j in range(p):
            s = 0.0
            for k in range(m):
                s += a[i, k] * b[k, j]
            out[i, j] = s


@kernel()
def _matmul_bt(a, b, out):
    """out = a @ b^T."""
    n, m, p = a.shape[0], a.shape[1], b.shape[0]
    for i in range(n):
        for j in range(p):
            s = 0.0
            for k in range(m):
                s += a[i, k] * b[j, k]
            out[i, j] = s


@kernel()
def wrap_yaw(x, yaw):
    """Wrap the filter states at the positions ``yaw`` to [-pi, pi) (``MultiRateEKF._wrap``)."""
    for i in yaw:
        v = x[i]
        if v >= _PI or v < -_PI:
            x[i] = (v + _PI) % _TWO_PI - _PI


@kernel()
def propagate(x, P, idx, flags, yaw, f, w, dt, g, q_in, q_rw, phi_out):
    """One predict step of ``dt`` seconds in place on ``x`` (n,) and ``P`` (n, n) (module
    docstring); ``phi_out`` (n, n) receives Phi. ``q_rw``: the diagonal of the random-walk
    PSD in the filter layout. Returns False when x or P is no longer finite."""
    n = x.shape[0]
    nk = flags[0]
    xe = np.zeros(N_EXT)
    for j in range(n):
        xe[idx[j]] = x[j]
    fb = np.empty(3)
    wb = np.empty(3)
    for a in range(3):
        fb[a] = f[a] - xe[15 + a] if flags[3] != 0 else f[a]
        wb[a] = w[a] - xe[12 + a] if flags[3] != 0 else w[a]
    F12 = np.empty((12, 12))
    G12 = np.empty((12, 6))
    linearize_k(xe, fb, wb, F12, G12)
    F = np.zeros((n, n))
    G = np.zeros((n, 6))
    for a in range(nk):
        for b in range(nk):
            F[a, b] = F12[idx[a], idx[b]]
        for b in range(6):
            G[a, b] = G12[idx[a], b]
    for j in range(nk, n):  # bias columns: -G of their input axes (ekf_reference.filter_jacobians)
        s = idx[j]
        if 12 <= s <= 14:
            for a in range(nk):
                F[a, j] = -G[a, 3 + s - 12]
        elif 15 <= s <= 17:
            for a in range(nk):
                F[a, j] = -G[a, s - 15]
    xn = np.empty(12)
    step_k(xe, fb, wb, dt, g, xn)
    for j in range(n):
        if idx[j] < 12:
            x[j] = xn[idx[j]]
    # Phi = I + F dt + (F dt)^2 / 2  (kinematics.transition)
    fd = F * dt
    phi = phi_out
    _matmul(fd, fd, phi)
    for i in range(n):
        for j in range(n):
            phi[i, j] = phi[i, j] * 0.5 + fd[i, j]
        phi[i, i] += 1.0
    # Q_c = G diag(q_u) G^T + diag(q_rw)
    gq = np.empty((n, 6))
    for i in range(n):
        for k in range(6):
            gq[i, k] = G[i, k] * q_in[k]
    qc = np.empty((n, n))
    _matmul_bt(gq, G, qc)
    for i in range(n):
        qc[i, i] += q_rw[i]
    tmp = np.empty((n, n))
    qd = np.empty((n, n))
    _matmul(phi, qc, tmp)
    _matmul_bt(tmp, phi, qd)
    _matmul(phi, P, tmp)
    _matmul_bt(tmp, phi, P)
    h = 0.5 * dt
    for i in range(n):
        for j in range(n):
            P[i, j] += (qd[i, j] + qc[i, j]) * h
    ok = True
    for i in range(n):
        for j in range(i + 1, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s
    wrap_yaw(x, yaw)
    for i in range(n):
        if not math.isfinite(x[i]):
            ok = False
        for j in range(n):
            if not math.isfinite(P[i, j]):
                ok = False
    return ok


def warm() -> None:
    """Compile the predict kernels for the float64 layouts (``python -m vdps_hil.jit --warm``)."""
    from vdps_hil.estimation.states import StateLayout

    lay = StateLayout(gyro_bias_axes=(0, 1, 2), accel_bias_axes=(0, 1, 2), wheel_scale=True)
    idx, pos, flags, yaw = layout_arrays(lay)
    n = lay.n
    x = np.zeros(n)
    P = np.eye(n)
    propagate(x, P, idx, flags, yaw, np.array([0.0, 0.0, 9.8]), np.zeros(3), 0.01, 9.8, np.ones(6),
              np.zeros(n), np.empty((n, n)))
    expand_k(x, idx, pos, flags, np.empty(N_EXT), np.empty((N_EXT, n)))
