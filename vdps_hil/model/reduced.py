"""A faster evaluation of the physics core's reduced model (paper eq 13-16) for the paper's
effect set: the same equations as :meth:`vdps_hil.model.core.Model.f` with
``unsprung_dof=False`` and ``linear_tire`` (plus static rolling-radius factors), specialised
once per model and once per input value.

This is a **hand-specialised numeric kernel**, kept beside its reference on purpose: it does not
call the stages of :mod:`vdps_hil.model.stages` (which ``Model.f`` composes) but writes the
reduced model's stages out in one loop, rearranged (below) and therefore equal to ``Model.f``
to rounding, not bit for bit. Its evaluation (``ReducedLinearCore.f``, ~100 lines) is one
function on purpose: splitting it into calls would cost the predictor's hot loop. It is tested
equal to ``Model.f`` in ``tests/test_reduced.py``.

Why: the predictor integrates this model 500 steps (1000 f-evaluations) per 5 s prediction in
pure Python; the generic core resolves effect hooks, builds per-corner tuples, calls a tire
function per corner and fills a diagnostics dict on every call. Here everything that depends
only on the vehicle or on the (held) inputs is computed once:

* per model (:class:`ReducedLinearCore`): the corner constants
  (x_i, y_i, r_i, C_kappa,i, C_alpha,i, spring C1 C2 C3, static compression, damper, m_u,i g) and
  the unsprung masses' first moments ``S_mu = sum m_u,i``, ``S_mux = sum m_u,i x_i``,
  ``S_muy = sum m_u,i y_i``;
* per input (:meth:`ReducedLinearCore.inputs`): the Ackermann wheel angles and their cos/sin,
  the drive and brake torques.

The equations are those of :mod:`vdps_hil.model.core` (read its docstring for the symbols);
the only rearrangement is the unsprung masses' weight and inertia moment, summed over the
corners with the first moments above (all wheel centres share z_w)::

    M_u = sum_i r_w,i x m_u,i (g_b - a) = (S_muy (g_z - a_z) - z_w S_mu (g_y - a_y),
                                           z_w S_mu (g_x - a_x) - S_mux (g_z - a_z),
                                           S_mux (g_y - a_y) - S_muy (g_x - a_x))

so results equal the generic core's to rounding (checked in ``tests/test_reduced.py`` against
``Model.f`` on random states and inputs: relative 1e-12).

:meth:`ReducedLinearCore.wheel_spin_jacobian` gives the diagonal d omega_dot_i / d omega_i
the predictor's ROS2 integrator needs, in closed form (eq 13 last line, eq 15)::

    d omega_dot_i / d omega_i = -(r_i C_kappa,i r_i / den_i) / I_w     (F_z,i > 0; else 0)
                                - B_i d sat(omega_i / 2 rad/s) / d omega_i / I_w

den_i = max(|v_l,i|, v_floor); the brake term is taken as the same forward difference the
generic path uses (step ``1e-4 max(1, |omega_i|)``), so the two agree also at the kink.
"""

from __future__ import annotations

import math

from vdps_hil.units import GRAVITY_MPS2

from .core import BRAKE_HOLD_SPEED_RADPS, Inputs, Model
from .stages import ackermann_angles
from .effects import LinearTire
from .frames import dcm_gv_elements

STATIC_HOOKS = frozenset({"rolling_radius_factor"})
"""Effect hooks the core resolves at construction (nothing to do per call)."""


def supports(model: Model) -> bool:
    """True when ``model`` is the reduced model with the linear tire and no per-call effect
    hooks (the paper's set; a static ``rolling_radius_factor`` is allowed) on a vehicle without
    anti-roll bars or roll centres (``model.chassis``; its Ackermann fraction is supported)."""
    if model.unsprung_dof or type(model.effects.tire) is not LinearTire:
        return False
    ch = model.vehicle.chassis
    if ch.has_anti_roll_bars or ch.has_roll_centres:  # the generic core has them (model.chassis)
        return False
    return all(e is model.effects.tire or set(e.HOOKS) <= STATIC_HOOKS for e in model.effects.dynamics)


