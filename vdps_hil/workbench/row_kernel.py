"""The residuals of eq 13 on every row of a drive in one compiled call: :func:`residual_rows` is
:class:`~vdps_hil.workbench.row_model.RowModel`'s ``residual`` (with its measured loads, the
slip the tire law gives the measured spin balance, and the slip columns), run over all rows with
the two velocity perturbations :func:`~vdps_hil.workbench.residuals.compute_residuals` takes
its nuisance columns from, on the compiled physics core (``model.core_kernel.core_rhs``).

Reference and equality
----------------------
``RowModel.residual`` stays the reference and the source of the equations; the functions here
mirror it operation for operation, so the values, the wheel-speed parts, the nuisance and the
slip columns are bit for bit those of the per-row path (``tests/test_row_kernel.py``: the
paper's vehicle and CommonRoad's with its chassis parts, the linear and the Magic Formula tire,
with and without measured suspension). A model whose core is not compiled (an effect without a
compiled form, or ``VDPS_JIT=0``) takes the per-row path.

Arrays
------
* ``X`` (n, 16) the reduced model's row states, ``U`` (n, 9) the inputs (steering wheel angle,
  drive torques 1-4, brake torques 1-4), ``ENV`` (n, 6) the road normal n_g and the ENU wind,
  ``MEAS`` (n, 22) the measured side (``RowStates.meas`` after the measurement effects);
* ``K, C, E`` the packed core (``core_kernel.pack_model``);
* ``P`` the row model's constants, indices ``P_*`` (mass, inertias, wheel inertia, slip
  stiffnesses C_kappa,i, the wheel centres' body z, the anti-roll bars and roll centres with the
  full track widths, 1.0 when the tire law is inverted for the slip, F_z0,i and C_alpha,i);
  ``CORN`` (4, 2) the corners' (x, y); ``SPR`` (4, 6) the spring law per corner (c1, c2, c3,
  static compression, damper, unsprung weight m_u g);
* outputs per row: ``XD`` (n, 16) x_dot and ``DG`` (n, N_DIAG) the core's diagnostics at the
  row's own state (for the named quantities), ``VALS`` (n, 14), ``WS`` (n, 8) v_l,i and
  kappa_q,i, ``NUIS`` (n, 14, 2) d r / d v_x and d r / d v_y by forward differences of 0.02 m/s,
  ``SLIP`` (n, 14, 8) d r / d F_a,i and d r / d F_b,i times alpha_i.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.jit import inline, kernel
from vdps_hil.model.chassis import anti_roll_forces_n, roll_centre_forces_n
from vdps_hil.model.core_kernel import D_ACC, D_GB, D_NB, N_DIAG, _tire, core_rhs
from vdps_hil.model.stages import wheel_axes

__all__ = ["N_P", "P_ARB", "P_CA", "P_CK", "P_FZ0", "P_NEWTON", "P_RC", "residual_rows", "warm"]

(P_MASS, P_IX, P_IY, P_IZ, P_IW) = range(5)
P_CK = 5  # 4 values
P_ZW = 9
P_ARB, P_KF, P_KR, P_TF, P_TR, P_RC, P_HF, P_HR, P_NEWTON = range(10, 19)
P_FZ0 = 19  # 4 values
P_CA = 23  # 4 values
P_RU = 27  # 3 values: the unsprung masses' moment arm (RowModel.unsprung_arm_m)
N_P = 30
NUISANCE_STEP_MPS = 0.02


@inline
def measured_normal_load(c1, c2, c3, sc, ds, mug, h, hd, farb):
    """Eq 14's normal load [N] from a measured deflection ``h`` and rate ``hd``: the spring
    (K_s(H) H, H = static compression ``sc`` + h) plus the anti-roll bar's ``farb`` (0 without
    one), the damper and the unsprung weight ``mug``, with the core's lift-off clamp. Shared by
    ``RowModel._measured_loads`` and the kernel."""
    hs = sc + h
    fsp = c1 * math.exp(c2 * ((hs if hs < 10.0 else 10.0) - c3)) * hs + farb
    if fsp + mug <= 0.0:
        return 0.0
    fz = fsp + ds * hd + mug
    return 0.0 if fz < 0.0 else fz


@inline
def normal_load_change(r, d, hw, xi, yi, zw, nx, ny, nz):
    """A corner's normal load changed by ``d`` [N] along the road normal n at its contact point
    r_c = (x_i, y_i, z_w) - h_w n: its force and moment taken off the residual ``r`` (rows 0-5).
    The callers pass the corner relative to the unsprung masses' arm r_u
    (``RowModel.unsprung_arm_m``), so the moment is the core's (r_c - r_u) x F. Shared by
    ``RowModel._measured_loads`` and the kernel."""
    rcx, rcy, rcz = xi - hw * nx, yi - hw * ny, zw - hw * nz
    fx, fy, fz = nx * d, ny * d, nz * d
    r[0] -= fx
    r[1] -= fy
    r[2] -= fz
    r[3] -= rcy * fz - rcz * fy
    r[4] -= rcz * fx - rcx * fz
    r[5] -= rcx * fy - rcy * fx


@inline
def _measured_loads(r, D, meas, P, CORN, SPR):
    """Mirror of ``RowModel._measured_loads``: the loads from the measured deflections (eq 14)
    in place of the rigid-tire pose's, acting along n at the contact points."""
    nx, ny, nz = D[D_NB], D[D_NB + 1], D[D_NB + 2]
    zw = P[P_ZW]
    farb = (0.0, 0.0, 0.0, 0.0)
    if P[P_ARB] != 0.0:
        farb = anti_roll_forces_n(P[P_KF], P[P_KR], P[P_TF], P[P_TR], (meas[14], meas[15], meas[16], meas[17]))
    jac = (0.0, 0.0, 0.0, 0.0)
    if P[P_RC] != 0.0:
        fy0 = 0.0
        fy1 = 0.0
        for i in range(4):
            lx, ly, lz, tx, ty, tz = wheel_axes(D[16 * i + 9], (nx, ny, nz))
            if i < 2:
                fy0 += D[16 * i] * ly + D[16 * i + 1] * ty
            else:
                fy1 += D[16 * i] * ly + D[16 * i + 1] * ty
        jac = roll_centre_forces_n(P[P_HF], P[P_HR], P[P_TF], P[P_TR], fy0, fy1)
    for i in range(4):
        fz = measured_normal_load(SPR[i, 0], SPR[i, 1], SPR[i, 2], SPR[i, 3], SPR[i, 4], SPR[i, 5], meas[14 + i],
                                  meas[18 + i], farb[i])
        if P[P_RC] != 0.0:
            fz += jac[i]
        normal_load_change(r, fz - D[16 * i + 2], D[16 * i + 11], CORN[i, 0] - P[P_RU], CORN[i, 1] - P[P_RU + 1],
                           zw - P[P_RU + 2], nx, ny, nz)


