"""Compiled kernels of the weighted RLS of eq 19 in covariance form (hand-specialised numeric
kernels, ``vdps_hil.jit``): the row selection, one update and the accumulated diagnostics, on
plain float64 arrays with explicit loops.

Reference: ``rls.WeightedRLS.update`` and ``_step_covariance`` (numpy; what runs with
``VDPS_JIT=0``). ``tests/test_rls_kernels.py`` holds the kernels equal to them within 1e-12
(relative to the largest element) and the compiled kernels bit-equal to their own Python form.
The formulas are the reference's term for term (``rls`` module docstring)::

    rows: selected and finite;   Q A, A_Q = Q A W, y = Q b      (k rows)
    v = y - A_Q x_Q,   S = lambda I + A_Q P A_Q^T,   K = P A_Q^T S^-1
    x_Q+ = x_Q + K v,  P+ = sym((I - K A_Q) (P / lambda) (I - K A_Q)^T + K K^T)
    J increment = lambda v^T S^-1 v

and, after the bounds (``accumulate``): info += (Q A)^T Q A, info_scaled += A_Q^T A_Q (both
discounted by lambda), the score g = A_Q^T (y - A_Q x_Q+) and its lag-0 / lag-1 sums
(``update_inside``: both in one call when the bounds leave x_Q+ as it is); ``consider_rows``: the
used rows of Q db/dtheta for the consider covariance.
The gain and the Joseph form are the EKF update's kernels (``ekf_update_kernels``: loops in a fixed
summation order instead of BLAS, S^-1 by Gauss-Jordan elimination with partial pivoting instead of
LAPACK), so the estimates move in their last bits.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.estimation.ekf_update_kernels import _gain, _joseph
from vdps_hil.jit import kernel

__all__ = ["accumulate", "consider_rows", "covariance_step", "update_inside", "warm"]


@kernel()
def _residual(aq, y, k, xq):
    """y - A_Q x_Q on the first k rows."""
    out = np.empty(k)
    for r in range(k):
        s = 0.0
        for j in range(xq.shape[0]):
            s += aq[r, j] * xq[j]
        out[r] = y[r] - s
    return out


@kernel()
def _finite_row(a, b, i):
    """A's row i and b_i finite (x - x is 0 for finite x only)."""
    ok = b[i] - b[i] == 0.0
    for j in range(a.shape[1]):
        ok = ok and a[i, j] - a[i, j] == 0.0
    return ok


@kernel()
def consider_rows(a, b, sel, qv, d, out):
    """Q db/dtheta on the rows ``covariance_step`` uses (``sel`` and finite), non-finite entries 0,
    into the first k rows of ``out``; returns k. Element for element the reference's
    ``qv[sel, None] * np.where(np.isfinite(d[sel]), d[sel], 0.0)`` (bit-equal)."""
    k = 0
    for i in range(a.shape[0]):
        if sel[i] and _finite_row(a, b, i):
            for j in range(d.shape[1]):
                v = d[i, j]
                out[k, j] = qv[i] * (v if v - v == 0.0 else 0.0)
            k += 1
    return k


@kernel()
def covariance_step(a, b, sel, qv, w, xq, P, lam, qa, aq, y, xq_new, P_new):
    """One eq-19 step on the rows ``sel`` of (a, b) that are finite: fills qa, aq, y (first k
    rows), xq_new and P_new; returns (k, rows left out as non-finite, J increment). k = 0: nothing
    else is written. A hand-specialised kernel, equal to ``WeightedRLS._step_covariance`` (module
    docstring)."""
    m, n = a.shape
    k = 0
    nan_rows = 0
    for i in range(m):
        if not sel[i]:
            continue
        if not _finite_row(a, b, i):
            nan_rows += 1
            continue
        for j in range(n):
            qa[k, j] = qv[i] * a[i, j]
            aq[k, j] = qa[k, j] * w[j]
        y[k] = qv[i] * b[i]
        k += 1
    if k == 0:
        return 0, nan_rows, 0.0
    v = _residual(aq, y, k, xq)  # a priori innovation
    A = aq[:k]
    eye = np.zeros((k, k))
    for r in range(k):
        eye[r, r] = 1.0
    K, S, s_inv = np.empty((n, k)), np.empty((k, k)), np.empty((k, k))
    _gain(P, A, lam * eye, K, S, s_inv)  # S = lambda I + A_Q P A_Q^T >= lambda I: never singular
    for i in range(n):
        s = 0.0
        for r in range(k):
            s += K[i, r] * v[r]
        xq_new[i] = xq[i] + s
    for i in range(n):
        for j in range(n):
            P_new[i, j] = P[i, j] / lam
    _joseph(P_new, K, A, eye)  # (I - K A_Q) (P / lambda) (I - K A_Q)^T + K K^T, symmetrised
    q = 0.0
    for r in range(k):
        s = 0.0
        for c in range(k):
            s += s_inv[r, c] * v[c]
        q += v[r] * s
    return k, nan_rows, lam * q


