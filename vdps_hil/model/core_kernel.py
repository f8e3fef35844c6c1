"""The physics core compiled: :func:`core_rhs` is ``Model.f`` (the stages of
:mod:`vdps_hil.model.stages` composed by ``derivative_function``) as one compiled function of
arrays, for both variants (truth with unsprung DOF, the paper's reduced model), every effect
with a compiled form and the vehicle's chassis parts (:mod:`vdps_hil.model.chassis`: anti-roll
bars, roll centres, Ackermann fraction).

Reference and equality
----------------------
The stages stay the reference and the source of the equations. The stages that work on floats
and tuples alone (``body_attitude``, ``steer_angles`` with ``ackermann_angles``,
``spring_force_n``, ``air_velocity_b``, ``pose_rates``, ``wheel_axes``), the chassis laws
(``chassis.blend_ackermann``, ``anti_roll_forces_n``, ``roll_centre_forces_n``) and the effects'
force laws are :func:`~vdps_hil.jit.inline` functions this kernel calls as they are; the stages
that take the model's constants and effect hooks (``corner_loads`` with ``_anti_roll``,
``tire_at_corner``, ``compliance_steer_angle``, ``corner_wrench`` with ``_roll_centre``,
``effect_wrench``, ``body_accelerations``, ``unsprung_accelerations``) are mirrored here, operation
for operation, so ``core_rhs`` equals ``derivative_function``'s ``f`` bit for bit
(``tests/test_core_kernel.py``, random states, inputs, roads, winds, effect sets and chassis
parts). The one liberty: ``_roll_centre`` evaluates the tire law again at each corner, the mirror
sums the axles' body-y forces from ``corner_wrench``'s own evaluation (same arguments, same
values). A new term in a stage goes into its mirror here too (the test fails until it does).

Arrays (built once per model by :func:`pack_model`)
---------------------------------------------------
* ``K`` model constants, indices ``K_*`` (the fields of ``stages.CoreConstants``; the chassis
  parts as ``K_ACKERMANN`` e_A, ``K_ARB`` 1/0 and ``K_ARB_KF .. K_ARB_TR`` (K_arb,f, K_arb,r,
  T_f, T_r), ``K_RC`` 1/0 and ``K_RC_HF .. K_RC_TR`` (h_rc,f, h_rc,r, T_f, T_r));
* ``C`` (4, 14) corner constants, columns ``C_*`` (``CoreConstants.corners`` without i);
* ``E`` (n, 8) effect terms ``[hook, code, p0 .. p5]``: row 0 the tire model, then the
  per-call hooks in the effects' order (``HOOK_*``; codes and parameters from each effect's
  ``kernel_terms()``);
* ``S`` (4, 15) workspace: the corner states of ``stages.corner_loads`` (columns ``S_*``).

Per call: ``x`` (16 or 24), ``u`` (9: steering wheel angle, drive torques 1-4, brake torques
1-4), ``env`` (6: road normal n_g, ENU wind of the environment), output ``xd`` and the
diagnostics ``D`` (``N_DIAG`` values, or an empty array for none): per corner i the 16 values
of ``Model.evaluate``'s record at ``D[16 i:16 i + 16]`` (F_a, F_b, F_z, kappa, alpha, H, H_dot,
T, T_eff, delta, r, h_w, F_s, F_tire,x, F_tire,y, F_tire,z; the reduced model's F_z includes the
roll-centre force J_i, as the stages report it), then ``D_ACC`` (a, 3), ``D_GB``
(g_b, 3), ``D_FORCE`` (3), ``D_MOMENT`` (3), ``D_NB`` (n_b, 3), ``D_HCG`` (1), ``D_AIR`` (3).

A model with an effect that lacks a compiled form has no packed arrays (:func:`pack_model`
returns the reason instead) and runs on the stages in Python.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.jit import inline, kernel

from .chassis import anti_roll_forces_n, roll_centre_forces_n
from .effects.aero import WRENCH_AERO_DRAG, WRENCH_CROSSWIND, crosswind_wrench, drag_wrench
from .effects.base import STATIC_HOOKS
from .effects.rolling import WHEEL_ROLLING_RESISTANCE, rolling_resistance_torque
from .effects.tires import (STIFFNESS_LOAD_DEPENDENT, TIRE_LINEAR, TIRE_MAGIC_FORMULA, linear_tire_forces,
                            load_dependent_stiffness_factor, magic_formula_forces)
from .stages import air_velocity_b, body_attitude, pose_rates, spring_force_n, steer_angles, wheel_axes

HOOK_TIRE, HOOK_STIFFNESS, HOOK_WRENCH, HOOK_WHEEL = 0.0, 1.0, 2.0, 3.0
HOOK_IDS = {"tire_forces": HOOK_TIRE, "cornering_stiffness_factor": HOOK_STIFFNESS,
            "body_wrench": HOOK_WRENCH, "wheel_torque": HOOK_WHEEL}
(K_DOF, K_G, K_INV_M_TOT, K_INV_M_S, K_IYZ, K_IZX, K_IXY, K_INV_IX, K_INV_IY, K_INV_IZ, K_IW_INV, K_KT,
 K_WHEELBASE, K_TF, K_RATIO, K_ZW0, K_R_LOAD, K_VFLOOR, K_BRAKE_HOLD, K_KC, K_WIND_E, K_WIND_N, K_WIND_U,
 K_N_WRENCH, K_ACKERMANN, K_ARB, K_ARB_KF, K_ARB_KR, K_ARB_TF, K_ARB_TR, K_RC, K_RC_HF, K_RC_HR, K_RC_TF,
 K_RC_TR) = range(35)
N_K = 35
(C_X, C_Y, C_MU, C_C1, C_C2, C_C3, C_SC, C_DS, C_R, C_RFREE, C_CKAP, C_CALP, C_FZ0, C_MUG) = range(14)
(S_X, S_Y, S_Z, S_HW, S_FZ, S_FS, S_H, S_HD, S_VWX, S_VWY, S_VWZ, S_R, S_CKAP, S_CALP, S_FZ0) = range(15)
D_ACC, D_GB, D_FORCE, D_MOMENT, D_NB, D_HCG, D_AIR = 64, 67, 70, 73, 76, 79, 80
N_DIAG = 83
NO_DIAG = np.zeros(0)


@inline
def _tire(E, fz, fz0, kap, alp, ckap, calp):
    """The tire model of row 0 (``tire_fn`` of the stages)."""
    if E[0, 1] == TIRE_LINEAR:
        return linear_tire_forces(fz, kap, alp, ckap, calp)
    return magic_formula_forces(fz, fz0, kap, alp, ckap, calp, E[0, 2], E[0, 3], E[0, 4], E[0, 5], E[0, 6],
                                E[0, 7])


@inline
def _corner_loads(K, C, E, x, h_cg, n_b, vel, rate, S):
    """Mirror of ``stages.corner_loads``: the corner states into ``S``."""
    nx, ny, nz = n_b
    vx, vy, vz = vel
    wx, wy, wz = rate
    dof, arb = K[K_DOF] != 0.0, K[K_ARB] != 0.0
    zw0, kt, r_load = K[K_ZW0], K[K_KT], K[K_R_LOAD]
    farb = _anti_roll(K, C, x, h_cg, n_b) if arb else (0.0, 0.0, 0.0, 0.0)
    for i in range(4):
        xi, yi, c1, c2, c3, sc, ds = C[i, C_X], C[i, C_Y], C[i, C_C1], C[i, C_C2], C[i, C_C3], C[i, C_SC], C[i, C_DS]
        calp, fz0, mug = C[i, C_CALP], C[i, C_FZ0], C[i, C_MUG]
        if dof:
            H = x[16 + i]
            Hd = x[20 + i]
            zi = zw0 + H
            hw = h_cg + nx * xi + ny * yi + nz * zi
            defl = C[i, C_RFREE] - hw
            fz = kt * defl if defl > 0.0 else 0.0
            fs = spring_force_n(sc + H, c1, c2, c3) + ds * Hd
            if arb:
                fs += farb[i]
            vwx = vx + wy * zi - wz * yi
            vwy = vy + wz * xi - wx * zi
            vwz = vz + wx * yi - wy * xi + Hd
        else:
            zi = zw0
            hw = h_cg + nx * xi + ny * yi + nz * zi
            vwx = vx + wy * zi - wz * yi
            vwy = vy + wz * xi - wx * zi
            vwz = vz + wx * yi - wy * xi
            H = r_load - hw
            Hd = -(nx * vwx + ny * vwy + nz * vwz)
            fsp = spring_force_n(sc + H, c1, c2, c3)
            if arb:
                fsp += farb[i]
            if fsp + mug <= 0.0:  # eq 14 clamp: lift-off
                fz = 0.0
            else:
                fz = fsp + ds * Hd + mug
                if fz < 0.0:
                    fz = 0.0
            fs = fz
        for j in range(1, E.shape[0]):
            if E[j, 0] == HOOK_STIFFNESS and E[j, 1] == STIFFNESS_LOAD_DEPENDENT:
                calp = calp * load_dependent_stiffness_factor(fz, fz0, E[j, 2], E[j, 3])
        S[i, S_X], S[i, S_Y], S[i, S_Z], S[i, S_HW], S[i, S_FZ], S[i, S_FS] = xi, yi, zi, hw, fz, fs
        S[i, S_H], S[i, S_HD], S[i, S_VWX], S[i, S_VWY], S[i, S_VWZ] = H, Hd, vwx, vwy, vwz
        S[i, S_R], S[i, S_CKAP], S[i, S_CALP], S[i, S_FZ0] = C[i, C_R], C[i, C_CKAP], calp, fz0


@inline
def _pose_deflection(K, C, i, h_cg, n_b):
    """H_i = r - h_w,i of the reduced model (``stages._anti_roll``)."""
    nx, ny, nz = n_b
    return K[K_R_LOAD] - (h_cg + nx * C[i, C_X] + ny * C[i, C_Y] + nz * K[K_ZW0])


@inline
def _anti_roll(K, C, x, h_cg, n_b):
    """Mirror of ``stages._anti_roll``: F_arb,i (``chassis.anti_roll_forces_n``) from the four
    deflections, the states (unsprung DOF) or H_i = r - h_w,i of the pose (reduced model)."""
    if K[K_DOF] != 0.0:
        h = (x[16], x[17], x[18], x[19])
    else:
        h = (_pose_deflection(K, C, 0, h_cg, n_b), _pose_deflection(K, C, 1, h_cg, n_b),
             _pose_deflection(K, C, 2, h_cg, n_b), _pose_deflection(K, C, 3, h_cg, n_b))
    return anti_roll_forces_n(K[K_ARB_KF], K[K_ARB_KR], K[K_ARB_TF], K[K_ARB_TR], h)


@inline
def _tire_at_corner(S, i, delta, n_b, x, v_floor, E):
    """Mirror of ``stages.tire_at_corner``: (F_a, F_b, kappa, alpha, e_l (3), e_t (3))."""
    lx, ly, lz, tx, ty, tz = wheel_axes(delta, n_b)
    vwx, vwy, vwz = S[i, S_VWX], S[i, S_VWY], S[i, S_VWZ]
    vl = vwx * lx + vwy * ly + vwz * lz
    vt = vwx * tx + vwy * ty + vwz * tz
    den = vl if vl > 0.0 else -vl
    if den < v_floor:
        den = v_floor
    kap = (S[i, S_R] * x[12 + i] - vl) / den
    alp = -math.atan(vt / den)
    fa, fb = _tire(E, S[i, S_FZ], S[i, S_FZ0], kap, alp, S[i, S_CKAP], S[i, S_CALP])
    return fa, fb, kap, alp, lx, ly, lz, tx, ty, tz


@inline
def _compliance_steer_angle(k_c, S, d1, d2, n_b, x, v_floor, E):
    """Mirror of ``stages.compliance_steer_angle`` (one secant step from delta_c = 0)."""
    r0 = 0.0 + k_c * (_tire_at_corner(S, 0, d1 + 0.0, n_b, x, v_floor, E)[1]
                      + _tire_at_corner(S, 1, d2 + 0.0, n_b, x, v_floor, E)[1])
    dc1 = -r0
    r1 = dc1 + k_c * (_tire_at_corner(S, 0, d1 + dc1, n_b, x, v_floor, E)[1]
                      + _tire_at_corner(S, 1, d2 + dc1, n_b, x, v_floor, E)[1])
    den = r1 - r0
    return dc1 - r1 * dc1 / den if den != 0.0 else dc1


@inline
def _corner_wrench(K, E, S, deltas, n_b, x, u, xd, fzt, D):
    """Mirror of ``stages.corner_wrench`` and ``stages._roll_centre``: the tires' wrench;
    omega_dot_i into ``xd[12:16]``, the tires' body-z forces into ``fzt[0:4]``, the roll-centre
    forces J_i into ``fzt[4:8]`` (with roll centres), the per-corner records into ``D`` (when not
    empty). The axles' body-y tire forces are summed from this loop's tire forces: the stages
    evaluate the tire law again at each corner, with the same arguments, to the same values."""
    dof, v_floor, iw_inv, wbrake = K[K_DOF] != 0.0, K[K_VFLOOR], K[K_IW_INV], K[K_BRAKE_HOLD]
    rc = K[K_RC] != 0.0
    nx, ny, nz = n_b
    Fx = Fy = Fz = Mx = My = Mz = 0.0
    fyf = fyr = 0.0
    for i in range(4):
        xi, yi, zi, hw, fz, fs, ri = S[i, S_X], S[i, S_Y], S[i, S_Z], S[i, S_HW], S[i, S_FZ], S[i, S_FS], S[i, S_R]
        fa, fb, kap, alp, lx, ly, lz, tx, ty, tz = _tire_at_corner(S, i, deltas[i], n_b, x, v_floor, E)
        ftx = fa * lx + fb * tx + fz * nx
        fty = fa * ly + fb * ty + fz * ny
        ftz = fa * lz + fb * tz + fz * nz
        if rc:
            if i < 2:
                fyf += fa * ly + fb * ty
            else:
                fyr += fa * ly + fb * ty
        rcx, rcy, rcz = xi - hw * nx, yi - hw * ny, zi - hw * nz
        Mx += rcy * ftz - rcz * fty
        My += rcz * ftx - rcx * ftz
        Mz += rcx * fty - rcy * ftx
        Fx += ftx
        Fy += fty
        if dof:
            Fz += fs
            Mx += yi * (fs - ftz)
            My -= xi * (fs - ftz)
            fzt[i] = ftz
        else:
            Fz += ftz
        om = x[12 + i]
        tq = u[1 + i]
        b = u[5 + i]
        if b != 0.0:
            s = om / wbrake
            tq -= b * (1.0 if s > 1.0 else (-1.0 if s < -1.0 else s))
        teff = 0.0
        for j in range(1, E.shape[0]):
            if E[j, 0] == HOOK_WHEEL and E[j, 1] == WHEEL_ROLLING_RESISTANCE:
                teff += rolling_resistance_torque(E[j, 2], om, fz, ri)
        xd[12 + i] = (tq - ri * fa + teff) * iw_inv
        if D.size > 0:
            r = D[16 * i:16 * i + 16]
            r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7] = fa, fb, fz, kap, alp, S[i, S_H], S[i, S_HD], tq
            r[8], r[9], r[10], r[11], r[12], r[13], r[14], r[15] = teff, deltas[i], ri, hw, fs, ftx, fty, ftz
    if rc:
        jac = roll_centre_forces_n(K[K_RC_HF], K[K_RC_HR], K[K_RC_TF], K[K_RC_TR], fyf, fyr)
        for i in range(4):
            j = jac[i]
            Fz += j
            Mx += S[i, S_Y] * j
            My -= S[i, S_X] * j
            fzt[4 + i] = j
            if D.size > 0 and not dof:
                D[16 * i + 2] = D[16 * i + 2] + j
    return Fx, Fy, Fz, Mx, My, Mz


@inline
def _effect_wrench(E, wrench, air):
    """Mirror of ``stages.effect_wrench``: each body-wrench term added in the effects' order."""
    Fx, Fy, Fz, Mx, My, Mz = wrench
    ax, ay, az = air
    for j in range(1, E.shape[0]):
        if E[j, 0] != HOOK_WRENCH:
            continue
        if E[j, 1] == WRENCH_AERO_DRAG:
            ex, ey, ez, emx, emy, emz = drag_wrench(E[j, 2], E[j, 3], ax, ay, az)
        else:
            ex, ey, ez, emx, emy, emz = crosswind_wrench(E[j, 2], E[j, 3], E[j, 4], ax, ay, az)
        Fx += ex
        Fy += ey
        Fz += ez
        Mx += emx
        My += emy
        Mz += emz
    return Fx, Fy, Fz, Mx, My, Mz


