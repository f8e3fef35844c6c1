"""Adapters of the built-in effects whose own regressors do not serve the ranking (the candidate
interface: :mod:`~vdps_hil.workbench.candidate_base`).

===================================  ===============================================================
adapter                              columns
===================================  ===============================================================
:class:`CrosswindCandidate`          the wind across the mean direction of travel: the side force and
                                     yaw moment, first order in the wind
:class:`LowPressureCandidate`        one tire's radius loss; the wheel (1..4) whose column fits best
:class:`MagicFormulaCandidate`       ``--add``'s tire: the peak friction mu itself, a profile of the
                                     identified model's objective (the ranking uses
                                     :class:`TireSaturationCandidate` instead)
:class:`TireSaturationCandidate`    the ranking's saturation column: s times the generic Magic
                                     Formula's pure-lateral departure from the linear tire (linear
                                     in s, judged beyond the re-identified stiffnesses)
:class:`SteeringOffsetCandidate`     the steering-angle sensor's offset: central differences of
                                     the residual (the rows' steering taken out by it); judged on
                                     the balance rows as a dynamics effect is, not on the GNSS
                                     innovations (it does not touch the IMU)
===================================  ===============================================================
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.model.frames import dcm_gv_batch

from .candidate_base import Candidate, NumericCandidate

__all__ = ["CrosswindCandidate", "LowPressureCandidate", "MagicFormulaCandidate", "TireSaturationCandidate",
           "SteeringOffsetCandidate",
           "saturation_columns", "cornering_coefficient"]


class CrosswindCandidate(Candidate):
    """Crosswind: theta = the wind across the drive's mean direction of travel [m/s] (positive
    toward its left); side-force area and centre of pressure at the effect's generic prior. A head
    or tail wind is not a crosswind (it would show as drag)."""

    def __init__(self, effect_cls):
        super().__init__(effect_cls, ("crosswind_mps",))
        self.heading = 0.0

    def prior_theta(self):
        return np.array([self.defaults["wind_speed_mps"]])

    def columns(self, ctx):
        # the side force of a wind across the car, to first order in the wind: F_y = 1/2 rho C_Y A
        # |v| w_y,body and M_z = x_cp F_y, w_y,body = (C_g^v w)_y. The effect's side force from the
        # car's own sideslip (v_air,y = v_y at zero wind) is left out: second order, and it would
        # let a "wind" mimic a cornering stiffness.
        c = ctx.table.columns
        idx = ctx.res.index
        psi = c["yaw_g_rad"][idx]
        ok = np.isfinite(psi)
        self.heading = float(np.arctan2(np.mean(np.sin(psi[ok])), np.mean(np.cos(psi[ok])))) if ok.any() else 0.0
        v = self.defaults
        k = 0.5 * v["air_density_kgpm3"] * v["side_force_area_m2"]
        speed = np.hypot(np.hypot(c["vel_g_mps_e"][idx], c["vel_g_mps_n"][idx]), c["vel_g_mps_u"][idx])
        cg = dcm_gv_batch(c["roll_g_rad"][idx], c["pitch_g_rad"][idx], psi)
        d = np.array([math.cos(self.heading + math.pi / 2), math.sin(self.heading + math.pi / 2), 0.0])
        fy = k * speed * (cg[:, 1, :] @ d)
        out = np.zeros((len(idx), 14, 1))
        out[:, 1, 0] = fy
        out[:, 5, 0] = v["cp_x_m"] * fy
        return np.nan_to_num(out), None

    def effect(self, theta):
        w = float(theta[0])
        to = self.heading + (math.pi / 2 if w >= 0 else -math.pi / 2)
        return self.effect_cls(**{**self.defaults, "wind_speed_mps": abs(w), "wind_to_rad": to})

    def report_params(self, theta, sigma):
        w, sw = float(theta[0]), float(sigma[0])
        to = self.heading + (math.pi / 2 if w >= 0 else -math.pi / 2)
        return {"wind_speed_mps": (abs(w), sw), "wind_to_rad": ((to + math.pi) % (2 * math.pi) - math.pi, 0.0),
                "crosswind_mps": (w, sw)}

    def plausible(self, theta):
        return abs(float(theta[0])) <= self.effect_cls.param_specs()["wind_speed_mps"].upper

    def material(self, phi, fraction: float = 0.1) -> bool:
        return abs(float(phi[0])) >= fraction * self.defaults["wind_speed_mps"]

    def clip_phi(self, phi):
        top = self.effect_cls.param_specs()["wind_speed_mps"].upper
        return np.clip(np.asarray(phi, dtype=float), -top, top)


class LowPressureCandidate(Candidate):
    """One under-inflated tire; the wheel whose column fits the residual best."""

    def __init__(self, effect_cls):
        super().__init__(effect_cls, ("radius_reduction",))
        self.wheel = int(self.defaults["wheel"])

    def columns(self, ctx):
        best, best_x = -1.0, None
        for w in (1, 2, 3, 4):
            eff = self.effect_cls(**{**self.defaults, "wheel": float(w)})
            X = ctx.dyn_from_regressors(eff, self.params)
            gain = ctx.fit_gain(X)
            if gain > best:
                best, best_x, self.wheel = gain, X, w
        return best_x, None

    def delta_columns(self, ctx, phi):
        """The wheel chosen when the candidate was screened stays (the residual it explained is
        gone from the model's residual once it is selected)."""
        eff = self.effect_cls(**{**self.defaults, "wheel": float(self.wheel)})
        return ctx.dyn_from_regressors(eff, self.params), None

    def effect(self, theta):
        return self.effect_cls(**{**self.defaults, "wheel": float(self.wheel), "radius_reduction": float(theta[0])})

    def report_params(self, theta, sigma):
        return {"wheel": (float(self.wheel), 0.0), "radius_reduction": (float(theta[0]), float(sigma[0]))}


def _saturation_report(s: float, s_sigma: float, mu: float) -> dict[str, tuple[float, float]]:
    """Reported parameters of a saturation scale s (sigma s_sigma) and the peak friction mu it
    implies, mu = mu_0 / sqrt(s): sigma_mu = mu s_sigma / (2 s) to first order."""
    smu = 0.5 * mu * s_sigma / s if s > 0 else math.nan
    return {"peak_friction": (mu, smu), "saturation_scale": (s, s_sigma)}


class MagicFormulaCandidate(Candidate):
    """Tire saturation: theta = s = (mu_0/mu)^2 scales the Magic Formula's departure from the
    linear tire at the generic prior mu_0 (module docstring) for screening; the joint fit is a
    profile of the identified model's objective over mu (``profile_range``), the other shape
    factors at their generic priors."""

    profile_range = (0.3, 1.6)

    def __init__(self, effect_cls):
        super().__init__(effect_cls, ("saturation_scale",))
        self.mu0 = self.defaults["peak_friction"]
        self.mu: float | None = None  # a fixed peak friction (None: from the saturation scale)

    linear = False

    def prior_theta(self):
        return np.array([1.0])

    def columns(self, ctx):
        return ctx.dyn_contribution(self.effect_cls(**self.defaults))[:, :, None], None

    def to_phi(self, theta):
        s = float(theta[0])
        mu = self.mu0 / math.sqrt(s) if s > 1e-3 else self.profile_range[1]
        return np.array([min(max(mu, self.profile_range[0]), self.profile_range[1])])

    def phi_effect(self, phi):
        return self.effect_cls(**{**self.defaults, "peak_friction": float(min(max(phi[0], 0.05), 1e3))})

    def phi_prior_sigma(self):
        """Peak friction of a dry road: generic prior 1.0 +- 0.3 -- a drive that never nears the
        limit cannot identify it, and then the prior keeps it (section 7.3's case)."""
        return [0.3]

    def phi_plausible(self, phi):
        spec = self.effect_cls.param_specs()["peak_friction"]
        return spec.lower <= float(phi[0]) <= spec.upper

    def phi_report(self, phi, sigma):
        return {"peak_friction": (float(phi[0]), float(sigma[0]))}

    def phi_steps(self, phi):
        return np.array([0.03 * max(float(phi[0]), 0.1)])

    def material(self, phi, fraction: float = 0.1) -> bool:
        return float(phi[0]) < 0.95 * self.profile_range[1]

    def clip_phi(self, phi):
        spec = self.effect_cls.param_specs()["peak_friction"]
        return np.array([min(max(float(phi[0]), spec.lower), spec.upper)])

    def _mu(self, theta) -> float:
        if self.mu is not None:
            return self.mu
        s = float(theta[0])
        return self.mu0 / math.sqrt(s) if s > 1e-6 else math.inf

    def effect(self, theta):
        mu = self._mu(theta)
        mu = min(max(mu if math.isfinite(mu) else 1e3, 0.05), 1e3)
        return self.effect_cls(**{**self.defaults, "peak_friction": mu})

    def report_params(self, theta, sigma):
        return _saturation_report(float(theta[0]), float(sigma[0]), self._mu(theta))

    def plausible(self, theta):
        if not float(theta[0]) > 0:
            return False
        mu = self._mu(theta)
        spec = self.effect_cls.param_specs()["peak_friction"]
        return spec.lower <= mu <= spec.upper


class TireSaturationCandidate(Candidate):
    """Tire saturation as the ranking judges it: theta = s, the saturation scale, multiplies the
    pure-lateral departure of the generic Magic Formula (``magic_formula_tire`` at its
    ``ParamSpec`` defaults, peak friction mu_0) from the linear tire, per tire i::

        dF_b,i = s [F_MF(alpha_i, F_z,i; mu_0, C'_i) - C'_i alpha_i]
               = s C'_i alpha_i (g(Y_i) / Y_i - 1),   Y_i = C'_i alpha_i / (mu(F_z,i) F_z,i)

    mapped onto eq 13 through the lateral force's direction and lever arm (the columns of the
    cornering stiffnesses, ``EquationResiduals.lateral_unit``). To lowest order the departure is
    cubic, dF ~ -k (C alpha)^3 / (mu F_z)^2, so s ~ (mu_0 / mu)^2: a tire with peak friction mu
    saturates s times as much as the generic one. The column is linear in s, so the ranking fits
    it together with the re-identified cornering stiffnesses and judges it on held-out blocks:
    only the saturation beyond what re-identified (secant) linear stiffnesses explain counts.
    Only the lateral force is modelled (no combined slip): the longitudinal forces are taken from
    the measured spin balance anyway (``ranking`` nuisance), and the combined-slip change of the
    wheel-speed rows would let the slip-stiffness priors speak for or against the tire.

    Plausible: s > 0 (a tire gives less force than linear at large slip, never more) with an
    implied peak friction mu_0 / sqrt(s) above the effect's lower bound. The upper bound of the
    peak friction is not applied to this estimate: it is biased high (measured s = 0.35-0.48 on
    the circle ramp with the generic tire as truth, i.e. mu ~ 1.5 instead of 1.0 -- the slowly
    varying body-velocity nuisance takes up part of a slowly growing saturation); ``--add`` fits
    the peak friction itself (:class:`MagicFormulaCandidate`). Material: s >= ``fraction``.

    The tires' own slip stiffness C'_i in Y_i (``stiffness``), the better of two on this drive
    (the larger in-sample fit beyond the two axle stiffnesses' columns, as
    :class:`LowPressureCandidate` picks its wheel):

    * ``"axle"``: the identified axle stiffness, C'_i = C_alpha,i (the model's linear tire is the
      tire itself, as in our simulator);
    * ``"common"``: four alike tires, one cornering coefficient for the car,
      C'_i = c F_z0,i with c = sum_k C_alpha,k / sum_k F_z0,k [1/rad]: the identified axle
      stiffnesses are effective ones whose front/rear split also holds what does not saturate
      (camber thrust from roll, roll and compliance steer). The departure grows with Y^2, i.e.
      with C'^2, so on CommonRoad's set 1 (rear axle identified 18 % above its Pacejka slope,
      front on it) ``"axle"`` puts 1.4 times the truth's rear/front share of the saturation into
      the column, which the lateral and yaw balances together reject (tuning seed 100: 11 % of
      the held-out balance residual explained, 38 % with ``"common"``).

    The effect it names (``effect``, ``--add``) keeps the model's axle stiffnesses: the Magic
    Formula effect has no cornering coefficient of its own."""

    STIFFNESS = ("axle", "common")

    def __init__(self, effect_cls):
        super().__init__(effect_cls, ("saturation_scale",))
        self.mu0 = float(self.defaults["peak_friction"])
        self.stiffness = "axle"
        self.coefficient_per_rad = math.nan  # c of ``"common"`` when screened (NaN: ``"axle"``)

    def prior_theta(self):
        return np.array([1.0])

    def _columns(self, res, coefficient_per_rad: float) -> np.ndarray:
        return saturation_columns(res, self.effect_cls(**self.defaults), coefficient_per_rad)[:, :, None]

    def columns(self, ctx):
        axles = np.concatenate([ctx.param_columns(p) for p in ("cornering_stiffness_front_nprad",
                                                              "cornering_stiffness_rear_nprad")], axis=2)
        best = None
        for stiffness in self.STIFFNESS:
            c = cornering_coefficient(ctx.res) if stiffness == "common" else math.nan
            x = self._columns(ctx.res, c)
            gain = ctx.fit_gain(np.concatenate([x, axles], axis=2))
            if best is None or gain > best[0]:
                best = (gain, x, stiffness, c)
        _, x, self.stiffness, self.coefficient_per_rad = best
        return x, None

    def delta_columns(self, ctx, phi):
        """The stiffness chosen when the candidate was screened stays, with its coefficient (the
        scale s was fitted on that column)."""
        return self._columns(ctx.res, self.coefficient_per_rad), None

    def _mu(self, s: float) -> float:
        return self.mu0 / math.sqrt(s) if s > 1e-9 else math.inf

    def effect(self, theta):
        spec = self.effect_cls.param_specs()["peak_friction"]
        mu = self._mu(float(theta[0]))
        return self.effect_cls(**{**self.defaults, "peak_friction": min(max(mu, spec.lower), spec.upper)})

    def report_params(self, theta, sigma):
        out = _saturation_report(float(theta[0]), float(sigma[0]), self._mu(float(theta[0])))
        if self.stiffness == "common":
            out["cornering_coefficient_per_rad"] = (self.coefficient_per_rad, 0.0)
        return out

    def plausible(self, theta):
        s = float(theta[0])
        return s > 0 and self._mu(s) >= self.effect_cls.param_specs()["peak_friction"].lower

    def material(self, phi, fraction: float = 0.1) -> bool:
        return float(phi[0]) >= fraction

    def clip_phi(self, phi):
        lower = self.effect_cls.param_specs()["peak_friction"].lower
        return np.clip(np.asarray(phi, dtype=float), 0.0, (self.mu0 / lower) ** 2)


def cornering_coefficient(res) -> float:
    """c = sum_i C_alpha,i / sum_i F_z0,i [1/rad]: the car's cornering stiffness per unit of
    static load (the model's stiffnesses and static loads, ``quantities``; NaN without rows)."""
    q = res.quantities[0] if len(res.t_s) else None
    if q is None:
        return math.nan
    ca = sum(q[f"cornering_stiffness_nprad_{i}"] for i in range(1, 5))
    return ca / sum(q[f"static_load_n_{i}"] for i in range(1, 5))


def saturation_columns(res, tire, coefficient_per_rad: float = math.nan) -> np.ndarray:
    """(n, 14): the change of the model side of eq 13 when every tire's lateral force departs
    from the linear tire as ``tire`` (pure lateral slip, kappa = 0) departs from its own linear
    law, at the rows' slip angles and normal loads (``TireSaturationCandidate``). The tire's
    slip stiffness C'_i: the row's cornering stiffness C_alpha,i, or ``coefficient_per_rad``
    times its static load when that is given (``"common"``)."""
    n = len(res.t_s)
    out = np.zeros((n, 14))
    unit = res.lateral_unit
    if unit is None or not n:
        return out
    tf = tire.tire_forces
    common = math.isfinite(coefficient_per_rad)
    for j, q in enumerate(res.quantities):
        for i in range(1, 5):
            a = q.get(f"slip_angle_rad_{i}")
            fz = q.get(f"normal_load_n_{i}")
            ca = q.get(f"cornering_stiffness_nprad_{i}")
            if a is None or fz is None or ca is None or not (fz > 0 and abs(a) > 1e-9):
                continue
            fz0 = q[f"static_load_n_{i}"]
            ca = coefficient_per_rad * fz0 if common else ca
            ratio = tf(fz, fz0, 0.0, a, 1.0, ca)[1] / (ca * a) - 1.0
            # lateral_unit = d r / d C_alpha,i = -(direction) alpha_i; the model side moves by
            # (direction) dF_b = (direction) alpha_i C'_i ratio
            out[j] -= unit[j, :, i - 1] * ca * ratio
    return np.nan_to_num(out)


class SteeringOffsetCandidate(NumericCandidate):
    """``steering_offset``: a sensor effect whose evidence is the lateral and yaw balance (the
    model steers by the reading), so the ranking fits and judges it on the balance rows
    (``family`` "dynamics" here; the effect stays a measurement effect) and it has no innovation
    columns (the strapdown of the GNSS innovations never reads the steering). Its central
    difference spans 0 to twice the prior (the residual is close to linear in the offset)."""

    STEP = 1.0
    INNOVATIONS = False

    def __init__(self, effect_cls, params=None):
        super().__init__(effect_cls, params)
        self.family = "dynamics"
