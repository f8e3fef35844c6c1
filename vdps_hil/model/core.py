"""The physics core: one vehicle model f(x, u, p, env) -> x_dot shared by the truth simulator and
the predictor (paper eq 13-17), with composable effects.

Bodies and degrees of freedom
-----------------------------
* Sprung body (mass m_s = m_tot - sum m_u, inertias I_x, I_y, I_z about its CG, principal axes):
  6 DOF. The vehicle frame {v} is fixed at the sprung-mass CG (``conventions``).
* Four wheels: spin omega_i (eq 13, last line).
* Four unsprung masses m_u,i. Two variants, chosen by ``unsprung_dof``:

  - ``unsprung_dof=True`` (truth simulator): each unsprung mass slides along the body z axis at
    its corner and has its own vertical DOF (coordinate H_i = suspension deflection from design
    ride height, compression positive, = wheel-centre displacement up the body z axis). The tire
    is a radial spring k_t between wheel centre and road: F_z,i = k_t (r_free,i - h_w,i) while
    positive, **lift-off = tire deflection <= 0, normal load 0**. The suspension force
    F_s,i = K_s H_s + D_s H_dot (eq 14 spring law, H_s = static_compression + H_i) acts between
    body and unsprung mass. Horizontally the unsprung masses translate with the body, so the
    body x/y balance uses m_tot and the body z balance m_s.
  - ``unsprung_dof=False`` (the paper's reduced model, eq 13-16; used by the predictor): tires
    are rigid, the unsprung masses move with the body, H_i follows from the body's pose over
    the road plane, and the normal load is eq 14 directly:
    F_z,i = K_s H_s + D_s H_dot + m_u g, with eq 14's clamp: when K_s H_s <= -m_u g the wheel
    has lifted and F_z,i = 0 (and F_z,i >= 0 always). Translation uses m_tot on all axes
    (eq 13).

State (1-D, named slices in :class:`StateLayout`)
-------------------------------------------------
=================  ====  ======================================================================
slice              size  meaning
=================  ====  ======================================================================
``pos_g``          3     sprung CG position, ENU [m]; the road plane passes through the origin
``euler_g``        3     phi_g, theta_g, psi_g (eq 1: roll right-down +, pitch nose-up +, yaw CCW
                         from East) [rad]
``vel_b``          3     CG velocity in body axes (u, v, w) [m/s]
``rate_b``         3     body rates (p, q, r) = (omega_x, omega_y, omega_z) [rad/s]
``wheel_spin``     4     omega_1..4 (FL FR RR RL), positive rolling forward [rad/s]
``susp_defl``      4     H_1..4 [m] (only with ``unsprung_dof``)
``susp_defl_rate`` 4     H_dot_1..4 [m/s] (only with ``unsprung_dof``)
=================  ====  ======================================================================

Entry points: ``Model(vehicle, effects, unsprung_dof=...)`` builds the parameters once;
``model.f(x, u, env)`` (or ``derivatives(x, u, model, env)``) is the pure derivative function,
composed of the stages in :mod:`vdps_hil.model.stages` (one function per stage below);
``model.evaluate(x, u, env)`` adds named diagnostics (tire forces, slips, loads, ...);
``model.design_state`` / ``model.trim_state`` / ``model.state_from`` build states.

Equations (body axes; a = CG acceleration, g_b = C_g^v [0, 0, -g], eq 13 written in {v})::

    dp_g/dt      = (C_g^v)^T v_b
    d(euler)/dt  = C_omega^-1 omega                 (frames.c_omega_inv, consistent with eq 1)
    m a          = sum F_tire + m g_b + F_eff       (m = m_tot; with unsprung_dof: m_s on z, and
                                                     the body receives F_s,i instead of the
                                                     tires' body-z force)
    dv_b/dt      = a - omega x v_b
    I_x dp/dt    = (I_y - I_z) q r + M_x, ...       (eq 13, principal axes)
    I_w domega_i/dt = T_i - r_i F_a,i + T_eff,i     (eq 13)
    m_u (a_z + (omega_dot x r_w)_z + (omega x (omega x r_w))_z + H_ddot) = F_tz' - F_s + m_u g_z

Moments about the sprung CG: each tire force acts at its contact point r_c = r_w - h_w n_b
(r_w wheel centre, h_w its height above the road along the road normal n); the unsprung masses'
weight and translational inertia act at their wheel centres. The wheels' spin angular momentum
is not coupled to the body (gyroscopic and spin-reaction moments neglected).

Tire kinematics (per corner; eq 15-16 axes)::

    e_l = unit((cos d, sin d, 0) - ((cos d, sin d, 0).n) n),  e_t = n x e_l    (road plane)
    v_w = v_b + omega x r_w (+ H_dot e_z)       wheel-centre velocity
    v_l = v_w . e_l,  v_t = v_w . e_t
    kappa = (r_i omega_i - v_l) / max(|v_l|, v_floor)        slip ratio
    alpha = -atan(v_t / max(|v_l|, v_floor))                  slip angle
    F_tire = F_a e_l + F_b e_t + F_z n                        (eq 16 when n = e_z)

**Low-speed treatment**: slip denominators are floored at ``v_floor`` (default 5 m/s), so slip
stays finite at standstill; below v_floor the tire acts as a damper on the slip velocity. The
wheel-spin time constant is tau = I_w max(|v|, v_floor) / (r^2 C_kappa): 3.9 ms at 25 m/s and
0.78 ms at the floor for the sedan (C_kappa = 80 kN); explicit RK4 is stable for
dt < 2.78 tau (``Model.max_stable_step_s``). Brake torques B_i >= 0 oppose rotation as
-B_i sat(omega_i / 2 rad/s) (a regularised Coulomb law: the brake holds a stopped wheel).

Steering: the mean front road-wheel angle delta_m = delta_sw / steer_ratio is the bicycle-model
angle; the wheel angles follow Ackermann: tan delta_1,2 = L tan delta_m / (L -+ t_f tan delta_m)
(the mean of delta_1,2 equals delta_m to third order), blended with parallel steer by the
vehicle's Ackermann fraction. Rear wheels do not steer.

Chassis parts (``model.chassis``, a vehicle file's optional ``[chassis]``; absent: the paper's
model, bit for bit): anti-roll bars add F_arb,i = K_arb (H_i - H_j) / T^2 to the strut forces
(plus the auxiliary roll stiffness of ``anti_roll_stiffness`` effects, e.g. ``roll_stiffness``);
roll centres add the linkage's vertical force pair J_i = -+ F_y,axle h_rc / T.

Road: a plane through the global origin with bank phi_r and grade theta_r (eq 2, psi_r = 0);
gravity enters through g_b, which equals eq 13's [G_x, G_y, G_z] when the body lies in the road
plane. Road normal in ENU: n_g = (-cos phi_r sin theta_r, -sin phi_r, cos phi_r cos theta_r).

Symbols and units: m_tot, m_s, m_u [kg]; I [kg m^2]; r_i rolling radius [m]; k_t tire radial
stiffness [N/m]; C_kappa [N], C_alpha [N/rad] per tire (C_alpha,i = C_alpha,axle / 2, eq 17);
forces [N], moments [N m], angles [rad].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

from vdps_hil import jit
from vdps_hil.units import GRAVITY_MPS2

from . import core_kernel
from .effects import EffectSet, LinearTire
from .effects.base import Effect
from .params import Vehicle
from .stages import CoreConstants, derivative_function

SLIP_SPEED_FLOOR_MPS = 5.0
"""Default v_floor of the slip denominators [m/s]."""
BRAKE_HOLD_SPEED_RADPS = 2.0
"""Wheel speed below which a brake torque is scaled down linearly (regularised Coulomb) [rad/s]."""
RK4_STABILITY_LIMIT = 2.78
"""|lambda dt| limit of explicit RK4 on the negative real axis."""


class StateLayout:
    """Named slices of the 1-D state vector (see the module docstring)."""

    __slots__ = ("unsprung_dof", "size", "slices", "names")

    def __init__(self, unsprung_dof: bool):
        self.unsprung_dof = bool(unsprung_dof)
        parts = [("pos_g", 3), ("euler_g", 3), ("vel_b", 3), ("rate_b", 3), ("wheel_spin", 4)]
        if self.unsprung_dof:
            parts += [("susp_defl", 4), ("susp_defl_rate", 4)]
        self.slices: dict[str, slice] = {}
        i = 0
        for name, n in parts:
            self.slices[name] = slice(i, i + n)
            i += n
        self.size = i
        elem = {"pos_g": ("pos_e_m", "pos_n_m", "pos_u_m"),
                "euler_g": ("roll_g_rad", "pitch_g_rad", "yaw_g_rad"),
                "vel_b": ("vel_b_mps_x", "vel_b_mps_y", "vel_b_mps_z"),
                "rate_b": ("rate_b_radps_x", "rate_b_radps_y", "rate_b_radps_z"),
                "wheel_spin": tuple(f"wheel_speed_radps_{i}" for i in range(1, 5)),
                "susp_defl": tuple(f"susp_deflection_m_{i}" for i in range(1, 5)),
                "susp_defl_rate": tuple(f"susp_deflection_rate_mps_{i}" for i in range(1, 5))}
        self.names: tuple[str, ...] = tuple(n for name, _ in parts for n in elem[name])

    def __getattr__(self, name):  # layout.pos_g -> slice
        try:
            return object.__getattribute__(self, "slices")[name]
        except KeyError:
            raise AttributeError(name) from None

    def __repr__(self):
        return f"StateLayout(unsprung_dof={self.unsprung_dof}, size={self.size})"


@dataclass(frozen=True, slots=True)
class Inputs:
    """Driver/ECU inputs, held over an integration step.

    steer_wheel_angle_rad: positive to the left (CCW). wheel_torque_nm: drive torque per wheel
    (FL FR RR RL), positive driving forward, applied as given (negative = retarding, e.g. engine
    braking; it can turn a wheel backwards). brake_torque_nm: brake torque magnitudes >= 0 that
    oppose the wheel's rotation and hold it at standstill."""

    steer_wheel_angle_rad: float = 0.0
    wheel_torque_nm: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    brake_torque_nm: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        for nm in ("wheel_torque_nm", "brake_torque_nm"):
            v = getattr(self, nm)
            if len(v) != 4:
                raise ValueError(f"Inputs.{nm} needs 4 values (FL FR RR RL), got {len(v)}")
            object.__setattr__(self, nm, tuple(float(e) for e in v))
        if any(b < 0.0 for b in self.brake_torque_nm):
            raise ValueError("Inputs.brake_torque_nm are magnitudes and must be >= 0")
        object.__setattr__(self, "steer_wheel_angle_rad", float(self.steer_wheel_angle_rad))