@inline
def _body_accelerations(K, C, S, wrench, g_b, rate):
    """Mirror of ``stages.body_accelerations``: (a, omega_dot, M)."""
    Fx, Fy, Fz, Mx, My, Mz = wrench
    gx, gy, gz = g_b
    wx, wy, wz = rate
    dof = K[K_DOF] != 0.0
    inv_m_tot = K[K_INV_M_TOT]
    ax_ = Fx * inv_m_tot + gx
    ay_ = Fy * inv_m_tot + gy
    if dof:
        az_ = Fz * K[K_INV_M_S] + gz
    else:
        az_ = Fz * inv_m_tot + gz
    for i in range(4):
        xi, yi, mu, zi = C[i, C_X], C[i, C_Y], C[i, C_MU], S[i, S_Z]
        ux, uy = mu * (gx - ax_), mu * (gy - ay_)
        uz = 0.0 if dof else mu * (gz - az_)
        Mx += yi * uz - zi * uy
        My += zi * ux - xi * uz
        Mz += xi * uy - yi * ux
    dw = (K[K_IYZ] * wy * wz + Mx * K[K_INV_IX], K[K_IZX] * wz * wx + My * K[K_INV_IY],
          K[K_IXY] * wx * wy + Mz * K[K_INV_IZ])
    return (ax_, ay_, az_), dw, (Mx, My, Mz)