class ReducedLinearCore:
    """``core = ReducedLinearCore(model)``; ``uc = core.inputs(u)``;
    ``xd, fz, n_b, kappa, den = core.f(x, uc, env)``.

    ``xd``: x_dot (16 values, as ``model.f``); ``fz``: the four normal loads F_z,i (eq 14) [N];
    ``n_b``: the road normal in body axes; ``kappa``: slip ratios; ``den``: the slip denominators
    max(|v_l,i|, v_floor) [m/s]. Raises ValueError for a model :func:`supports` refuses."""

    def __init__(self, model: Model):
        if not supports(model):
            raise ValueError("ReducedLinearCore needs the reduced model (unsprung_dof=False) with "
                             "linear_tire and no per-call effect hooks")
        self.model = model
        veh = model.vehicle
        geo = veh.geometry
        self._steer = (geo.steer_ratio, geo.wheelbase_m, geo.track_half_front_m, veh.chassis.ackermann_fraction)
        self.iw_inv = 1.0 / veh.tire.wheel_inertia_kgm2
        corners = []
        for i in range(4):
            ax = veh.axle(i)
            x_i, y_i = model.corner_xy[i]
            corners.append((i, x_i, y_i, ax.spring_c1_npm, ax.spring_c2_per_m, ax.spring_c3_m,
                            ax.static_compression_m + veh.tire.rolling_radius_m, ax.damper_nspm,
                            model.rolling_radius_m[i],
                            model.c_kappa[i], model.c_alpha[i], model.m_u[i] * GRAVITY_MPS2))
        self.corners = tuple(corners)
        self.f = self._build()

    def inputs(self, u: Inputs) -> tuple:
        """The per-input constants: ((cos delta_i, sin delta_i) x 4, drive torques, brakes)."""
        ratio, wheelbase, t_f, e_a = self._steer
        d1, d2 = ackermann_angles(u.steer_wheel_angle_rad / ratio, wheelbase, t_f, e_a)
        return (((math.cos(d1), math.sin(d1)), (math.cos(d2), math.sin(d2)), (1.0, 0.0), (1.0, 0.0)),
                u.wheel_torque_nm, u.brake_torque_nm)

    def wheel_spin_jacobian(self, x, uc, fz, den) -> list[float]:
        """d omega_dot_i / d omega_i (i = 1..4) at ``x`` from the loads and slip denominators of
        ``f(x, uc, env)`` (module docstring)."""
        iw_inv = self.iw_inv
        brakes = uc[2]
        wb = BRAKE_HOLD_SPEED_RADPS
        out = []
        for (i, _x, _y, _c1, _c2, _c3, _sr, _ds, ri, ckap, _ca, _mg) in self.corners:
            jd = -(ri * ckap * ri / den[i]) * iw_inv if fz[i] > 0.0 else 0.0
            b = brakes[i]
            if b != 0.0:
                om = x[12 + i]
                e = 1e-4 * max(1.0, abs(om))
                s0, s1 = om / wb, (om + e) / wb
                s0 = 1.0 if s0 > 1.0 else (-1.0 if s0 < -1.0 else s0)
                s1 = 1.0 if s1 > 1.0 else (-1.0 if s1 < -1.0 else s1)
                jd -= b * (s1 - s0) / e * iw_inv
            out.append(jd)
        return out

    def _build(self):
        """The evaluation ``f(x, uc, env)``: a hand-specialised numeric kernel of the reduced
        model's stages written out in one loop (module docstring), tested equal to ``Model.f``."""
        m = self.model
        veh = m.vehicle
        p = veh.params
        g = GRAVITY_MPS2
        inv_m = 1.0 / m.m_tot
        Ix, Iy, Iz = p.inertia_x_kgm2, p.inertia_y_kgm2, p.inertia_z_kgm2
        Iyz, Izx, Ixy = (Iy - Iz) / Ix, (Iz - Ix) / Iy, (Ix - Iy) / Iz
        inv_Ix, inv_Iy, inv_Iz = 1.0 / Ix, 1.0 / Iy, 1.0 / Iz
        iw_inv = self.iw_inv
        zw = m.wheel_centre_z_m
        r_load = veh.tire.rolling_radius_m
        vfloor = m.slip_speed_floor_mps
        wb = BRAKE_HOLD_SPEED_RADPS
        s_mu = sum(m.m_u)
        s_mux = sum(m.m_u[i] * m.corner_xy[i][0] for i in range(4))
        s_muy = sum(m.m_u[i] * m.corner_xy[i][1] for i in range(4))
        zs_mu = zw * s_mu
        corners = self.corners
        sqrt, sin, cos, atan, exp = math.sqrt, math.sin, math.cos, math.atan, math.exp

        def f(x, uc, env):
            """Hand-specialised kernel (see ``_build``): x_dot, F_z,i, n_b, kappa_i, den_i."""
            (pe, pn, pu, phi, theta, psi, vx, vy, vz, wx, wy, wz) = x[0:12]
            sph, cph, sth, cth, sps, cps = sin(phi), cos(phi), sin(theta), cos(theta), sin(psi), cos(psi)
            c00, c01, c02, c10, c11, c12, c20, c21, c22 = dcm_gv_elements(sph, cph, sth, cth, sps, cps)  # eq 1
            ng0, ng1, ng2 = env.normal_g
            nx = c00 * ng0 + c01 * ng1 + c02 * ng2
            ny = c10 * ng0 + c11 * ng1 + c12 * ng2
            nz = c20 * ng0 + c21 * ng1 + c22 * ng2
            gx, gy, gz = -g * c02, -g * c12, -g * c22
            hc = pe * ng0 + pn * ng1 + pu * ng2 + nz * zw  # wheel-centre height without the x/y terms
            va = vx + wy * zw
            vb = vy - wx * zw
            csd, torques, brakes = uc
            Fx = Fy = Fz = Syz = Sxz = Sz = Hx = Hy = Hz = 0.0
            wd = [0.0, 0.0, 0.0, 0.0]
            fzs = [0.0, 0.0, 0.0, 0.0]
            kaps = [0.0, 0.0, 0.0, 0.0]
            dens = [0.0, 0.0, 0.0, 0.0]
            for (i, xi, yi, c1, c2, c3, sr, ds, ri, ckap, calp, mug) in corners:
                # eq 14: rigid tire, deflection from the pose over the road plane
                hw = hc + nx * xi + ny * yi
                vwx = va - wz * yi
                vwy = vb + wz * xi
                vwz = vz + wx * yi - wy * xi
                vn = nx * vwx + ny * vwy + nz * vwz
                hsp = sr - hw
                fsp = c1 * exp(c2 * (hsp - c3)) * hsp
                if fsp + mug <= 0.0:  # eq 14 clamp: lift-off
                    fz = 0.0
                else:
                    fz = fsp - ds * vn + mug
                    if fz < 0.0:
                        fz = 0.0
                # eq 15-16: e_l = (c - (c.n) n) / |.|, c = (cos d, sin d, 0); e_t = n x e_l = (n x c) / |.|
                cd, sd = csd[i]
                hn = cd * nx + sd * ny
                inv = 1.0 / sqrt(1.0 - hn * hn)
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
                kaps[i] = kap
                dens[i] = den
                if fz <= 0.0:  # a wheel off the ground carries no force
                    wd[i] = tq * iw_inv
                    continue
                fa = ckap * kap
                ncz = nx * sd - ny * cd
                vt = (nz * (vwy * cd - vwx * sd) + vwz * ncz) * inv
                fb = -calp * atan(vt / den)
                # F_tire = F_a e_l + F_b e_t + F_z n = A c + B (n x c) + (F_z - A (c.n)) n
                A, B = fa * inv, fb * inv
                C = fz - A * hn
                ftx = A * cd - B * nz * sd + C * nx
                fty = A * sd + B * nz * cd + C * ny
                ftz = B * ncz + C * nz
                Fx += ftx
                Fy += fty
                Fz += ftz
                # moment about the CG at the contact point r_w - h_w n: summed as
                # sum r_w x F_tire - n x sum h_w F_tire (all r_w share z_w)
                Syz += yi * ftz
                Sxz += xi * ftz
                Sz += xi * fty - yi * ftx
                Hx += hw * ftx
                Hy += hw * fty
                Hz += hw * ftz
                wd[i] = (tq - ri * fa) * iw_inv
            ax_ = Fx * inv_m + gx
            ay_ = Fy * inv_m + gy
            az_ = Fz * inv_m + gz
            ux, uy, uz = gx - ax_, gy - ay_, gz - az_
            Mx = Syz - zw * Fy - (ny * Hz - nz * Hy) + s_muy * uz - zs_mu * uy
            My = zw * Fx - Sxz - (nz * Hx - nx * Hz) + zs_mu * ux - s_mux * uz
            Mz = Sz - (nx * Hy - ny * Hx) + s_mux * uy - s_muy * ux
            tth = sth / cth
            return ([c00 * vx + c10 * vy + c20 * vz, c01 * vx + c11 * vy + c21 * vz,
                     c02 * vx + c12 * vy + c22 * vz,
                     wx - tth * sph * wy - tth * cph * wz, -cph * wy + sph * wz, (sph * wy + cph * wz) / cth,
                     ax_ - (wy * vz - wz * vy), ay_ - (wz * vx - wx * vz), az_ - (wx * vy - wy * vx),
                     Iyz * wy * wz + Mx * inv_Ix, Izx * wz * wx + My * inv_Iy, Ixy * wx * wy + Mz * inv_Iz,
                     wd[0], wd[1], wd[2], wd[3]],
                    fzs, (nx, ny, nz), kaps, dens)

        return f


__all__ = ["ReducedLinearCore", "STATIC_HOOKS", "supports"]
