"""Tire effects: the two tire force laws and the two tire modifiers.

Symbols (one corner i; wheel axes in the road plane, eq 15-16)::

    kappa     slip ratio (r_i omega_i - v_l) / max(|v_l|, v_floor)        [-]
    alpha     slip angle -atan(v_t / max(|v_l|, v_floor))                  [rad]
    F_a, F_b  longitudinal / lateral adhesive force                         [N]
    F_z       normal load, F_z0 its static (nominal) value                  [N]
    C_kappa   tracking (longitudinal slip) stiffness C_lambda,i             [N]
    C_alpha   cornering stiffness of one tire, C_alpha,f/2 or C_alpha,r/2   [N/rad] (eq 17)

* ``linear_tire`` (eq 15): F_a = C_kappa kappa, F_b = C_alpha alpha.
* ``magic_formula_tire`` (Pacejka): pure-slip Magic Formula with combined slip by the
  normalised-slip (similarity) method and load-sensitive friction.
* ``load_dependent_cornering_stiffness``: C_alpha(F_z) = C_alpha,0 (1 + a d - b d^2),
  d = F_z/F_z0 - 1.
* ``low_pressure_tire``: one wheel's rolling radius is smaller.

Compiled form (:meth:`~vdps_hil.model.effects.base.DynamicsEffect.kernel_terms`): the force
laws and the stiffness factor are written once, as :func:`~vdps_hil.jit.inline` functions the
effects' methods call and the compiled core (:mod:`vdps_hil.model.core_kernel`) calls with the
parameters as numbers (codes ``TIRE_LINEAR``, ``TIRE_MAGIC_FORMULA``, ``STIFFNESS_LOAD_DEPENDENT``).
"""

from __future__ import annotations

import math
from typing import Mapping

from vdps_hil.jit import inline

from .base import DynamicsEffect, EffectConfigError, ParamSpec, TireModel

TIRE_LINEAR = 1
TIRE_MAGIC_FORMULA = 2
STIFFNESS_LOAD_DEPENDENT = 1


@inline
def linear_tire_forces(fz_n, kappa, alpha_rad, c_kappa_n, c_alpha_nprad):
    """Eq 15: (F_a, F_b) = (C_kappa kappa, C_alpha alpha); (0, 0) off the ground (F_z <= 0)."""
    if fz_n <= 0.0:
        return 0.0, 0.0
    return c_kappa_n * kappa, c_alpha_nprad * alpha_rad


@inline
def magic_formula_forces(fz_n, fz0_n, kappa, alpha_rad, c_kappa_n, c_alpha_nprad, mu0, ez, cx, ex, cy, ey):
    """(F_a, F_b) of :class:`MagicFormulaTire` (its docstring) with its six parameters."""
    if fz_n <= 0.0:
        return 0.0, 0.0
    mu = mu0 * (1.0 + ez * (fz_n / fz0_n - 1.0))
    if mu < 0.05 * mu0:
        mu = 0.05 * mu0
    d = mu * fz_n
    x = c_kappa_n * kappa / d
    y = c_alpha_nprad * alpha_rad / d
    rho = math.sqrt(x * x + y * y)
    if rho < 1e-12:
        return c_kappa_n * kappa, c_alpha_nprad * alpha_rad
    bx = rho / cx
    gx = math.sin(cx * math.atan(bx - ex * (bx - math.atan(bx))))
    by = rho / cy
    gy = math.sin(cy * math.atan(by - ey * (by - math.atan(by))))
    s = d / rho
    return s * gx * x, s * gy * y


@inline
def load_dependent_stiffness_factor(fz_n, fz0_n, load_slope, load_degression):
    """max(0, 1 + a d - b d^2), d = F_z / F_z0 - 1 (:class:`LoadDependentCorneringStiffness`)."""
    d = fz_n / fz0_n - 1.0
    f = 1.0 + load_slope * d - load_degression * d * d
    return f if f > 0.0 else 0.0


class LinearTire(TireModel):
    """``linear_tire`` -- the paper's eq 15 (with eq 17's axle split C_alpha,i = C_alpha,axle/2):

        F_a = C_kappa kappa          [N]
        F_b = C_alpha alpha          [N]

    The stiffnesses are the vehicle's identified parameters (no parameters of its own; default
    magnitudes are the vehicle file's: sedan C_kappa = 80 kN, C_alpha = 60 kN/rad front and
    85 kN/rad rear per tire). A wheel off the ground (F_z <= 0) carries no force. Valid at small
    slip only (no saturation).
    """

    name = "linear_tire"
    PARAMS = ()
    LINEAR_IN_PARAMETERS = True

    def tire_forces(self, fz_n, fz0_n, kappa, alpha_rad, c_kappa_n, c_alpha_nprad):
        return linear_tire_forces(fz_n, kappa, alpha_rad, c_kappa_n, c_alpha_nprad)

    def kernel_terms(self):
        return (("tire_forces", TIRE_LINEAR, ()),)

    def regressors(self, q: Mapping[str, float]) -> dict[str, dict[str, float]]:
        """No parameters of its own: its stiffnesses are the vehicle's (eq 21-22 identify them)."""
        return {}