@inline
def _unsprung_accelerations(C, S, fzt, rc, acc, dw, rate, gz, xd):
    """Mirror of ``stages.unsprung_accelerations``: H_ddot_i into ``xd[20:24]`` (``rc``: with
    the roll-centre forces J_i of ``fzt[4:8]``)."""
    wx, wy, wz = rate
    dwx, dwy, _ = dw
    az_ = acc[2]
    ww = wx * wx + wy * wy + wz * wz
    for i in range(4):
        xi, yi, mu, zi = C[i, C_X], C[i, C_Y], C[i, C_MU], S[i, S_Z]
        acc_z = az_ + (dwx * yi - dwy * xi) + (wz * (wx * xi + wy * yi + wz * zi) - zi * ww)
        f_link = S[i, S_FS] + fzt[4 + i] if rc else S[i, S_FS]
        xd[20 + i] = (fzt[i] - f_link) / mu + gz - acc_z


@kernel()
def core_rhs(x, u, env, K, C, E, S, xd, D):
    """x_dot = f(x, u, env) into ``xd``; diagnostics into ``D`` unless empty (module docstring).
    Mirror of ``stages.derivative_function``'s ``f``."""
    dof = K[K_DOF] != 0.0
    vel, rate = (x[6], x[7], x[8]), (x[9], x[10], x[11])
    trig, c, n_b, g_b, h_cg = body_attitude((x[0], x[1], x[2]), (x[3], x[4], x[5]), (env[0], env[1], env[2]),
                                            K[K_G])
    d1, d2 = steer_angles(u[0] / K[K_RATIO], K[K_WHEELBASE], K[K_TF], K[K_ACKERMANN])
    _corner_loads(K, C, E, x, h_cg, n_b, vel, rate, S)
    k_c, v_floor = K[K_KC], K[K_VFLOOR]
    dcomp = _compliance_steer_angle(k_c, S, d1, d2, n_b, x, v_floor, E) if k_c != 0.0 else 0.0
    deltas = (d1 + dcomp, d2 + dcomp, 0.0, 0.0)
    fzt = np.zeros(8)
    wrench = _corner_wrench(K, E, S, deltas, n_b, x, u, xd, fzt, D)
    wind_env, wind_eff = (env[3], env[4], env[5]), (K[K_WIND_E], K[K_WIND_N], K[K_WIND_U])
    if K[K_N_WRENCH] > 0.0:
        wrench = _effect_wrench(E, wrench, air_velocity_b(vel, c, wind_env, wind_eff))
    acc, dw, moment = _body_accelerations(K, C, S, wrench, g_b, rate)
    p0, p1, p2, p3, p4, p5 = pose_rates(trig, c, vel, rate)
    xd[0], xd[1], xd[2], xd[3], xd[4], xd[5] = p0, p1, p2, p3, p4, p5
    wx, wy, wz = rate
    vx, vy, vz = vel
    xd[6] = acc[0] - (wy * vz - wz * vy)
    xd[7] = acc[1] - (wz * vx - wx * vz)
    xd[8] = acc[2] - (wx * vy - wy * vx)
    xd[9], xd[10], xd[11] = dw
    if dof:
        for i in range(4):
            xd[16 + i] = x[20 + i]
        _unsprung_accelerations(C, S, fzt, K[K_RC] != 0.0, acc, dw, rate, g_b[2], xd)
    if D.size > 0:
        air = air_velocity_b(vel, c, wind_env, wind_eff)
        for k in range(3):
            D[D_ACC + k], D[D_GB + k], D[D_FORCE + k] = acc[k], g_b[k], wrench[k]
            D[D_MOMENT + k], D[D_NB + k], D[D_AIR + k] = moment[k], n_b[k], air[k]
        D[D_HCG] = h_cg