@kernel()
def accumulate(qa, aq, y, k, xq_new, lam, info, info_scaled, gg, g1, g_prev, has_prev):
    """The diagnostics of an accepted update (in place): info, info_scaled, gg, g1 (when
    ``has_prev``) and g_prev <- the score g. A hand-specialised kernel, equal to the reference's lines in
    ``WeightedRLS.update`` (module docstring)."""
    n = xq_new.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            t = 0.0
            for r in range(k):
                s += qa[r, i] * qa[r, j]
                t += aq[r, i] * aq[r, j]
            info[i, j] = lam * info[i, j] + s
            info_scaled[i, j] = lam * info_scaled[i, j] + t
    e = _residual(aq, y, k, xq_new)  # a posteriori residual
    for j in range(n):
        s = 0.0
        for r in range(k):
            s += aq[r, j] * e[r]
        gg[j] = lam * gg[j] + s * s
        if has_prev:
            g1[j] = lam * g1[j] + s * g_prev[j]
        g_prev[j] = s


@kernel()
def update_inside(a, b, sel, qv, w, xq, P, lam, lower, upper, qa, aq, y, xq_new, P_new, info, info_scaled, gg, g1,
                  g_prev, has_prev):
    """``covariance_step``, then ``accumulate`` when the update needs no bounds handling: x_Q+ and
    the J increment finite, x = x_Q+ W within [lower, upper] (the common case; one call instead of
    two). Returns (k, rows left out as non-finite, J increment, accumulated)."""
    k, nan_rows, drss = covariance_step(a, b, sel, qv, w, xq, P, lam, qa, aq, y, xq_new, P_new)
    if k == 0 or not math.isfinite(drss):
        return k, nan_rows, drss, False
    for j in range(xq_new.shape[0]):
        x = xq_new[j] * w[j]
        if not math.isfinite(xq_new[j]) or x < lower[j] or x > upper[j]:
            return k, nan_rows, drss, False
    accumulate(qa, aq, y, k, xq_new, lam, info, info_scaled, gg, g1, g_prev, has_prev)
    return k, nan_rows, drss, True


def warm() -> None:
    """Compile (or load from the cache) both kernels with the argument types the RLS uses."""
    m, n = 3, 2
    a, b = np.ones((m, n)), np.ones(m)
    sel = np.ones(m, dtype=np.bool_)
    qa, aq, y = np.empty((m, n)), np.empty((m, n)), np.empty(m)
    xq_new, P_new = np.empty(n), np.empty((n, n))
    k, _, _ = covariance_step(a, b, sel, np.ones(m), np.ones(n), np.zeros(n), np.eye(n), 1.0, qa, aq, y, xq_new,
                              P_new)
    accumulate(qa, aq, y, k, xq_new, 1.0, np.zeros((n, n)), np.zeros((n, n)), np.zeros(n), np.zeros(n),
               np.zeros(n), True)
    consider_rows(a, b, sel, np.ones(m), np.ones((m, 4)), np.empty((m, 4)))
    update_inside(a, b, sel, np.ones(m), np.ones(n), np.zeros(n), np.eye(n), 1.0, np.full(n, -np.inf),
                  np.full(n, np.inf), qa, aq, y, xq_new, P_new, np.zeros((n, n)), np.zeros((n, n)), np.zeros(n),
                  np.zeros(n), np.zeros(n), True)