class MagicFormulaTire(TireModel):
    """``magic_formula_tire`` -- Pacejka's Magic Formula with combined slip and load sensitivity.

    Peak friction with load sensitivity (mu_0 = peak_friction, e_z = load_sensitivity)::

        mu = mu_0 (1 + e_z (F_z / F_z0 - 1)),   D = mu F_z

    Normalised slip demand (the linear forces over D) and its magnitude::

        X = C_kappa kappa / D,   Y = C_alpha alpha / D,   rho = sqrt(X^2 + Y^2)

    Pure-slip Magic Formula in the normalised variable (B = 1/C so the slope at zero is 1, i.e.
    the initial slip stiffnesses are exactly C_kappa and C_alpha as in eq 15)::

        g(rho; C, E) = sin(C atan(B rho - E (B rho - atan(B rho)))),   B = 1/C

    Combined slip (similarity method: the force points along the linear demand, its size follows
    the Magic Formula of the resultant slip, so |F| <= D -- the friction circle)::

        F_a = D g(rho; C_x, E_x) X / rho,    F_b = D g(rho; C_y, E_y) Y / rho

    For pure slip this is the standard Magic Formula F = D sin(C atan(B s - E(B s - atan B s)))
    with B = C_slip / (C D). Defaults (sedan-truth [effects]): mu_0 = 1.0, C_y = 1.3, C_x = 1.65,
    E_y = -1.0, E_x = 0.0, e_z = -0.1 (peak friction falls 10 % per 100 % extra load). Small-slip
    limit equals ``linear_tire``; the lateral peak is mu F_z (tested).
    """

    name = "magic_formula_tire"
    PARAMS = (
        ParamSpec("peak_friction", "1", 1.0, "peak friction coefficient mu_0 at the nominal load", 0.1, 1.6),
        ParamSpec("shape_lateral", "1", 1.3, "Magic Formula shape factor C_y", 1.0, 2.0),
        ParamSpec("shape_longitudinal", "1", 1.65, "Magic Formula shape factor C_x", 1.0, 2.0),
        ParamSpec("curvature_lateral", "1", -1.0, "Magic Formula curvature factor E_y", -10.0, 1.0),
        ParamSpec("curvature_longitudinal", "1", 0.0, "Magic Formula curvature factor E_x", -10.0, 1.0),
        ParamSpec("load_sensitivity", "1", -0.1, "d(mu/mu_0)/d(F_z/F_z0)", -0.5, 0.2),
    )

    def _validate(self) -> None:
        for k in ("shape_lateral", "shape_longitudinal"):
            if not 1.0 <= self._values[k] < 2.0:
                raise EffectConfigError(f"effect {self.name!r}: {k} must be in [1, 2) for a force peak")
        for k in ("curvature_lateral", "curvature_longitudinal"):
            if self._values[k] > 1.0:
                raise EffectConfigError(f"effect {self.name!r}: {k} must be <= 1")
        if self._values["peak_friction"] <= 0.0:
            raise EffectConfigError(f"effect {self.name!r}: peak_friction must be positive")
        v = self._values
        object.__setattr__(self, "_k", (v["peak_friction"], v["load_sensitivity"],
                                        v["shape_longitudinal"], v["curvature_longitudinal"],
                                        v["shape_lateral"], v["curvature_lateral"]))

    @staticmethod
    def shape(rho: float, c: float, e: float) -> float:
        """g(rho; C, E): the normalised pure-slip Magic Formula (slope 1 at 0, peak 1)."""
        brho = rho / c
        return math.sin(c * math.atan(brho - e * (brho - math.atan(brho))))

    def tire_forces(self, fz_n, fz0_n, kappa, alpha_rad, c_kappa_n, c_alpha_nprad):
        return magic_formula_forces(fz_n, fz0_n, kappa, alpha_rad, c_kappa_n, c_alpha_nprad, *self._k)

    def kernel_terms(self):
        return (("tire_forces", TIRE_MAGIC_FORMULA, self._k),)

    def peak_force(self, fz_n: float, fz0_n: float) -> float:
        """D = mu(F_z) F_z [N]: the force the tire cannot exceed."""
        mu0, ez = self._k[0], self._k[1]
        return max(0.05 * mu0, mu0 * (1.0 + ez * (fz_n / fz0_n - 1.0))) * fz_n