def kernel_terms_of(effect) -> tuple | None:
    """An effect's compiled terms, or None when it has none or a subclass overrides a hook of
    the class whose compiled form it inherits (the compiled form would not be its formula)."""
    terms = effect.kernel_terms()
    if terms is None:
        return None
    owner = next(k for k in type(effect).__mro__ if "kernel_terms" in vars(k))
    for hook in set(effect.HOOKS) - STATIC_HOOKS:
        if getattr(type(effect), hook) is not getattr(owner, hook, None):
            return None
    return terms


def pack_model(k, effects) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray] | None, str]:
    """((K, C, E), "compiled") from a model's ``stages.CoreConstants`` ``k`` and its dynamics
    effects (tire first), or (None, reason) when an effect has no compiled form."""
    rows = []
    for e in effects:
        terms = kernel_terms_of(e)
        if terms is None:
            return None, f"effect {e.name!r} has no compiled form"
        for hook, code, params in terms:
            if len(params) > 6 or hook not in HOOK_IDS:
                return None, f"effect {e.name!r}: unknown compiled term {hook!r}"
            row = [HOOK_IDS[hook], float(code), *params] + [0.0] * (6 - len(params))
            rows.insert(0, row) if hook == "tire_forces" else rows.append(row)
    n_wrench = sum(1 for r in rows if r[0] == HOOK_WRENCH)
    if not rows or rows[0][0] != HOOK_TIRE or rows[0][1] not in (TIRE_LINEAR, TIRE_MAGIC_FORMULA):
        return None, "no compiled tire model"
    known = {HOOK_STIFFNESS: (STIFFNESS_LOAD_DEPENDENT,), HOOK_WRENCH: (WRENCH_AERO_DRAG, WRENCH_CROSSWIND),
             HOOK_WHEEL: (WHEEL_ROLLING_RESISTANCE,)}
    if any(r[1] not in known[r[0]] for r in rows[1:]):
        return None, "unknown compiled effect code"
    Iyz, Izx, Ixy, inv_Ix, inv_Iy, inv_Iz = k.inertia
    K = np.array([1.0 if k.unsprung_dof else 0.0, k.g, k.inv_m_tot, k.inv_m_s, Iyz, Izx, Ixy, inv_Ix, inv_Iy,
                  inv_Iz, k.iw_inv, k.tire_radial_stiffness, k.wheelbase_m, k.track_half_front_m, k.steer_ratio,
                  k.zw0, k.r_load, k.v_floor, k.brake_hold_radps, k.k_c, *k.wind_effects, float(n_wrench),
                  *_chassis_terms(k)])
    C = np.array([c[1:] for c in k.corners], dtype=float)
    return (K, C, np.array(rows, dtype=float)), "compiled"