@dataclass(frozen=True)
class Env:
    """The environment: a road plane (bank phi_r, grade theta_r, constant) and the wind.

    bank_rad > 0: right edge low (ISO). grade_rad < 0: downhill along the road's x axis (East at
    psi = 0). wind_enu_mps: ambient wind velocity over ground (the ``crosswind`` effect adds its
    own)."""

    bank_rad: float = 0.0
    grade_rad: float = 0.0
    wind_enu_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal_g: tuple[float, float, float] = field(init=False, repr=False)

    def __post_init__(self):
        pr, tr = self.bank_rad, self.grade_rad
        object.__setattr__(self, "normal_g", (-math.cos(pr) * math.sin(tr), -math.sin(pr),
                                              math.cos(pr) * math.cos(tr)))
        object.__setattr__(self, "wind_enu_mps", tuple(float(w) for w in self.wind_enu_mps))


_AXIS_KEYS = tuple((f"accel_b_mps2_{a}", f"specific_force_b_mps2_{a}", f"angular_accel_b_radps2_{a}",
                    f"force_b_n_{a}", f"moment_b_nm_{a}") for a in "xyz")
_AIR_KEYS = tuple(f"air_vel_b_mps_{a}" for a in "xyz")
_CORNER_KEYS = tuple(tuple(f"{stem}_{i}" for stem in (
    "tire_force_long_n", "tire_force_lat_n", "normal_load_n", "slip_ratio", "slip_angle_rad", "susp_deflection_m",
    "susp_deflection_rate_mps", "susp_force_n", "wheel_torque_nm", "effect_wheel_torque_nm", "road_wheel_angle_rad",
    "rolling_radius_m", "wheel_centre_height_m", "wheel_accel_radps2")) for i in range(1, 5))


