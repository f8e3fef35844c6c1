"""A faster evaluation of the physics core's reduced model (paper eq 13-16) for the paper's
effect set: the same equations as :meth:`vdps_hil.model.core.Model.f` with
``unsprung_dof=False`` and ``linear_tire`` (plus static rolling-radius factors), specialised
once per model and once per input value, and compiled (:mod:`vdps_hil.jit`).

This is a **hand-specialised numeric kernel**, kept beside its reference on purpose: it does not
call the stages of :mod:`vdps_hil.model.stages` (which ``Model.f`` composes) but writes the
reduced model's stages out in one loop, rearranged (below) and therefore equal to ``Model.f``
to rounding, not bit for bit. Its evaluation (:func:`reduced_rhs`, ~100 lines) is one function
on purpose: splitting it into calls would cost the predictor's hot loop. It is tested equal to
``Model.f`` in ``tests/test_reduced.py`` (relative 1e-9; measured ~1e-12), and the compiled
kernel bit for bit equal to its Python reference (``reduced_rhs.py_func``, the same source run
by CPython: the same IEEE operations in the same order, the same libm).

Why: the predictor integrates this model 500 steps (1000 f-evaluations) per 5 s prediction;
the generic core resolves effect hooks, builds per-corner tuples, calls a tire function per
corner and fills a diagnostics dict on every call. Here everything that depends only on the
vehicle or on the (held) inputs is computed once:

* per model (:class:`ReducedLinearCore`): the model constants ``K`` (index names ``K_*``) and
  the corner constants ``C`` (one row per corner, columns ``C_*``): x_i, y_i, spring C1 C2 C3,
  static compression + r, damper, r_i, C_kappa,i, C_alpha,i, m_u,i g; and the unsprung masses'
  first moments ``S_mu = sum m_u,i``, ``S_mux = sum m_u,i x_i``, ``S_muy = sum m_u,i y_i``;
* per input (:meth:`ReducedLinearCore.inputs`): the Ackermann wheel angles' cos/sin, the drive
  and brake torques.

The chassis parts of ``model.chassis`` are in the kernel too (as ``stages.corner_loads`` and
``stages.corner_wrench`` have them): the anti-roll bars' F_arb,i = K_arb (H_i - H_j) / T^2 with
H_i - H_j = h_w,j - h_w,i, added to the spring force before eq 14's clamp; the roll centres'
J_i = -+ F_y,axle h_rc / T from each axle's body-y tire force (F_a e_l + F_b e_t), acting on the
body along z at the struts and reported in the corner's normal load (``fz``; the tire itself
keeps the load of eq 14, ``tire_fz``); the Ackermann fraction in the wheel angles.

The equations are those of :mod:`vdps_hil.model.core` (read its docstring for the symbols);
the only rearrangement is the unsprung masses' weight and inertia moment, summed over the
corners with the first moments above (all wheel centres share z_w)::

    M_u = sum_i r_w,i x m_u,i (g_b - a) = (S_muy (g_z - a_z) - z_w S_mu (g_y - a_y),
                                           z_w S_mu (g_x - a_x) - S_mux (g_z - a_z),
                                           S_mux (g_y - a_y) - S_muy (g_x - a_x))

:func:`wheel_spin_jacobian` gives the diagonal d omega_dot_i / d omega_i the predictor's ROS2
integrator needs, in closed form (eq 13 last line, eq 15)::

    d omega_dot_i / d omega_i = -(r_i C_kappa,i r_i / den_i) / I_w     (F_z,i > 0; else 0)
                                - B_i d sat(omega_i / 2 rad/s) / d omega_i / I_w

den_i = max(|v_l,i|, v_floor); the brake term is taken as the same forward difference the
generic path uses (step ``1e-4 max(1, |omega_i|)``), so the two agree also at the kink.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.jit import kernel
from vdps_hil.units import GRAVITY_MPS2

from .core import BRAKE_HOLD_SPEED_RADPS, Inputs, Model
from .effects import LinearTire
from .frames import dcm_gv_elements
from .stages import steer_angles

STATIC_HOOKS = frozenset({"rolling_radius_factor", "anti_roll_stiffness"})
"""Effect hooks the core resolves at construction (nothing to do per call: the rolling radii, the
auxiliary roll stiffness of ``anti_roll_stiffness`` effects)."""

# model constants K[...]: 1/m_tot, g, (I_y - I_z)/I_x, (I_z - I_x)/I_y, (I_x - I_y)/I_z, 1/I_x,
# 1/I_y, 1/I_z, 1/I_w, z_w, v_floor, brake hold speed, S_mux, S_muy, z_w S_mu, K_arb,f / T_f^2,
# K_arb,r / T_r^2, h_rc,f / T_f, h_rc,r / T_r
(K_INV_M, K_G, K_IYZ, K_IZX, K_IXY, K_INV_IX, K_INV_IY, K_INV_IZ, K_IW_INV, K_ZW, K_VFLOOR, K_WB,
 K_S_MUX, K_S_MUY, K_ZS_MU, K_ARB_F, K_ARB_R, K_RC_F, K_RC_R) = range(19)
N_K = 19
# corner constants C[i, ...]: x_i, y_i, C1, C2, C3, static compression + r, D_s, r_i, C_kappa,
# C_alpha, m_u g
C_X, C_Y, C_C1, C_C2, C_C3, C_SR, C_DS, C_R, C_CKAP, C_CALP, C_MUG = range(11)
N_C = 11


def supports(model: Model) -> bool:
    """True when ``model`` is the reduced model with the linear tire and no per-call effect
    hooks (the paper's set; a static ``rolling_radius_factor`` is allowed), with any chassis
    parts (``model.chassis``: anti-roll bars, roll centres, Ackermann fraction)."""
    if model.unsprung_dof or type(model.effects.tire) is not LinearTire:
        return False
    return all(e is model.effects.tire or set(e.HOOKS) <= STATIC_HOOKS for e in model.effects.dynamics)


@kernel()
def reduced_rhs(x, csd, torques, brakes, ng, K, C, xd, fzs, nb, kaps, dens, tfzs):
    """The hand-specialised kernel of the reduced model's stages in one loop (module docstring):
    writes x_dot (16) into ``xd``, the normal loads F_z,i (roll-centre forces included) into
    ``fzs``, n_b into ``nb``, kappa_i into ``kaps``, den_i into ``dens`` and the tires' loads
    (eq 14) into ``tfzs``. ``csd`` (4, 2): cos/sin of the road-wheel angles; ``ng``: road
    normal, ENU."""
    g, inv_m, zw, vfloor, wb, iw_inv = K[K_G], K[K_INV_M], K[K_ZW], K[K_VFLOOR], K[K_WB], K[K_IW_INV]
    pe, pn, pu, phi, theta, psi = x[0], x[1], x[2], x[3], x[4], x[5]
    vx, vy, vz, wx, wy, wz = x[6], x[7], x[8], x[9], x[10], x[11]
    sph, cph, sth, cth, sps, cps = (math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta),
                                    math.sin(psi), math.cos(psi))
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = dcm_gv_elements(sph, cph, sth, cth, sps, cps)  # eq 1
    ng0, ng1, ng2 = ng[0], ng[1], ng[2]
    nx = c00 * ng0 + c01 * ng1 + c02 * ng2
    ny = c10 * ng0 + c11 * ng1 + c12 * ng2
    nz = c20 * ng0 + c21 * ng1 + c22 * ng2
    gx, gy, gz = -g * c02, -g * c12, -g * c22
    hc = pe * ng0 + pn * ng1 + pu * ng2 + nz * zw  # wheel-centre height without the x/y terms
    va = vx + wy * zw
    vb = vy - wx * zw
    Fx = Fy = Fz = Syz = Sxz = Sz = Hx = Hy = Hz = 0.0
    arb = K[K_ARB_F] != 0.0 or K[K_ARB_R] != 0.0
    fyf = fyr = 0.0  # body y of F_a e_l + F_b e_t per axle (the roll centres' J_i)
    for i in range(4):
        xi, yi, c1, c2, c3, sr = C[i, C_X], C[i, C_Y], C[i, C_C1], C[i, C_C2], C[i, C_C3], C[i, C_SR]
        ds, ri, ckap, calp, mug = C[i, C_DS], C[i, C_R], C[i, C_CKAP], C[i, C_CALP], C[i, C_MUG]
        # eq 14: rigid tire, deflection from the pose over the road plane
        hw = hc + nx * xi + ny * yi
        vwx = va - wz * yi
        vwy = vb + wz * xi
        vwz = vz + wx * yi - wy * xi
        vn = nx * vwx + ny * vwy + nz * vwz
        hsp = sr - hw
        fsp = c1 * math.exp(c2 * (hsp - c3)) * hsp
        if arb:  # F_arb,i = K_arb (H_i - H_j) / T^2, j the axle's other corner (i ^ 1)
            o = i ^ 1
            fsp += (K[K_ARB_F] if i < 2 else K[K_ARB_R]) * ((hc + nx * C[o, C_X] + ny * C[o, C_Y]) - hw)
        if fsp + mug <= 0.0:  # eq 14 clamp: lift-off
            fz = 0.0
        else:
            fz = fsp - ds * vn + mug
            if fz < 0.0:
                fz = 0.0
        # eq 15-16: e_l = (c - (c.n) n) / |.|, c = (cos d, sin d, 0); e_t = n x e_l = (n x c) / |.|
        cd, sd = csd[i, 0], csd[i, 1]
        hn = cd * nx + sd * ny
        inv = 1.0 / math.sqrt(1.0 - hn * hn)
        vl = (vwx * cd + vwy * sd - hn * vn) * inv
        den = vl if vl > 0.0 else -vl
        if den < vfloor:
            den = vfloor
        om = x[12 + i]
        kap = (ri * om - vl) / den
        tq = torques[i]
        b = brakes[i]
        if b != 0.0:
            s = om / wb
            tq -= b * (1.0 if s > 1.0 else (-1.0 if s < -1.0 else s))
        fzs[i] = fz
        tfzs[i] = fz
        kaps[i] = kap
        dens[i] = den
        if fz <= 0.0:  # a wheel off the ground carries no force
            xd[12 + i] = tq * iw_inv
            continue
        fa = ckap * kap
        ncz = nx * sd - ny * cd
        vt = (nz * (vwy * cd - vwx * sd) + vwz * ncz) * inv
        fb = -calp * math.atan(vt / den)
        # F_tire = F_a e_l + F_b e_t + F_z n = A c + B (n x c) + (F_z - A (c.n)) n
        A, B = fa * inv, fb * inv
        Cn = fz - A * hn
        ftx = A * cd - B * nz * sd + Cn * nx
        fty = A * sd + B * nz * cd + Cn * ny
        ftz = B * ncz + Cn * nz
        Fx += ftx
        Fy += fty
        Fz += ftz
        if i < 2:
            fyf += fty - fz * ny
        else:
            fyr += fty - fz * ny
        # moment about the CG at the contact point r_w - h_w n: summed as
        # sum r_w x F_tire - n x sum h_w F_tire (all r_w share z_w)
        Syz += yi * ftz
        Sxz += xi * ftz
        Sz += xi * fty - yi * ftx
        Hx += hw * ftx
        Hy += hw * fty
        Hz += hw * ftz
        xd[12 + i] = (tq - ri * fa) * iw_inv
    if K[K_RC_F] != 0.0 or K[K_RC_R] != 0.0:  # J_i along body z at the struts, in the reported load
        jf, jr = fyf * K[K_RC_F], fyr * K[K_RC_R]
        for i in range(4):
            j = -jf if i == 0 else (jf if i == 1 else (jr if i == 2 else -jr))
            Fz += j
            Syz += C[i, C_Y] * j
            Sxz += C[i, C_X] * j
            fzs[i] += j
    ax_ = Fx * inv_m + gx
    ay_ = Fy * inv_m + gy
    az_ = Fz * inv_m + gz
    ux, uy, uz = gx - ax_, gy - ay_, gz - az_
    s_mux, s_muy, zs_mu = K[K_S_MUX], K[K_S_MUY], K[K_ZS_MU]
    Mx = Syz - zw * Fy - (ny * Hz - nz * Hy) + s_muy * uz - zs_mu * uy
    My = zw * Fx - Sxz - (nz * Hx - nx * Hz) + zs_mu * ux - s_mux * uz
    Mz = Sz - (nx * Hy - ny * Hx) + s_mux * uy - s_muy * ux
    tth = sth / cth
    xd[0] = c00 * vx + c10 * vy + c20 * vz
    xd[1] = c01 * vx + c11 * vy + c21 * vz
    xd[2] = c02 * vx + c12 * vy + c22 * vz
    xd[3] = wx - tth * sph * wy - tth * cph * wz
    xd[4] = -cph * wy + sph * wz
    xd[5] = (sph * wy + cph * wz) / cth
    xd[6] = ax_ - (wy * vz - wz * vy)
    xd[7] = ay_ - (wz * vx - wx * vz)
    xd[8] = az_ - (wx * vy - wy * vx)
    xd[9] = K[K_IYZ] * wy * wz + Mx * K[K_INV_IX]
    xd[10] = K[K_IZX] * wz * wx + My * K[K_INV_IY]
    xd[11] = K[K_IXY] * wx * wy + Mz * K[K_INV_IZ]
    nb[0], nb[1], nb[2] = nx, ny, nz


@kernel()
def wheel_spin_jacobian(x, brakes, fz, den, K, C, out):
    """d omega_dot_i / d omega_i (i = 1..4) into ``out`` at ``x`` from the tires' loads
    (``tfzs``) and slip denominators of :func:`reduced_rhs` (module docstring)."""
    iw_inv, wb = K[K_IW_INV], K[K_WB]
    for i in range(4):
        ri, ckap = C[i, C_R], C[i, C_CKAP]
        jd = -(ri * ckap * ri / den[i]) * iw_inv if fz[i] > 0.0 else 0.0
        b = brakes[i]
        if b != 0.0:
            om = x[12 + i]
            a_om = om if om >= 0.0 else -om
            e = 1e-4 * (a_om if a_om > 1.0 else 1.0)
            s0, s1 = om / wb, (om + e) / wb
            s0 = 1.0 if s0 > 1.0 else (-1.0 if s0 < -1.0 else s0)
            s1 = 1.0 if s1 > 1.0 else (-1.0 if s1 < -1.0 else s1)
            jd -= b * (s1 - s0) / e * iw_inv
        out[i] = jd


class ReducedLinearCore:
    """``core = ReducedLinearCore(model)``; ``uc = core.inputs(u)``;
    ``xd, fz, n_b, kappa, den, tire_fz = core.f(x, uc, env)``.

    ``xd``: x_dot (16 values, as ``model.f``); ``fz``: the four normal loads F_z,i (eq 14, the
    roll centres' J_i included, as ``Model.evaluate`` reports them) [N]; ``n_b``: the road normal
    in body axes; ``kappa``: slip ratios; ``den``: the slip denominators max(|v_l,i|, v_floor)
    [m/s]; ``tire_fz``: the tires' loads (eq 14 alone; ``wheel_spin_jacobian`` takes these). ``K`` and ``C``: the constants the kernels take (module
    docstring). Raises ValueError for a model :func:`supports` refuses."""

    def __init__(self, model: Model):
        if not supports(model):
            raise ValueError("ReducedLinearCore needs the reduced model (unsprung_dof=False) with "
                             "linear_tire and no per-call effect hooks")
        self.model = model
        veh = model.vehicle
        geo, p = veh.geometry, veh.params
        self._steer = (geo.steer_ratio, geo.wheelbase_m, geo.track_half_front_m, veh.chassis.ackermann_fraction)
        corners = []
        for i in range(4):
            ax = veh.axle(i)
            x_i, y_i = model.corner_xy[i]
            corners.append((x_i, y_i, ax.spring_c1_npm, ax.spring_c2_per_m, ax.spring_c3_m,
                            ax.static_compression_m + veh.tire.rolling_radius_m, ax.damper_nspm,
                            model.rolling_radius_m[i], model.c_kappa[i], model.c_alpha[i],
                            model.m_u[i] * GRAVITY_MPS2))
        self.C = np.array(corners, dtype=float)
        Ix, Iy, Iz = p.inertia_x_kgm2, p.inertia_y_kgm2, p.inertia_z_kgm2
        zw = model.wheel_centre_z_m
        s_mu = sum(model.m_u)
        ch = veh.chassis
        kf, kr = model.anti_roll_stiffness_nmprad  # the file's bars (plus ``anti_roll_stiffness`` effects)
        tf, tr = 2.0 * geo.track_half_front_m, 2.0 * geo.track_half_rear_m
        self.K = np.array([1.0 / model.m_tot, GRAVITY_MPS2, (Iy - Iz) / Ix, (Iz - Ix) / Iy, (Ix - Iy) / Iz,
                           1.0 / Ix, 1.0 / Iy, 1.0 / Iz, 1.0 / veh.tire.wheel_inertia_kgm2, zw,
                           model.slip_speed_floor_mps, BRAKE_HOLD_SPEED_RADPS,
                           sum(model.m_u[i] * model.corner_xy[i][0] for i in range(4)),
                           sum(model.m_u[i] * model.corner_xy[i][1] for i in range(4)), zw * s_mu,
                           kf / (tf * tf), kr / (tr * tr), ch.roll_centre_height_front_m / tf,
                           ch.roll_centre_height_rear_m / tr])
        self.iw_inv = float(self.K[K_IW_INV])

    def inputs(self, u: Inputs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The per-input constants: (cos/sin of the road-wheel angles (4, 2), drive torques (4,),
        brake torques (4,))."""
        ratio, wheelbase, t_f, e_a = self._steer
        d1, d2 = steer_angles(u.steer_wheel_angle_rad / ratio, wheelbase, t_f, e_a)
        csd = np.array(((math.cos(d1), math.sin(d1)), (math.cos(d2), math.sin(d2)), (1.0, 0.0), (1.0, 0.0)))
        return csd, np.array(u.wheel_torque_nm, dtype=float), np.array(u.brake_torque_nm, dtype=float)

    def f(self, x, uc, env) -> tuple[list, list, tuple, list, list, list]:
        """(x_dot, F_z,i, n_b, kappa_i, den_i, tire F_z,i) at ``x`` (16 values) under ``uc``
        (``inputs``)."""
        xd, fz, nb, kap, den, tfz = (np.empty(16), np.empty(4), np.empty(3), np.empty(4), np.empty(4),
                                     np.empty(4))
        reduced_rhs(np.asarray(x, dtype=float), uc[0], uc[1], uc[2], np.asarray(env.normal_g), self.K, self.C,
                    xd, fz, nb, kap, den, tfz)
        return xd.tolist(), fz.tolist(), tuple(nb.tolist()), kap.tolist(), den.tolist(), tfz.tolist()

    def wheel_spin_jacobian(self, x, uc, fz, den) -> list[float]:
        """d omega_dot_i / d omega_i (i = 1..4) at ``x`` from the tires' loads and the slip
        denominators of ``f(x, uc, env)`` (module docstring)."""
        out = np.empty(4)
        wheel_spin_jacobian(np.asarray(x, dtype=float), uc[2], np.asarray(fz, dtype=float),
                            np.asarray(den, dtype=float), self.K, self.C, out)
        return out.tolist()


def warm() -> None:
    """Compile (or load from the cache) the kernels of this module with representative
    arguments (``python -m vdps_hil.jit --warm``)."""
    x, v4, K, C = np.zeros(16), np.zeros(4), np.ones(N_K), np.ones((4, N_C))
    x[4] = 0.0
    reduced_rhs(x, np.ones((4, 2)) * 0.5, v4, v4, np.array([0.0, 0.0, 1.0]), K, C, np.empty(16), np.empty(4),
                np.empty(3), np.empty(4), np.empty(4), np.empty(4))
    wheel_spin_jacobian(x, v4, v4 + 1.0, v4 + 1.0, K, C, np.empty(4))


__all__ = ["N_C", "N_K", "ReducedLinearCore", "STATIC_HOOKS", "reduced_rhs", "supports", "wheel_spin_jacobian"]