def _chassis_terms(k) -> list[float]:
    """K[K_ACKERMANN:N_K]: the Ackermann fraction, then a flag (1: present) and the four
    constants of the anti-roll bars (``CoreConstants.arb``) and of the roll centres
    (``CoreConstants.roll_centre``), zeros when absent."""
    out = [float(k.ackermann_fraction)]
    for part in (k.arb, k.roll_centre):
        out += [0.0] * 5 if part is None else [1.0, *(float(v) for v in part)]
    return out


def warm() -> None:
    """Compile (or load from the cache) :func:`core_rhs` with representative arguments."""
    for dof in (1.0, 0.0):
        K = np.ones(N_K)
        K[K_DOF] = dof
        E = np.array([[HOOK_TIRE, TIRE_MAGIC_FORMULA, 1.0, -0.1, 1.65, 0.0, 1.3, -1.0]])
        x = np.zeros(24 if dof else 16)
        for D in (NO_DIAG, np.empty(N_DIAG)):
            core_rhs(x, np.zeros(9), np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0]), K, np.ones((4, 14)), E,
                     np.empty((4, 15)), np.empty(x.size), D)




def compiled_function(arrays, size: int):
    """``f(x, u, env, out=None) -> x_dot`` (list) of ``Model.f``'s signature on :func:`core_rhs`
    with the packed ``arrays`` (K, C, E) of a model of ``size`` states; ``out`` gets the named
    diagnostics of the Python core (``_rec``, ``_acc_b``, ``_g_b``, ``_force_b``, ``_moment_b``,
    ``_normal_b``, ``_height_cg``, ``_air_b`` unless ``out["_want_air"]`` is false). Scratch
    arrays are made per call, so one model may be evaluated from several threads."""
    K, C, E = arrays
    envs: dict = {}

    def f(x, u, env, out=None):
        ea = envs.get(id(env))
        if ea is None or ea[0] is not env:
            if len(envs) > 8:
                envs.clear()
            ea = envs[id(env)] = (env, np.array((*env.normal_g, *env.wind_enu_mps)))
        ua = np.array((u.steer_wheel_angle_rad, *u.wheel_torque_nm, *u.brake_torque_nm))
        xd = np.empty(size)
        D = NO_DIAG if out is None else np.empty(N_DIAG)
        core_rhs(np.asarray(x, dtype=float), ua, ea[1], K, C, E, np.empty((4, 15)), xd, D)
        if out is not None:
            fill_diagnostics(out, D)
        return xd.tolist()

    return f


def fill_diagnostics(out: dict, D: np.ndarray) -> None:
    """The named diagnostics of the Python core (``compiled_function``) from ``D``."""
    d = D.tolist()
    out["_rec"] = [tuple(d[16 * i:16 * i + 16]) for i in range(4)]
    out["_acc_b"] = tuple(d[D_ACC:D_ACC + 3])
    out["_g_b"] = tuple(d[D_GB:D_GB + 3])
    out["_force_b"] = tuple(d[D_FORCE:D_FORCE + 3])
    out["_moment_b"] = tuple(d[D_MOMENT:D_MOMENT + 3])
    out["_normal_b"] = tuple(d[D_NB:D_NB + 3])
    out["_height_cg"] = d[D_HCG]
    if out.get("_want_air", True):
        out["_air_b"] = tuple(d[D_AIR:D_AIR + 3])


__all__ = ["N_DIAG", "NO_DIAG", "compiled_function", "core_rhs", "fill_diagnostics", "kernel_terms_of",
           "pack_model"]
