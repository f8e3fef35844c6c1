"""Compiled kernels of the EKF's update (hand-specialised numeric kernels, ``vdps_hil.jit``): the
observation models of eq 9-11 with their Jacobians, and one update step (innovation, gate,
iterated EKF, Joseph form) on plain float64 arrays.

Reference: the model classes of :mod:`vdps_hil.estimation.observations` (``h``, ``jacobian``,
``residual``) and ``ekf_reference.update_reference``; ``tests/test_ekf_kernels.py`` holds the
kernels equal to them within 1e-12 and the compiled kernels bit-equal to their Python form.
The formulas are the reference's term for term; the small products are loops (fixed order)
and S^-1 is Gauss-Jordan elimination with partial pivoting (numpy: LAPACK), so the estimates
move in their last bits.

Update (``update``; ``ekf`` module docstring for the cycle)::

    x_e, E = expand(x);  nu = z - h(x_e) (angles wrapped);  H = H_full E       (rows of finite z)
    S = H P H^T + R,  NIS = nu^T S^-1 nu;  NIS > gate(dof) -> gated
    K = P H^T S^-1,  x+ = x + K nu;  nonlinear kinds: x_i+1 = x + K_i (z - h(x_i) - H_i (x - x_i))
    P+ = sym((I - K H) P (I - K H)^T + K R K^T)

Kinds (``KIND_CODES``, the order of ``observations.ObsKind``) and ``aux`` (float64 array, used
when ``has_aux``): gnss_vel, nhc: the body rate w (3); y2_gps: theta_v (1; NaN: eq 4 of the
state); wheel_speed: w (3), the wheel headings d (4) and weights a (4). Model parameters
(``model_params``): the GNSS lever arm (3) and the NHC point (3); the wheel positions (4, 3).
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.estimation.ekf_kernels import (N_EXT, _matmul, _matmul_bt, dcm_gr_partials_k, dcm_gv_partials_k,
                                             expand_k, road_normal_k, vehicle_angles_eq4_k, wrap_yaw)
from vdps_hil.jit import kernel

__all__ = ["ACCEPTED", "GATED", "KIND_CODES", "NAN", "MODEL_DIMS", "model_eval", "model_params", "update", "warm"]

KIND_CODES = ("gnss_pos", "gnss_att", "gnss_vel", "y2_gps", "y1_sus", "y2_sus_plane", "y2_sus_rate",
              "wheel_speed", "nhc")
"""Kernel code of each measurement kind (index); ``ObsKind`` values."""
MODEL_DIMS = (3, 3, 2, 2, 2, 1, 1, 1, 2)
ACCEPTED, GATED, NAN = 0, 1, 2
_PI = math.pi
_TWO_PI = 2.0 * math.pi


def model_params(lever_arm_m, nhc_point_m, wheel_positions_m) -> tuple[np.ndarray, np.ndarray]:
    """(params (6,) = lever arm, NHC point; wheel positions (4, 3)) for the kernels."""
    p = np.concatenate([np.asarray(lever_arm_m, dtype=float).reshape(3),
                        np.asarray(nhc_point_m, dtype=float).reshape(3)])
    return p, np.ascontiguousarray(np.asarray(wheel_positions_m, dtype=float).reshape(4, 3))


@kernel()
def _wrap(a):
    return (a + _PI) % _TWO_PI - _PI


@kernel()
def _wheel_terms(aux, has_aux, wheels):
    """(A, B, c) of ``observations.WheelSpeed._terms``."""
    A = 0.0
    B = 0.0
    c = 0.0
    for i in range(4):
        if has_aux:
            w0, w1, w2, di, ai = aux[0], aux[1], aux[2], aux[3 + i], aux[7 + i]
        else:
            w0, w1, w2, di, ai = 0.0, 0.0, 0.0, 0.0, 0.25
        if ai == 0.0:
            continue
        cd, sd = math.cos(di), math.sin(di)
        r0, r1, r2 = wheels[i, 0], wheels[i, 1], wheels[i, 2]
        wr0 = w1 * r2 - w2 * r1
        wr1 = w2 * r0 - w0 * r2
        A += ai * cd
        B += ai * sd
        c += ai * (cd * wr0 + sd * wr1)
    return A, B, c


@kernel()
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@kernel()
def _model_geometry(kind, x, aux, has_aux, params, wheels, y, H, ext):
    """y = h(x) and H = dh/dx (rows of ``MODEL_DIMS[kind]``, 19 columns; columns 12.. only for
    the wheel-speed scale) of the kinds gnss_pos .. y2_gps (``observations``)."""
    gv = np.empty((4, 3, 3))
    dcm_gv_partials_k(x[6], x[7], x[8], gv)
    if kind == 0:  # gnss_pos: p + C^T l
        for i in range(3):
            y[i] = x[i] + (gv[0, 0, i] * params[0] + gv[0, 1, i] * params[1] + gv[0, 2, i] * params[2])
            H[i, i] = 1.0
            for k in range(3):
                d = gv[1 + k]
                H[i, 6 + k] = d[0, i] * params[0] + d[1, i] * params[1] + d[2, i] * params[2]
    elif kind == 1:  # gnss_att
        for i in range(3):
            y[i] = x[6 + i]
            H[i, 6 + i] = 1.0
    elif kind == 2:  # gnss_vel: [|v_a,h|, atan2(v_a,y, v_a,x)], v_a = v + C^T (w x l)
        u = np.zeros(3)
        if has_aux:
            w0, w1, w2 = aux[0], aux[1], aux[2]
            l0, l1, l2 = params[0], params[1], params[2]
            u[0], u[1], u[2] = w1 * l2 - w2 * l1, w2 * l0 - w0 * l2, w0 * l1 - w1 * l0
        va = np.empty(3)
        for i in range(3):
            va[i] = x[3 + i] + (gv[0, 0, i] * u[0] + gv[0, 1, i] * u[1] + gv[0, 2, i] * u[2])
        y[0] = math.hypot(va[0], va[1])
        y[1] = math.atan2(va[1], va[0])
        s2 = max(1e-12, va[0] ** 2 + va[1] ** 2)
        s = math.sqrt(s2)
        dva = np.zeros((3, 12))
        dva[0, 3] = 1.0
        dva[1, 4] = 1.0
        dva[2, 5] = 1.0
        for k in range(3):
            d = gv[1 + k]
            for i in range(3):
                dva[i, 6 + k] = d[0, i] * u[0] + d[1, i] * u[1] + d[2, i] * u[2]
        for j in range(12):
            H[0, j] = (va[0] * dva[0, j] + va[1] * dva[1, j]) / s
            H[1, j] = (va[0] * dva[1, j] - va[1] * dva[0, j]) / s2
    else:  # y2_gps: [C_r^v C_g^r](1, 1:2), theta_v from aux or eq 4
        gr = np.empty((3, 3, 3))
        dcm_gr_partials_k(x[9], x[10], gr)
        ang = np.empty(3)
        jac = np.empty((3, 5))
        eq4 = not has_aux or not math.isfinite(aux[0])
        if eq4:
            vehicle_angles_eq4_k(x[6], x[7], x[8], x[9], x[10], ang, jac)
            tv = ang[1]
        else:
            tv = aux[0]
        ct, st = math.cos(tv), math.sin(tv)
        cp, sp = math.cos(x[11]), math.sin(x[11])
        r0, r1, r2 = ct * cp, ct * sp, st
        for j in range(2):
            y[j] = r0 * gr[0, 0, j] + r1 * gr[0, 1, j] + r2 * gr[0, 2, j]
            H[j, 9] = r0 * gr[1, 0, j] + r1 * gr[1, 1, j] + r2 * gr[1, 2, j]
            H[j, 10] = r0 * gr[2, 0, j] + r1 * gr[2, 1, j] + r2 * gr[2, 2, j]
            H[j, 11] = -ct * sp * gr[0, 0, j] + ct * cp * gr[0, 1, j] + 0.0 * gr[0, 2, j]
            if eq4:
                dh = -st * cp * gr[0, 0, j] + -st * sp * gr[0, 1, j] + ct * gr[0, 2, j]
                for k in range(5):
                    H[j, 6 + k] += dh * jac[1, k]


@kernel()
def _model_chassis(kind, x, aux, has_aux, params, wheels, y, H, ext):
    """y = h(x) and H of the kinds y1_sus .. nhc (``observations``)."""
    if kind == 4:  # y1_sus: [C_g^v n]_0:2, n = row 3 of C_g^r
        gv = np.empty((4, 3, 3))
        gr = np.empty((3, 3, 3))
        dcm_gv_partials_k(x[6], x[7], x[8], gv)
        dcm_gr_partials_k(x[9], x[10], gr)
        n = gr[0, 2]
        for i in range(2):
            y[i] = gv[0, i, 0] * n[0] + gv[0, i, 1] * n[1] + gv[0, i, 2] * n[2]
            for k in range(3):
                H[i, 6 + k] = _dot3(gv[1 + k, i], n)
            for k in range(2):
                H[i, 9 + k] = _dot3(gv[0, i], gr[1 + k, 2])
    elif kind == 5 or kind == 6:  # y2_sus_plane: n . p ; y2_sus_rate: n . v
        rn = np.empty((3, 3))
        road_normal_k(x[9], x[10], rn)
        o = 0 if kind == 5 else 3
        y[0] = rn[0, 0] * x[o] + rn[0, 1] * x[o + 1] + rn[0, 2] * x[o + 2]
        for i in range(3):
            H[0, o + i] = rn[0, i]
        H[0, 9] = rn[1, 0] * x[o] + rn[1, 1] * x[o + 1] + rn[1, 2] * x[o + 2]
        H[0, 10] = rn[2, 0] * x[o] + rn[2, 1] * x[o + 1] + rn[2, 2] * x[o + 2]
    else:
        gv = np.empty((4, 3, 3))
        dcm_gv_partials_k(x[6], x[7], x[8], gv)
        v = x[3:6]
        if kind == 7:  # wheel_speed: (1 + k_w) sum a_i [cos d_i, sin d_i, 0] (C v + w x r_i)
            A, B, c = _wheel_terms(aux, has_aux, wheels)
            k1 = 1.0 + x[18] if ext else 1.0
            cv0, cv1 = _dot3(gv[0, 0], v), _dot3(gv[0, 1], v)
            y[0] = k1 * (A * cv0 + B * cv1 + c)
            for i in range(3):
                H[0, 3 + i] = k1 * (A * gv[0, 0, i] + B * gv[0, 1, i])
            for k in range(3):
                H[0, 6 + k] = k1 * (A * _dot3(gv[1 + k, 0], v) + B * _dot3(gv[1 + k, 1], v))
            if ext:
                H[0, 18] = A * cv0 + B * cv1 + c
        else:  # nhc: body y, z velocity at the point r_p
            wr1, wr2 = 0.0, 0.0
            if has_aux:
                w0, w1, w2 = aux[0], aux[1], aux[2]
                r0, r1, r2 = params[3], params[4], params[5]
                wr1, wr2 = w2 * r0 - w0 * r2, w0 * r1 - w1 * r0
            y[0] = _dot3(gv[0, 1], v) + wr1
            y[1] = _dot3(gv[0, 2], v) + wr2
            for i in range(2):
                for j in range(3):
                    H[i, 3 + j] = gv[0, 1 + i, j]
                for k in range(3):
                    H[i, 6 + k] = _dot3(gv[1 + k, 1 + i], v)


@kernel()
def model_eval(kind, x, aux, has_aux, params, wheels, y, H, ext):
    """y = h(x) (``MODEL_DIMS[kind]``,) and H = dh/dx (dim x 19, zeroed here) of one kind at the
    extended state ``x`` (19,); ``ext``: the wheel-speed scale state x[18] is in use."""
    H[:, :] = 0.0
    if kind <= 3:
        _model_geometry(kind, x, aux, has_aux, params, wheels, y, H, ext)
    else:
        _model_chassis(kind, x, aux, has_aux, params, wheels, y, H, ext)


@kernel()
def _inverse(S, out):
    """out = S^-1 by Gauss-Jordan elimination with partial pivoting; False if S is singular."""
    k = S.shape[0]
    a = S.copy()
    for i in range(k):
        for j in range(k):
            out[i, j] = 1.0 if i == j else 0.0
    for c in range(k):
        p = c
        for r in range(c + 1, k):
            if abs(a[r, c]) > abs(a[p, c]):
                p = r
        if a[p, c] == 0.0:
            return False
        if p != c:
            for j in range(k):
                a[c, j], a[p, j] = a[p, j], a[c, j]
                out[c, j], out[p, j] = out[p, j], out[c, j]
        piv = a[c, c]
        for j in range(k):
            a[c, j] /= piv
            out[c, j] /= piv
        for r in range(k):
            if r != c:
                f = a[r, c]
                if f != 0.0:
                    for j in range(k):
                        a[r, j] -= f * a[c, j]
                        out[r, j] -= f * out[c, j]
    return True


@kernel()
def _linearise(kind, x, z, ok, aux, has_aux, idx, pos, flags, params, wheels, nu, H):
    """nu (k,) = z - h(x) on the rows ``ok`` (angles wrapped) and H (k x n) = H_full E at the
    filter vector ``x``."""
    n = x.shape[0]
    m = z.shape[0]
    xe = np.empty(N_EXT)
    E = np.empty((N_EXT, n))
    expand_k(x, idx, pos, flags, xe, E)
    ext = flags[3] != 0
    y = np.empty(m)
    Hf = np.empty((m, N_EXT))
    model_eval(kind, xe, aux, has_aux, params, wheels, y, Hf, ext)
    ncol = N_EXT if (kind == 7 and ext) else 12
    r = 0
    for i in range(m):
        if not ok[i]:
            continue
        v = z[i] - y[i]
        if kind == 1 or (kind == 2 and i == 1):
            v = _wrap(v)
        nu[r] = v
        for j in range(n):
            s = 0.0
            for c in range(ncol):
                s += Hf[i, c] * E[c, j]
            H[r, j] = s
        r += 1


@kernel()
def _gain(P, H, R, K, S, S_inv):
    """S = H P H^T + R, S^-1 and K = P H^T S^-1; False if S is singular."""
    n, k = P.shape[0], H.shape[0]
    pht = np.empty((n, k))
    _matmul_bt(P, H, pht)
    _matmul(H, pht, S)
    for i in range(k):
        for j in range(k):
            S[i, j] += R[i, j]
    if not _inverse(S, S_inv):
        return False
    _matmul(pht, S_inv, K)
    return True


@kernel()
def _joseph(P, K, H, R):
    """P <- sym((I - K H) P (I - K H)^T + K R K^T) in place."""
    n, k = P.shape[0], H.shape[0]
    ikh = np.empty((n, n))
    _matmul(K, H, ikh)
    for i in range(n):
        for j in range(n):
            ikh[i, j] = (1.0 if i == j else 0.0) - ikh[i, j]
    tmp = np.empty((n, n))
    _matmul(ikh, P, tmp)
    kr = np.empty((n, k))
    _matmul(K, R, kr)
    _matmul_bt(tmp, ikh, P)
    krk = np.empty((n, n))
    _matmul_bt(kr, K, krk)
    for i in range(n):
        for j in range(n):
            P[i, j] += krk[i, j]
    for i in range(n):
        for j in range(i + 1, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s


@kernel()
def update(kind, x, P, z, R_full, aux, has_aux, idx, pos, flags, yaw, params, wheels, iterations, gates,
           innov, sig, H_out, R_out):
    """One EKF update of ``kind`` in place on ``x`` and ``P`` (module docstring). Returns
    (status ACCEPTED / GATED / NAN, dof, NIS, gate, x and P finite); ``innov``, ``sig`` receive
    the innovation and sqrt(diag S) of the used rows (when the NIS was computed), ``H_out``,
    ``R_out`` the final H and R (accepted). At least one z must be finite (the caller's check).
    A hand-specialised kernel, tested equal to ``ekf_reference.update_reference``."""
    n = x.shape[0]
    m = z.shape[0]
    ok = np.empty(m, dtype=np.bool_)
    k = 0
    for i in range(m):
        ok[i] = math.isfinite(z[i])
        if ok[i]:
            k += 1
    R = np.empty((k, k))
    a = 0
    for i in range(m):
        if ok[i]:
            b = 0
            for j in range(m):
                if ok[j]:
                    R[a, b] = R_full[i, j]
                    b += 1
            a += 1
    nu = np.empty(k)
    H = np.empty((k, n))
    _linearise(kind, x, z, ok, aux, has_aux, idx, pos, flags, params, wheels, nu, H)
    for i in range(k):
        if not math.isfinite(nu[i]):
            return NAN, 0, math.nan, math.nan, True
        for j in range(k):
            if not math.isfinite(R[i, j]):
                return NAN, 0, math.nan, math.nan, True
    K = np.empty((n, k))
    S = np.empty((k, k))
    S_inv = np.empty((k, k))
    if not _gain(P, H, R, K, S, S_inv):
        return NAN, 0, math.nan, math.nan, True
    nis = 0.0
    for j in range(k):
        s = 0.0
        for i in range(k):
            s += nu[i] * S_inv[i, j]
        nis += s * nu[j]
    gate = gates[k] if k < gates.shape[0] else math.inf
    for i in range(k):
        innov[i] = nu[i]
        sig[i] = math.sqrt(max(0.0, S[i, i]))
    if not math.isfinite(nis) or nis > gate:
        return (GATED if math.isfinite(nis) else NAN), k, nis, gate, True
    x0 = x.copy()
    x_new = np.empty(n)
    for i in range(n):
        s = 0.0
        for j in range(k):
            s += K[i, j] * nu[j]
        x_new[i] = x0[i] + s
    Hi = np.empty((k, n))
    nui = np.empty(k)
    Ki = np.empty((n, k))
    Si = np.empty((k, k))
    Si_inv = np.empty((k, k))
    for _ in range(iterations - 1):  # iterated EKF (Gauss-Newton): relinearise at the new estimate
        _linearise(kind, x_new, z, ok, aux, has_aux, idx, pos, flags, params, wheels, nui, Hi)
        if not _gain(P, Hi, R, Ki, Si, Si_inv):
            break
        step = 0.0
        x_next = np.empty(n)
        for r in range(k):
            s = 0.0
            for c in range(n):
                s += Hi[r, c] * (x_new[c] - x0[c])
            nui[r] += s
        for i in range(n):
            s = 0.0
            for j in range(k):
                s += Ki[i, j] * nui[j]
            x_next[i] = x0[i] + s
            d = abs(x_next[i] - x_new[i])
            if d > step or d != d:
                step = d
        H[:, :] = Hi
        K[:, :] = Ki
        x_new = x_next
        if not math.isfinite(step) or step < 1e-12:
            break
    x[:] = x_new
    _joseph(P, K, H, R)
    wrap_yaw(x, yaw)
    H_out[:k, :] = H
    R_out[:k, :k] = R
    finite = True
    for i in range(n):
        if not math.isfinite(x[i]):
            finite = False
        for j in range(n):
            if not math.isfinite(P[i, j]):
                finite = False
    return ACCEPTED, k, nis, gate, finite


def warm() -> None:
    """Compile the update kernels (``python -m vdps_hil.jit --warm``)."""
    from vdps_hil.estimation.ekf_kernels import layout_arrays, warm as warm_predict
    from vdps_hil.estimation.states import StateLayout

    warm_predict()
    lay = StateLayout(gyro_bias_axes=(0, 1, 2), accel_bias_axes=(0, 1, 2), wheel_scale=True)
    idx, pos, flags, yaw = layout_arrays(lay)
    n = lay.n
    params, wheels = model_params((0.0, 0.0, 1.0), (-1.0, 0.0, -0.5), np.ones((4, 3)))
    gates = np.full(7, np.inf)
    for kind, m in enumerate(MODEL_DIMS):
        x = np.full(n, 0.01)
        x[3] = 10.0
        update(kind, x, np.eye(n), np.full(m, 0.1), np.eye(m), np.zeros(11), True, idx, pos, flags, yaw, params,
               wheels, 2, gates, np.empty(3), np.empty(3), np.empty((3, n)), np.empty((3, 3)))
