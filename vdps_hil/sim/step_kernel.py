"""The truth simulator's steps compiled: explicit Runge-Kutta steps of the compiled physics core
(:func:`vdps_hil.model.core_kernel.core_rhs`) with the inputs held over each step, and the
per-step truth the sensor models read (the rows of :class:`vdps_hil.sim.sampling.StepRecorder`).

The same operations in the same order as ``stepping.rk_step`` over ``Model.f`` and
``Simulator.kinematics``, so a compiled run is bit for bit the Python one
(``tests/test_step_kernel.py``)::

    rk2 (Heun):  k2 = f(x + h k1);  x+ = x + h/2 (k1 + k2)
    rk4:         k2 = f(x + h/2 k1), k3 = f(x + h/2 k2), k4 = f(x + h k3);
                 x+ = x + h/6 (k1 + 2 (k2 + k3) + k4)
    recorder row after a step, at the new state x under the next step's inputs u:
        k1 = f(x, u),  a = k1[6:9] + omega x v_b,  g_b = -g (sin theta, sin phi cos theta, cos phi cos theta)
        [n, a - g_b, omega, k1[9:12], x[0:9], x[12:16], H (x[16:20] or the reduced model's),
         steering, drive torques, brake torques]

Arguments: ``x`` (state, updated in place), ``k1`` (f(x) under ``U[0]``, updated to f of the
final state under the next inputs), ``U`` (m + 1, 9) inputs of the steps (row j for step j,
row m for the state reached), ``env`` (6: n_g, wind), ``K, C, E`` the model's packed arrays,
``rec`` the recorder rows (``rec.shape[0] == 0``: none), ``D`` diagnostics of the final state
(``core_kernel.N_DIAG`` values or empty).
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.jit import kernel
from vdps_hil.model.core_kernel import K_DOF, K_G, N_DIAG, core_rhs

N_REC = 36
"""Columns of a recorder row (``sampling._COLS``)."""


@kernel()
def rk_step(x, k1, u, h, rk4, env, K, C, E, S):
    """One step of ``h`` from ``x`` (in place) with ``k1 = f(x)`` given; True when the state is
    finite after it (u, v, p and omega_1)."""
    n = x.size
    nod = np.empty(0)
    xs, k2 = np.empty(n), np.empty(n)
    if rk4:
        k3, k4 = np.empty(n), np.empty(n)
        hh = 0.5 * h
        for i in range(n):
            xs[i] = x[i] + hh * k1[i]
        core_rhs(xs, u, env, K, C, E, S, k2, nod)
        for i in range(n):
            xs[i] = x[i] + hh * k2[i]
        core_rhs(xs, u, env, K, C, E, S, k3, nod)
        for i in range(n):
            xs[i] = x[i] + h * k3[i]
        core_rhs(xs, u, env, K, C, E, S, k4, nod)
        h6 = h / 6.0
        for i in range(n):
            x[i] = x[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
    else:
        for i in range(n):
            xs[i] = x[i] + h * k1[i]
        core_rhs(xs, u, env, K, C, E, S, k2, nod)
        h2 = 0.5 * h
        for i in range(n):
            x[i] = x[i] + h2 * (k1[i] + k2[i])
    return math.isfinite(x[6] + x[9] + x[12])


@kernel()
def record_row(x, k1, u, n, env, K, C, E, S, row, D):
    """k1 = f(x, u) (diagnostics into ``D`` unless empty) and, unless ``row`` is empty, the
    recorder row of step ``n`` at ``x`` (module docstring)."""
    reduced = K[K_DOF] == 0.0
    want = row.size > 0
    dd = D if (D.size > 0 or not (reduced and want)) else np.empty(N_DIAG)
    core_rhs(x, u, env, K, C, E, S, k1, dd)
    if not want:
        return
    g = K[K_G]
    vx, vy, vz, wx, wy, wz = x[6], x[7], x[8], x[9], x[10], x[11]
    phi, theta = x[3], x[4]
    gb0 = -g * math.sin(theta)
    gb1 = -g * math.sin(phi) * math.cos(theta)
    gb2 = -g * math.cos(phi) * math.cos(theta)
    row[0] = float(n)
    row[1] = (k1[6] + wy * vz - wz * vy) - gb0
    row[2] = (k1[7] + wz * vx - wx * vz) - gb1
    row[3] = (k1[8] + wx * vy - wy * vx) - gb2
    row[4], row[5], row[6] = wx, wy, wz
    row[7], row[8], row[9] = k1[9], k1[10], k1[11]
    for i in range(9):
        row[10 + i] = x[i]
    for i in range(4):
        row[19 + i] = x[12 + i]
        row[23 + i] = dd[16 * i + 5] if reduced else x[16 + i]
    for i in range(9):
        row[27 + i] = u[i]


@kernel()
def truth_steps(x, k1, U, m, h, rk4, env, K, C, E, rec, n0, D):
    """``m`` steps from step ``n0`` (module docstring); recorder rows into ``rec[0:m]`` unless
    ``rec`` is empty, diagnostics of the final state into ``D`` unless empty. Returns the steps
    taken (fewer than ``m`` after a non-finite state: that step is the last)."""
    S = np.empty((4, 15))
    nod = np.empty(0)
    for j in range(m):
        ok = rk_step(x, k1, U[j], h, rk4, env, K, C, E, S)
        row = rec[j] if rec.shape[0] > 0 else nod
        record_row(x, k1, U[j + 1], n0 + j + 1, env, K, C, E, S, row, D if j == m - 1 else nod)
        if not ok:
            return j + 1
    return m


def warm() -> None:
    """Compile (or load from the cache) the kernels of this module with representative arguments."""
    from vdps_hil.model import core_kernel

    core_kernel.warm()
    for dof in (1.0, 0.0):
        K = np.ones(core_kernel.N_K)
        K[K_DOF] = dof
        E = np.array([[core_kernel.HOOK_TIRE, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
        n = 24 if dof else 16
        env, C = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]), np.ones((4, 14))
        for rec, D in ((np.empty((2, N_REC)), np.empty(N_DIAG)), (np.empty((0, N_REC)), np.empty(0))):
            truth_steps(np.zeros(n), np.zeros(n), np.zeros((3, 9)), 2, 1e-3, False, env, K, C, E, rec, 0, D)
        S = np.empty((4, 15))
        for rk4 in (True, False):
            rk_step(np.zeros(n), np.zeros(n), np.zeros(9), 1e-3, rk4, env, K, C, E, S)
        for row, D in ((np.empty(N_REC), np.empty(N_DIAG)), (np.empty(0), np.empty(0)), (np.empty(N_REC), np.empty(0)),
                       (np.empty(0), np.empty(N_DIAG))):
            record_row(np.zeros(n), np.zeros(n), np.zeros(9), 1, env, K, C, E, S, row, D)


__all__ = ["N_REC", "record_row", "rk_step", "truth_steps"]