class LoadDependentCorneringStiffness(DynamicsEffect):
    """``load_dependent_cornering_stiffness`` -- cornering stiffness that grows less than in
    proportion to the normal load (so lateral load transfer lowers an axle's stiffness)::

        C_alpha,i = C_alpha,i,0 * max(0, 1 + a d - b d^2),     d = F_z,i / F_z0,i - 1

    a = load_slope [-] (default 0.6), b = load_degression [-] (default 0.4). The defaults make
    C_alpha vanish at zero load and match, to second order about F_z0, Pacejka's
    K_y = p_Ky1 F_z0 sin(2 atan(F_z / (2 F_z0))) (peak stiffness at twice the nominal load:
    slope 0.6, curvature -0.88/2). With a = b = 0 the law is ``linear_tire``'s constant C_alpha.
    Linear in (a, b): dF_b/da = C_alpha,0 alpha d, dF_b/db = -C_alpha,0 alpha d^2 (small slip).
    """

    name = "load_dependent_cornering_stiffness"
    HOOKS = ("cornering_stiffness_factor",)
    LINEAR_IN_PARAMETERS = True
    PARAMS = (
        ParamSpec("load_slope", "1", 0.6, "a: relative stiffness change per relative load change", 0.0, 1.5),
        ParamSpec("load_degression", "1", 0.4, "b: quadratic degression of stiffness with load", 0.0, 1.5),
    )

    def cornering_stiffness_factor(self, corner, fz_n, fz0_n):
        v = self._values
        return load_dependent_stiffness_factor(fz_n, fz0_n, v["load_slope"], v["load_degression"])

    def kernel_terms(self):
        v = self._values
        return (("cornering_stiffness_factor", STIFFNESS_LOAD_DEPENDENT, (v["load_slope"], v["load_degression"])),)

    def regressors(self, q: Mapping[str, float]) -> dict[str, dict[str, float]]:
        """Lateral tire force change in the body lat/yaw equations (small slip, small steer):
        per corner dF_b/da = C0 alpha d, dF_b/db = -C0 alpha d^2, with yaw moment arm x_i.

        ``q`` needs ``slip_angle_rad_i``, ``normal_load_n_i``, ``static_load_n_i``,
        ``cornering_stiffness_nprad_i`` (C0) and ``corner_x_m_i``, i = 1..4."""
        ra = {"lat": 0.0, "yaw": 0.0}
        rb = {"lat": 0.0, "yaw": 0.0}
        for i in range(1, 5):
            d = q[f"normal_load_n_{i}"] / q[f"static_load_n_{i}"] - 1.0
            base = q[f"cornering_stiffness_nprad_{i}"] * q[f"slip_angle_rad_{i}"]
            x = q[f"corner_x_m_{i}"]
            ra["lat"] += base * d
            ra["yaw"] += base * d * x
            rb["lat"] -= base * d * d
            rb["yaw"] -= base * d * d * x
        return {eq: {"load_slope": ra[eq], "load_degression": rb[eq]} for eq in ("lat", "yaw")}


class LowPressureTire(DynamicsEffect):
    """``low_pressure_tire`` -- one under-inflated tire rolls on a smaller effective radius::

        r_w = r (1 - radius_reduction)     for the chosen wheel (1..4 = FL FR RR RL)

    Free rolling then spins that wheel faster: omega_w / omega_nominal = r / r_w. Default:
    wheel 4 (rear left), radius_reduction = 0.015 (1.5 %, about a tire at half its pressure).
    Only the rolling radius changes (slip kinematics and the wheel's lever arm r_i of eq 13);
    ride height and vertical stiffness are left as they are.
    Regressor (wheel-speed relation v = r omega): d(r_w omega_w)/d(radius_reduction) = -r omega_w.
    """

    name = "low_pressure_tire"
    HOOKS = ("rolling_radius_factor",)
    LINEAR_IN_PARAMETERS = True
    PARAMS = (
        ParamSpec("wheel", "1", 4.0, "wheel number 1..4 (FL FR RR RL)", 1.0, 4.0),
        ParamSpec("radius_reduction", "1", 0.015, "relative rolling radius loss of that wheel", 0.0, 0.1),
    )

    def _validate(self) -> None:
        w = self._values["wheel"]
        if w not in (1.0, 2.0, 3.0, 4.0):
            raise EffectConfigError(f"effect {self.name!r}: wheel must be 1, 2, 3 or 4, got {w:g}")
        if not 0.0 <= self._values["radius_reduction"] < 0.5:
            raise EffectConfigError(f"effect {self.name!r}: radius_reduction must be in [0, 0.5)")

    def rolling_radius_factor(self, corner: int) -> float:
        if corner == int(self._values["wheel"]) - 1:
            return 1.0 - self._values["radius_reduction"]
        return 1.0

    def regressors(self, q: Mapping[str, float]) -> dict[str, dict[str, float]]:
        """On the wheel-speed relation of the chosen wheel: ``{"wheel_speed_i": {...}}`` with
        d(r omega)/d(radius_reduction) = -r_nominal omega (needs ``wheel_speed_radps_i``,
        ``rolling_radius_nominal_m``)."""
        i = int(self._values["wheel"])
        return {f"wheel_speed_{i}": {"radius_reduction": -q["rolling_radius_nominal_m"] * q[f"wheel_speed_radps_{i}"]}}


TIRE_EFFECTS = (LinearTire, MagicFormulaTire, LoadDependentCorneringStiffness, LowPressureTire)
