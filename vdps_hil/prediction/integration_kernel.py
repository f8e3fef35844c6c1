"""The predictor's integration loop on the reduced core, compiled: :func:`reduced_loop` runs a
whole prediction (every step, the ROS2 W-method or Heun, the stop rules) in one call of
compiled code over :func:`vdps_hil.model.reduced.reduced_rhs`.

The steps are those of :mod:`vdps_hil.prediction.integration` (its docstring has the
equations and the measured accuracy); the same operations in the same order as the Python
loop it replaced, so the trajectory is bit for bit the one of ``reduced_loop.py_func`` (the
same source run by CPython; ``tests/test_integration_kernel.py``) and equal to the generic
loop on ``Model.f`` to rounding.

Inputs: one row (held inputs) or one row per step (``U_csd`` (n, 4, 2) cos/sin of the road-wheel
angles, ``U_tq`` (n, 4) drive and ``U_br`` (n, 4) brake torques, sampled at the start of each
step). Outputs, per kept step k: ``X[k]`` state, ``FZ[k]`` normal loads, ``T[k]`` time after
t0, ``PHI[k]`` road-relative roll phi_v = atan2(n_y, n_z) and ``RATE[k]`` its rate
p - tan(theta_v) (sin phi_v q + cos phi_v r), theta_v = asin(n_x): what the rollover monitor is
fed. A step is kept every ``out_every`` steps and at the last one; the loop stops at the
horizon, at the first kept step whose |phi_v| exceeds the static tip angle with phi_v phi_v_dot
> 0 (the point of no return of :mod:`vdps_hil.model.rollover`; with ``stop_ponr``), when
|phi_v| > ``roll_limit`` (that step kept, not fed to the monitor) or at a non-finite state.
Returns ``(n_kept, n_fed, n_steps_taken, n_f_evals, stop)`` with ``stop`` an index into
:data:`STOP_REASONS`.

Layer: prediction (imports the model's kernels and :mod:`vdps_hil.jit`).
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.jit import kernel
from vdps_hil.model.reduced import C_R, C_X, C_Y, K_VFLOOR, reduced_rhs, wheel_spin_jacobian

STOP_REASONS = ("horizon", "point_of_no_return", "roll_limit", "non_finite")


@kernel()
def _coupling_geometry(csd, gh, C, kc):
    """kc = gamma h / r_i times (cos d_i, sin d_i, x_i sin d_i - y_i cos d_i), i = 1..4 (12
    values): v_l,i -> v_x, v_y, omega_z."""
    for k in range(4):
        kc[k] = gh / C[k, C_R] * csd[k, 0]
    for k in range(4):
        kc[4 + k] = gh / C[k, C_R] * csd[k, 1]
    for k in range(4):
        kc[8 + k] = gh / C[k, C_R] * (C[k, C_X] * csd[k, 1] - C[k, C_Y] * csd[k, 0])


@kernel()
def _w_factors(jd, x, kap, gh, vfloor, coupling, kc, w, cpl):
    """w = 1 / (1 - gamma h J_kk) (J clipped to <= 0) and, with ``coupling``, cpl = q * kc with
    q = -J_kk (1 + kappa_k) above v_floor, else -J_kk (d omega_dot / d v_l = J_kk (d kappa /
    d v_l) / (d kappa / d omega))."""
    for k in range(4):
        j = jd[k]
        if j > 0.0 or j != j:
            j = 0.0
        jd[k] = j
        w[k] = 1.0 / (1.0 - gh * j)
    if coupling:
        above = abs(x[6]) > vfloor
        for k in range(4):
            q = -jd[k] * (1.0 + kap[k]) if above else -jd[k]
            cpl[k] = q * kc[k]
            cpl[4 + k] = q * kc[4 + k]
            cpl[8 + k] = q * kc[8 + k]


@kernel()
def _roll_v(nb, x):
    """(phi_v, d phi_v / dt) from the road normal in body axes and the body rates."""
    phi_v = math.atan2(nb[1], nb[2])
    nx = nb[0]
    nx = nx if nx < 1.0 else 1.0
    nx = nx if nx > -1.0 else -1.0
    tt = math.tan(math.asin(nx))
    return phi_v, x[9] - tt * math.sin(phi_v) * x[10] - tt * math.cos(phi_v) * x[11]


@kernel()
def _keep(X, FZ, T, PHI, RATE, k, x, fz, t, phi_v, rate):
    """Row ``k`` of the outputs: state, loads, time, phi_v and its rate."""
    X[k] = x
    FZ[k] = fz
    T[k] = t
    PHI[k] = phi_v
    RATE[k] = rate


@kernel()
def reduced_loop(x0, U_csd, U_tq, U_br, ng, K, C, h, n_steps, out_every, jac_every, ros2, coupling,
                 stop_ponr, tip_angle, roll_limit, gamma, X, FZ, T, PHI, RATE):
    """A hand-specialised kernel: one prediction on the reduced core (module docstring)."""
    h_k1, h_k2, gh = 1.5 * h, 0.5 * h, gamma * h
    vfloor = K[K_VFLOOR]
    held = U_csd.shape[0] == 1
    x = x0.copy()
    k1, f1, xs, fz, nb, kap, den, tfz = (np.empty(16), np.empty(16), np.empty(16), np.empty(4), np.empty(3),
                                         np.empty(4), np.empty(4), np.empty(4))
    jd, w, kc, cpl = np.empty(4), np.ones(4), np.zeros(12), np.zeros(12)
    n = n_eval = n_out = 0
    n_fed = 0
    stop = 0
    iu_c = -1
    while True:
        iu = 0 if held else n
        reduced_rhs(x, U_csd[iu], U_tq[iu], U_br[iu], ng, K, C, k1, fz, nb, kap, den, tfz)
        n_eval += 1
        record = n % out_every == 0 or n == n_steps
        phi_v, rate = _roll_v(nb, x)
        if record:
            _keep(X, FZ, T, PHI, RATE, n_out, x, fz, n * h, phi_v, rate)
            n_out += 1
            n_fed = n_out
            if stop_ponr and abs(phi_v) > tip_angle and phi_v * rate > 0.0:
                stop = 1
                break
        if abs(phi_v) > roll_limit:
            if not record:
                _keep(X, FZ, T, PHI, RATE, n_out, x, fz, n * h, phi_v, rate)
                n_out += 1
            stop = 2
            break
        if n >= n_steps:
            break
        if not ros2:  # Heun: x_n+1 = x_n + h/2 (f(x_n) + f(x_n + h f(x_n)))
            for j in range(16):
                xs[j] = x[j] + h * k1[j]
            reduced_rhs(xs, U_csd[iu], U_tq[iu], U_br[iu], ng, K, C, f1, fz, nb, kap, den, tfz)
            n_eval += 1
            for j in range(16):
                x[j] = x[j] + h_k2 * (k1[j] + f1[j])
        else:
            if n % jac_every == 0:
                if coupling and iu != iu_c:
                    iu_c = iu
                    _coupling_geometry(U_csd[iu], gh, C, kc)
                wheel_spin_jacobian(x, U_br[iu], tfz, den, K, C, jd)
                _w_factors(jd, x, kap, gh, vfloor, coupling, kc, w, cpl)
            # stage 1: k1 = W^-1 f(x_n) (W = I on the body rows)
            a6, a7, a11 = k1[6], k1[7], k1[11]
            for j in range(4):
                k1[12 + j] = (k1[12 + j] + cpl[j] * a6 + cpl[4 + j] * a7 + cpl[8 + j] * a11) * w[j]
            # stage 2: k2 = W^-1 (f(x_n + h k1) - 2 k1); x_n+1 = x_n + 3/2 h k1 + 1/2 h k2
            for j in range(16):
                xs[j] = x[j] + h * k1[j]
            reduced_rhs(xs, U_csd[iu], U_tq[iu], U_br[iu], ng, K, C, f1, fz, nb, kap, den, tfz)
            n_eval += 1
            a6, a7, a11 = f1[6] - 2.0 * k1[6], f1[7] - 2.0 * k1[7], f1[11] - 2.0 * k1[11]
            for j in range(12):
                x[j] = x[j] + h_k1 * k1[j] + h_k2 * (f1[j] - 2.0 * k1[j])
            for j in range(4):
                x[12 + j] = x[12 + j] + h_k1 * k1[12 + j] + h_k2 * (
                    f1[12 + j] - 2.0 * k1[12 + j] + cpl[j] * a6 + cpl[4 + j] * a7 + cpl[8 + j] * a11) * w[j]
        n += 1
        if not math.isfinite(x[6] + x[9] + x[12] + x[3] + x[4]):
            stop = 3
            break
    return n_out, n_fed, n, n_eval, stop


def warm() -> None:
    """Compile (or load from the cache) :func:`reduced_loop` with representative arguments."""
    from vdps_hil.model import reduced

    reduced.warm()
    x, K, C = np.zeros(16), np.ones(reduced.N_K), np.ones((4, reduced.N_C))
    csd = np.full((1, 4, 2), 0.5)
    out = [np.empty((4, 16)), np.empty((4, 4)), np.empty(4), np.empty(4), np.empty(4)]
    for ros2 in (True, False):
        reduced_loop(x, csd, np.zeros((1, 4)), np.zeros((1, 4)), np.array([0.0, 0.0, 1.0]), K, C, 0.01, 2, 1, 2,
                     ros2, True, True, 1.0, 1.5, 1.7, *out)


__all__ = ["STOP_REASONS", "reduced_loop"]
