"""The EKF's predict and update step in numpy: the Python reference of the compiled kernels
(``ekf_kernels.propagate``, ``ekf_update_kernels.update``), and what ``MultiRateEKF`` runs with
``VDPS_JIT=0``. The cycle and its equations are in the ``ekf`` module docstring; the
kinematics and the observation models are :mod:`vdps_hil.estimation.kinematics` and
:mod:`vdps_hil.estimation.observations`.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.estimation.kinematics import linearize, step, transition
from vdps_hil.estimation.states import N_EXT, N_FULL, AugStates

__all__ = ["filter_jacobians", "propagate_reference", "update_reference"]

_TWO_PI = 2.0 * math.pi


def filter_jacobians(layout, x_ext, f_b, w_b) -> tuple[np.ndarray, np.ndarray]:
    """(F, G) of the continuous model in the filter layout at the extended state ``x_ext``
    (N_EXT) with the bias-corrected inputs ``f_b``, ``w_b``: F = d x_dot / d x (n x n),
    G = d x_dot / d [f, w] (n x 6). The bias columns are -G of their input axes (``ekf_config``
    module docstring, IMU bias states); augmented states have zero rows (random walks)."""
    idx = layout.full_index
    nk = layout.n_kinematic
    kin = idx[:nk]
    F12, G12 = linearize(x_ext[:N_FULL], f_b, w_b)
    if nk == layout.n:
        return F12[np.ix_(kin, kin)], G12[kin]
    n = layout.n
    F = np.zeros((n, n))
    F[:nk, :nk] = F12[np.ix_(kin, kin)]
    Gk = G12[kin]
    for j in range(nk, n):
        s = int(idx[j])
        if AugStates.BG_X <= s <= AugStates.BG_Z:
            F[:nk, j] = -Gk[:, 3 + s - AugStates.BG_X]
        elif AugStates.BA_X <= s <= AugStates.BA_Z:
            F[:nk, j] = -Gk[:, s - AugStates.BA_X]
    G = np.zeros((n, 6))
    G[:nk] = Gk
    return F, G


def wrap_positions(x: np.ndarray, positions) -> None:
    """Wrap ``x`` at ``positions`` to [-pi, pi) in place."""
    for i in positions:
        v = x[i]
        if v >= math.pi or v < -math.pi:
            x[i] = (v + math.pi) % _TWO_PI - math.pi


def propagate_reference(layout, x, P, f, w, dt: float, g: float, q_in, q_rw, yaw) -> tuple:
    """One predict step: (x, P, Phi) after ``dt`` seconds from the filter vector ``x`` and
    covariance ``P`` with the input ``f``, ``w``; ``q_in`` the input PSD (6,), ``q_rw`` the
    random-walk PSD (n x n), ``yaw`` the wrapped positions."""
    idx, n = layout.full_index, layout.n
    if layout.augmented:
        xe = np.zeros(N_EXT)
        xe[idx] = x
        fb = f - xe[AugStates.BA_X:AugStates.BA_Z + 1]
        wb = w - xe[AugStates.BG_X:AugStates.BG_Z + 1]
        F, G = filter_jacobians(layout, xe, fb, wb)
        xn = xe.copy()
        xn[:N_FULL] = step(xe[:N_FULL], fb, wb, dt, g)
    else:
        xf = np.zeros(N_FULL)
        xf[idx] = x
        F, G = linearize(xf, f, w)
        xn = step(xf, f, w, dt, g)
        if n != N_FULL:
            F = F[np.ix_(idx, idx)]
            G = G[idx]
    phi = transition(F, dt)
    qc = (G * q_in) @ G.T + q_rw
    qd = (phi @ qc @ phi.T + qc) * (0.5 * dt)
    P = phi @ P @ phi.T + qd
    x = xn[idx]
    wrap_positions(x, yaw)
    return x, 0.5 * (P + P.T), phi


def _linearised(model, layout, x, z, ok, aux):
    """(nu, H) at the filter vector ``x`` on the rows ``ok`` (H in the filter layout)."""
    xf, E = layout.expand(x, ext=layout.augmented)
    H = model.jacobian(xf, aux)
    H = H @ (E if H.shape[1] == E.shape[0] else E[:H.shape[1]])
    nu = model.residual(z, model.h(xf, aux))
    if not ok.all():
        nu, H = nu[ok], H[ok]
    return nu, H


def update_reference(model, layout, x, P, z, R, aux, iterations: int, gates, yaw) -> tuple:
    """One update of ``model`` with ``z`` (at least one finite), ``R``: (status, dof, NIS,
    gate, innovation, innovation sigmas, x, P, H, R used). Status "nan" before the NIS has
    dof 0 and empty innovations; "gated" and "nan" (NIS) leave x and P as they are."""
    ok = np.isfinite(z)
    nu, H = _linearised(model, layout, x, z, ok, aux)
    if not ok.all():
        R = R[np.ix_(ok, ok)]
    if not np.isfinite(R).all() or not np.isfinite(nu).all():
        return "nan", 0, math.nan, math.nan, (), (), x, P, H, R
    PHt = P @ H.T
    S = H @ PHt + R
    try:
        S_inv = np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return "nan", 0, math.nan, math.nan, (), (), x, P, H, R
    nis = float(nu @ S_inv @ nu)
    dof = int(nu.shape[0])
    gate = gates.get(dof, math.inf)
    innov = tuple(float(v) for v in nu)
    sig = tuple(float(math.sqrt(max(0.0, S[i, i]))) for i in range(dof))
    if not math.isfinite(nis) or nis > gate:
        return ("gated" if math.isfinite(nis) else "nan"), dof, nis, gate, innov, sig, x, P, H, R
    K = PHt @ S_inv
    x0 = x
    x_new = x0 + K @ nu
    for _ in range(iterations - 1):
        # iterated EKF (Gauss-Newton): relinearise at the new estimate
        dx = x_new - x0
        nu_i, H_i = _linearised(model, layout, x_new, z, ok, aux)
        PHt_i = P @ H_i.T
        try:
            K_i = PHt_i @ np.linalg.inv(H_i @ PHt_i + R)
        except np.linalg.LinAlgError:
            break
        x_next = x0 + K_i @ (nu_i + H_i @ dx)
        H, K = H_i, K_i
        step_size = float(np.abs(x_next - x_new).max())
        x_new = x_next
        if not math.isfinite(step_size) or step_size < 1e-12:
            break
    ikh = np.eye(x.shape[0]) - K @ H
    P = ikh @ P @ ikh.T + K @ R @ K.T
    wrap_positions(x_new, yaw)
    return "accepted", dof, nis, gate, innov, sig, x_new, 0.5 * (P + P.T), H, R