def _named(xd, acc, g_b, force, moment, h_cg, air, recs) -> dict:
    """The named diagnostics of ``Model.evaluate`` (body, then per corner i = 1..4)."""
    d: dict[str, float] = {}
    for k, (ka, ks, kw, kf, km) in enumerate(_AXIS_KEYS):
        d[ka] = acc[k]
        d[ks] = acc[k] - g_b[k]
        d[kw] = xd[9 + k]
        d[kf] = force[k]
        d[km] = moment[k]
    d["height_cg_above_road_m"] = h_cg
    for k, ka in enumerate(_AIR_KEYS):
        d[ka] = air[k]
    for i, rec in enumerate(recs):
        (fa, fb, fz, kap, alp, H, Hd, tq, teff, delta, ri, hw, fs, ftx, fty, ftz) = rec
        d.update(zip(_CORNER_KEYS[i], (fa, fb, fz, kap, alp, H, Hd, fs, tq, teff, delta, ri, hw, xd[12 + i])))
    return d


def derivatives(x: Sequence[float], u: "Inputs", p: "Model", env: "Env") -> list[float]:
    """f(x, u, p, env) -> x_dot: the core as a pure function of state, inputs, parameters (a
    :class:`Model`: vehicle + effects + variant) and environment. Same as ``p.f(x, u, env)``."""
    return p.f(x, u, env)