@inline
def _slip_for_force(E, fz, fz0, alp, ck, ca, fa_target, k0):
    """Mirror of ``RowModel._slip_for_force``: Newton on the tire law for the slip ratio whose
    longitudinal force is the measured one (three steps from the linear tire's value)."""
    k = k0
    for _ in range(3):
        f0 = _tire(E, fz, fz0, k, alp, ck, ca)[0]
        h = 1e-5
        df = (_tire(E, fz, fz0, k + h, alp, ck, ca)[0] - f0) / h
        if not df > 0.05 * ck:
            break
        k = k + (fa_target - f0) / df
    return k


@inline
def _row(x, meas, xd, D, P, CORN, SPR, E, r, ws):
    """Mirror of ``RowModel.residual`` after the core's call: the 14 residuals into ``r`` and
    the wheel-speed parts (v_l,i, kappa_q,i) into ``ws``."""
    mass, ix, iy, iz = P[P_MASS], P[P_IX], P[P_IY], P[P_IZ]
    r[0] = mass * (meas[0] - (D[D_ACC] - D[D_GB]))
    r[1] = mass * (meas[1] - (D[D_ACC + 1] - D[D_GB + 1]))
    r[2] = mass * (meas[2] - (D[D_ACC + 2] - D[D_GB + 2]))
    r[3] = ix * (meas[3] - xd[9])
    r[4] = iy * (meas[4] - xd[10])
    r[5] = iz * (meas[5] - xd[11])
    for k in range(6, 14):
        r[k] = 0.0
    if meas[14] == meas[14] and meas[18] == meas[18]:
        _measured_loads(r, D, meas, P, CORN, SPR)
    iw, zw = P[P_IW], P[P_ZW]
    vx, vy, vz = x[6], x[7], x[8]
    wx, wy, wz = x[9], x[10], x[11]
    nx, ny, nz = D[D_NB], D[D_NB + 1], D[D_NB + 2]
    for i in range(4):
        b = 16 * i
        tq, teff, delta, ri = D[b + 7], D[b + 8], D[b + 9], D[b + 10]
        r[6 + i] = iw * (meas[6 + i] - xd[12 + i])
        xi, yi = CORN[i, 0], CORN[i, 1]
        cd, sd = math.cos(delta), math.sin(delta)
        hn = cd * nx + sd * ny
        lx, ly, lz = cd - hn * nx, sd - hn * ny, -hn * nz
        inv = 1.0 / math.sqrt(lx * lx + ly * ly + lz * lz)
        vwx = vx + wy * zw - wz * yi
        vwy = vy + wz * xi - wx * zw
        vwz = vz + wx * yi - wy * xi
        vl = (vwx * lx + vwy * ly + vwz * lz) * inv
        ck = P[P_CK + i]
        kq = (tq + teff - iw * meas[6 + i]) / (ri * ck)
        if P[P_NEWTON] != 0.0:
            kq = _slip_for_force(E, D[b + 2], P[P_FZ0 + i], D[b + 4], ck, P[P_CA + i], kq * ck, kq)
        r[10 + i] = vl * (1.0 + kq) - ri * meas[10 + i]
        ws[i] = vl
        ws[4 + i] = kq