class Model:
    """A vehicle model: vehicle parameters + effects + variant, with ``f(x, u, env) -> x_dot``.

    ``Model(vehicle, effects, unsprung_dof=True)`` is the truth simulator's model;
    ``Model(model_vehicle, EffectSet([LinearTire()]), unsprung_dof=False)`` is the paper's eq
    13-16. When ``effects`` has no tire model, ``linear_tire`` is used. Build once, call ``f``
    many times: ``f`` composes the stages of :mod:`vdps_hil.model.stages` over the model's
    constants (:class:`~vdps_hil.model.stages.CoreConstants`), on plain floats (no numpy inside).

    ``f`` is the compiled core (:mod:`vdps_hil.model.core_kernel`, bit for bit the stages) when
    every effect has a compiled form, else the stages in Python; ``f_python`` is always the
    stages; ``compiled_status`` says which and why ("compiled", or the reason for Python);
    ``kernel_arrays`` the packed constants (K, C, E) of the compiled core, or None.

    Attributes: ``layout`` (StateLayout), ``vehicle``, ``effects`` (EffectSet incl. the tire),
    ``static_load_n`` (F_z0 per corner on a level road [N]), ``rolling_radius_m`` (per corner),
    ``max_stable_step_s``.
    """

    def __init__(self, vehicle: Vehicle, effects: EffectSet | Sequence[Effect] = (), *,
                 unsprung_dof: bool = True, slip_speed_floor_mps: float = SLIP_SPEED_FLOOR_MPS):
        effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
        if effects.tire is None:
            effects = EffectSet((LinearTire(), *effects))
        if slip_speed_floor_mps <= 0.0:
            raise ValueError("slip_speed_floor_mps must be positive")
        self.vehicle = vehicle
        self.effects = effects
        self.unsprung_dof = bool(unsprung_dof)
        self.layout = StateLayout(unsprung_dof)
        self.slip_speed_floor_mps = float(slip_speed_floor_mps)
        geo, p = vehicle.geometry, vehicle.params
        g = GRAVITY_MPS2
        L = geo.wheelbase_m
        self.m_tot = p.mass_kg
        self.m_s = vehicle.sprung_mass_kg
        self.corner_xy = geo.corner_xy_m()
        m_u = tuple(vehicle.axle(i).unsprung_mass_kg for i in range(4))
        self.m_u = m_u
        sprung_share = (geo.l_r_m / L / 2.0, geo.l_r_m / L / 2.0, geo.l_f_m / L / 2.0, geo.l_f_m / L / 2.0)
        self.static_load_n = tuple(self.m_s * g * sprung_share[i] + m_u[i] * g for i in range(4))
        self.static_spring_n = tuple(self.m_s * g * sprung_share[i] for i in range(4))
        dyn = effects.dynamics
        rfac = [1.0] * 4
        for e in dyn:
            if "rolling_radius_factor" in e.HOOKS:
                for i in range(4):
                    rfac[i] *= e.rolling_radius_factor(i)
        r0 = vehicle.tire.rolling_radius_m
        self.rolling_radius_m = tuple(r0 * f for f in rfac)
        kt = vehicle.tire.vertical_stiffness_npm
        self.tire_free_radius_m = tuple(r0 + self.static_load_n[i] / kt for i in range(4))
        self.wheel_centre_z_m = -(geo.h_cg_m - r0)  # body z of the wheel centres at design ride height
        ck = p.tracking_stiffness_n
        ca = (p.cornering_stiffness_front_nprad / 2.0,) * 2 + (p.cornering_stiffness_rear_nprad / 2.0,) * 2
        self.c_kappa = tuple(ck)
        self.c_alpha = ca
        tau_min = vehicle.tire.wheel_inertia_kgm2 * self.slip_speed_floor_mps / (min(self.rolling_radius_m) ** 2 * max(ck))
        self.wheel_spin_tau_floor_s = tau_min
        self.max_stable_step_s = RK4_STABILITY_LIMIT * tau_min
        wind_extra = [0.0, 0.0, 0.0]
        for e in dyn:
            if hasattr(e, "wind_enu_mps"):
                w = e.wind_enu_mps()
                wind_extra = [wind_extra[k] + w[k] for k in range(3)]
        self.effect_wind_enu_mps = tuple(wind_extra)
        self.f_python, k = self._build()
        self.kernel_arrays, status = core_kernel.pack_model(k, dyn)
        if self.kernel_arrays is not None and not jit.ENABLED:
            status = "python (VDPS_JIT=0)"
        self.compiled_status = status
        self.f = (core_kernel.compiled_function(self.kernel_arrays, self.layout.size)
                  if self.kernel_arrays is not None and jit.ENABLED else self.f_python)

    # ------------------------------------------------------------------ the core
    def _build(self) -> tuple[Callable, CoreConstants]:
        """(f, constants): f from the model's constants and the stages of
        :mod:`vdps_hil.model.stages`."""
        veh = self.vehicle
        geo, p = veh.geometry, veh.params
        g = GRAVITY_MPS2
        Ix, Iy, Iz = p.inertia_x_kgm2, p.inertia_y_kgm2, p.inertia_z_kgm2
        corners = []
        for i in range(4):
            ax = veh.axle(i)
            x_i, y_i = self.corner_xy[i]
            corners.append((i, x_i, y_i, self.m_u[i], ax.spring_c1_npm, ax.spring_c2_per_m, ax.spring_c3_m,
                            ax.static_compression_m, ax.damper_nspm, self.rolling_radius_m[i],
                            self.tire_free_radius_m[i], self.c_kappa[i], self.c_alpha[i],
                            self.static_load_n[i], self.m_u[i] * g))
        dyn = self.effects.dynamics
        k = CoreConstants(
            unsprung_dof=self.unsprung_dof, g=g, inv_m_tot=1.0 / self.m_tot, inv_m_s=1.0 / self.m_s,
            inertia=((Iy - Iz) / Ix, (Iz - Ix) / Iy, (Ix - Iy) / Iz, 1.0 / Ix, 1.0 / Iy, 1.0 / Iz),
            iw_inv=1.0 / veh.tire.wheel_inertia_kgm2, tire_radial_stiffness=veh.tire.vertical_stiffness_npm,
            wheelbase_m=geo.wheelbase_m, track_half_front_m=geo.track_half_front_m, steer_ratio=geo.steer_ratio,
            zw0=self.wheel_centre_z_m, r_load=veh.tire.rolling_radius_m, v_floor=self.slip_speed_floor_mps,
            brake_hold_radps=BRAKE_HOLD_SPEED_RADPS, corners=tuple(corners),
            corner_masses=tuple(c[0:4] for c in corners), tire_fn=self.effects.tire.tire_forces,
            stiffness_fns=tuple(e.cornering_stiffness_factor for e in dyn if "cornering_stiffness_factor" in e.HOOKS),
            wrench_fns=tuple(e.body_wrench for e in dyn if "body_wrench" in e.HOOKS),
            wheel_fns=tuple(e.wheel_torque for e in dyn if "wheel_torque" in e.HOOKS),
            k_c=sum(e.compliance_steer() for e in dyn if "compliance_steer" in e.HOOKS),
            wind_effects=self.effect_wind_enu_mps, **self._chassis_constants())
        return derivative_function(k), k

    def _chassis_constants(self) -> dict:
        """The chassis parts (``model.chassis``) of the vehicle plus the auxiliary roll stiffness
        of ``anti_roll_stiffness`` effects, as ``CoreConstants`` fields (None: not present)."""
        veh = self.vehicle
        ch, geo = veh.chassis, veh.geometry
        kf, kr = ch.anti_roll_stiffness_front_nmprad, ch.anti_roll_stiffness_rear_nmprad
        for e in self.effects.dynamics:
            if "anti_roll_stiffness" in e.HOOKS:
                ef, er = e.anti_roll_stiffness()
                kf, kr = kf + ef, kr + er
        tf, tr = 2.0 * geo.track_half_front_m, 2.0 * geo.track_half_rear_m
        self.anti_roll_stiffness_nmprad = (kf, kr)
        return {"ackermann_fraction": ch.ackermann_fraction,
                "arb": (kf, kr, tf, tr) if (kf != 0.0 or kr != 0.0) else None,
                "roll_centre": ((ch.roll_centre_height_front_m, ch.roll_centre_height_rear_m, tf, tr)
                                if ch.has_roll_centres else None)}

    # ------------------------------------------------------------------ helpers
    def evaluate(self, x, u: Inputs, env: Env) -> tuple[list, dict]:
        """x_dot and named diagnostics (slow path, for snapshots): see ``snapshot_fields``."""
        raw: dict = {}
        xd = self.f(x, u, env, raw)
        return xd, self._named(x, xd, raw, env)

    def _named(self, x, xd, raw: dict, env: Env) -> dict:
        """The named diagnostics from x_dot and the raw diagnostics ``raw`` of ``f(x, u, env, raw)``."""
        return _named(xd, raw["_acc_b"], raw["_g_b"], raw["_force_b"], raw["_moment_b"], raw["_height_cg"],
                      raw["_air_b"], raw["_rec"])

    def corner_kinematics(self, x, u: Inputs, env: Env) -> tuple[tuple, tuple, tuple]:
        """(slip ratios, slip angles [rad], road-wheel angles [rad]) per corner at ``x``: the
        ``slip_ratio_i``, ``slip_angle_rad_i`` and ``road_wheel_angle_rad_i`` of ``evaluate``
        without its other named diagnostics (the identifier's feeder, at 100 Hz)."""
        raw: dict = {"_want_air": False}
        self.f(x, u, env, raw)
        recs = raw["_rec"]
        return (tuple(r[3] for r in recs), tuple(r[4] for r in recs), tuple(r[9] for r in recs))

    def evaluate_from(self, x, xd, diag, env: Env) -> tuple[list, dict]:
        """``evaluate``'s result from x_dot and the compiled core's diagnostics array ``diag``
        (:mod:`vdps_hil.model.core_kernel`) already computed at ``x``."""
        d = diag.tolist()
        k = core_kernel
        return xd, _named(xd, d[k.D_ACC:k.D_ACC + 3], d[k.D_GB:k.D_GB + 3], d[k.D_FORCE:k.D_FORCE + 3],
                          d[k.D_MOMENT:k.D_MOMENT + 3], d[k.D_HCG], d[k.D_AIR:k.D_AIR + 3],
                          [d[16 * i:16 * i + 16] for i in range(4)])

    def regressor_quantities(self, q: Mapping[str, float]) -> dict[str, float]:
        """``q`` (e.g. a truth snapshot or the estimator's equivalents of its names) completed
        with the model's constants that effects' ``regressors`` need: ``static_load_n_i``,
        ``cornering_stiffness_nprad_i`` (C_alpha,i before effects), ``corner_x_m_i``,
        ``rolling_radius_nominal_m``, ``cornering_stiffness_front_nprad``, ``l_f_m``,
        ``track_front_m``, ``track_rear_m`` and ``front_lateral_force_n`` (from
        ``tire_force_lat_n_1/2`` when present)."""
        out = dict(q)
        p = self.vehicle.params
        for i in range(4):
            out[f"static_load_n_{i + 1}"] = self.static_load_n[i]
            out[f"cornering_stiffness_nprad_{i + 1}"] = self.c_alpha[i]
            out[f"corner_x_m_{i + 1}"] = self.corner_xy[i][0]
            out.setdefault(f"rolling_radius_m_{i + 1}", self.rolling_radius_m[i])
        out["rolling_radius_nominal_m"] = self.vehicle.tire.rolling_radius_m
        out["track_front_m"] = 2.0 * self.vehicle.geometry.track_half_front_m
        out["track_rear_m"] = 2.0 * self.vehicle.geometry.track_half_rear_m
        out["cornering_stiffness_front_nprad"] = p.cornering_stiffness_front_nprad
        out["l_f_m"] = self.vehicle.geometry.l_f_m
        if "tire_force_lat_n_1" in q and "tire_force_lat_n_2" in q:
            out["front_lateral_force_n"] = q["tire_force_lat_n_1"] + q["tire_force_lat_n_2"]
        return out

    def state_from(self, pos_g, euler_g, vel_b, rate_b, wheel_spin, susp_defl=None,
                   susp_defl_rate=None) -> list[float]:
        """A state vector from its named parts (e.g. an estimator's state at t0). With
        ``unsprung_dof`` the suspension deflections and rates default to zero."""
        x = [float(v) for part in (pos_g, euler_g, vel_b, rate_b, wheel_spin) for v in part]
        if len(x) != 16:
            raise ValueError("state_from needs 3 + 3 + 3 + 3 + 4 values")
        if self.unsprung_dof:
            x += [float(v) for v in (susp_defl if susp_defl is not None else (0.0,) * 4)]
            x += [float(v) for v in (susp_defl_rate if susp_defl_rate is not None else (0.0,) * 4)]
        return x

    def static_loads(self) -> tuple[float, ...]:
        """F_z0 per corner on a level road [N] (sprung share + unsprung weight)."""
        return self.static_load_n

    def design_state(self, speed_mps: float = 0.0, env: Env | None = None, heading_rad: float = 0.0,
                     east_m: float = 0.0, north_m: float = 0.0) -> list[float]:
        """The body at design ride height parallel to the road plane, moving straight ahead at
        ``speed_mps`` with heading ``heading_rad`` (yaw of the road-plane projection), wheels
        rolling without slip. The CG is at h_cg above the road plane."""
        env = env or Env()
        from .frames import compose_absolute
        phi_g, theta_g, psi_g = compose_absolute(0.0, 0.0, heading_rad, env.bank_rad, env.grade_rad)
        n = env.normal_g
        # point on the road below (east, north): solve n . p = 0 for up, then lift by h_cg along n
        up0 = -(n[0] * east_m + n[1] * north_m) / n[2]
        h = self.vehicle.geometry.h_cg_m
        pos = [east_m + h * n[0], north_m + h * n[1], up0 + h * n[2]]
        x = pos + [phi_g, theta_g, psi_g, float(speed_mps), 0.0, 0.0, 0.0, 0.0, 0.0]
        x += [speed_mps / r for r in self.rolling_radius_m]
        if self.unsprung_dof:
            x += [0.0] * 8
        return x

    def trim_state(self, speed_mps: float = 0.0, env: Env | None = None, heading_rad: float = 0.0,
                   inputs: Inputs | None = None, iterations: int = 30, **kw) -> list[float]:
        """``design_state`` with the vertical, roll, pitch (and unsprung) DOFs moved to static
        equilibrium (Newton on the body-z/roll/pitch accelerations and H_ddot; horizontal motion
        is left free). Used to start scenarios without a settling transient."""
        env = env or Env()
        u = inputs or Inputs()
        x0 = self.design_state(speed_mps, env, heading_rad, **kw)
        lay = self.layout
        n_env = env.normal_g
        # unknowns: height along the road normal, roll/pitch relative to the road, H_1..4
        from .frames import compose_absolute

        def build(z):
            x = list(x0)
            phi, th, ps = compose_absolute(z[1], z[2], heading_rad, env.bank_rad, env.grade_rad)
            x[3], x[4], x[5] = phi, th, ps
            for k in range(3):
                x[k] = x0[k] + z[0] * n_env[k]
            if lay.unsprung_dof:
                for i in range(4):
                    x[16 + i] = z[3 + i]
            return x

        def resid(z):
            x = build(z)
            xd = self.f(x, u, env)
            r = [xd[8], xd[9], xd[10]]
            if lay.unsprung_dof:
                r += xd[20:24]
            return r

        nz = 7 if lay.unsprung_dof else 3
        z = [0.0] * nz
        import numpy as np
        for _ in range(iterations):
            r0 = np.array(resid(z))
            if np.max(np.abs(r0)) < 1e-10:
                break
            J = np.zeros((len(r0), nz))
            for j in range(nz):
                zp = list(z)
                zp[j] += 1e-7
                J[:, j] = (np.array(resid(zp)) - r0) / 1e-7
            dz = np.linalg.lstsq(J, -r0, rcond=None)[0]
            z = [z[j] + float(dz[j]) for j in range(nz)]
        return build(z)

    def state_names(self) -> tuple[str, ...]:
        return self.layout.names