@inline
def corner_force_columns(out, i, delta, ri, hw, alp, xi, yi, zw, nx, ny, nz):
    """Corner ``i``'s two columns of ``RowModel._slip_columns`` into ``out`` (14 x 8): d r / d F_a,i
    (column i: along the wheel's heading e_l at the contact point r_c, force, moment r_c x e_l,
    wheel spin -r_i) and d r / d F_b,i times alpha_i (column 4 + i: along e_t). ``xi, yi, zw``: the
    corner relative to the unsprung masses' arm r_u (``RowModel.unsprung_arm_m``; the moment is
    then the core's (r_c - r_u) x F). Shared by the reference and the kernel: one formula for both."""
    lx, ly, lz, tx, ty, tz = wheel_axes(delta, (nx, ny, nz))
    rcx, rcy, rcz = xi - hw * nx, yi - hw * ny, zw - hw * nz
    out[0, i], out[1, i], out[2, i] = -lx, -ly, -lz
    out[3, i] = -(rcy * lz - rcz * ly)
    out[4, i] = -(rcz * lx - rcx * lz)
    out[5, i] = -(rcx * ly - rcy * lx)
    out[6 + i, i] = ri
    k = 4 + i
    out[0, k], out[1, k], out[2, k] = -tx * alp, -ty * alp, -tz * alp
    out[3, k] = -(rcy * tz - rcz * ty) * alp
    out[4, k] = -(rcz * tx - rcx * tz) * alp
    out[5, k] = -(rcx * ty - rcy * tx) * alp


@inline
def _slip_columns(D, P, CORN, out):
    """Mirror of ``RowModel._slip_columns``: (14, 8) d r / d F_a,i (columns 0-3) and d r / d F_b,i
    times alpha_i (columns 4-7) into ``out`` (zeroed here)."""
    nx, ny, nz = D[D_NB], D[D_NB + 1], D[D_NB + 2]
    out[:, :] = 0.0
    for i in range(4):
        b = 16 * i
        corner_force_columns(out, i, D[b + 9], D[b + 10], D[b + 11], D[b + 4], CORN[i, 0] - P[P_RU],
                             CORN[i, 1] - P[P_RU + 1], P[P_ZW] - P[P_RU + 2],
                             nx, ny, nz)


@kernel()
def residual_rows(X, U, ENV, MEAS, K, C, E, P, CORN, SPR, nuisance, XD, DG, VALS, WS, NUIS, SLIP):
    """Every row's residuals, wheel-speed parts and (``nuisance`` true) velocity-nuisance and
    slip columns into the output arrays (module docstring)."""
    n, size = X.shape[0], X.shape[1]
    S = np.empty((4, 15))
    xp = np.empty(size)
    xd2 = np.empty(size)
    D2 = np.empty(N_DIAG)
    r2 = np.empty(14)
    ws2 = np.empty(8)
    h = NUISANCE_STEP_MPS
    for j in range(n):
        x, u, env, meas = X[j], U[j], ENV[j], MEAS[j]
        core_rhs(x, u, env, K, C, E, S, XD[j], DG[j])
        _row(x, meas, XD[j], DG[j], P, CORN, SPR, E, VALS[j], WS[j])
        if not nuisance:
            continue
        for c in range(2):
            for k in range(size):
                xp[k] = x[k]
            xp[6 + c] += h
            core_rhs(xp, u, env, K, C, E, S, xd2, D2)
            _row(xp, meas, xd2, D2, P, CORN, SPR, E, r2, ws2)
            for k in range(14):
                NUIS[j, k, c] = (r2[k] - VALS[j, k]) / h
        _slip_columns(DG[j], P, CORN, SLIP[j])


def warm() -> None:
    """Compile (or load from the cache) :func:`residual_rows` with representative arguments."""
    from vdps_hil.model.core_kernel import HOOK_TIRE, N_K
    from vdps_hil.model.effects.tires import TIRE_MAGIC_FORMULA

    n = 2
    K = np.ones(N_K)
    K[0] = 0.0
    E = np.array([[HOOK_TIRE, TIRE_MAGIC_FORMULA, 1.0, -0.1, 1.65, 0.0, 1.3, -1.0]])
    env = np.zeros((n, 6))
    env[:, 2] = 1.0
    residual_rows(np.zeros((n, 16)), np.zeros((n, 9)), env, np.zeros((n, 22)), K, np.ones((4, 14)), E,
                  np.ones(N_P), np.ones((4, 2)), np.ones((4, 6)), True, np.empty((n, 16)), np.empty((n, N_DIAG)),
                  np.empty((n, 14)), np.empty((n, 8)), np.empty((n, 14, 2)), np.empty((n, 14, 8)))
