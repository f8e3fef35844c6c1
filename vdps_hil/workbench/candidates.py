"""Effect candidates: how each effect (built-in or the user's) offers columns to the ranking.

A candidate turns an effect into regressor columns over the residual rows of
:mod:`~vdps_hil.workbench.residuals` -- ``dyn`` (rows x 14 equations x parameters, the change
of the eq 13 residuals the effect explains per unit of each fitted parameter) and ``inn`` (GNSS
innovation rows x parameters) -- and back into an :class:`~vdps_hil.model.effects.Effect` with
fitted values. The residual convention: r = measured - model, so an effect present in the car
but missing in the model leaves r = sum_p column_p theta_p.

===================================  ===============================================================
adapter                              columns
===================================  ===============================================================
:class:`RegressorCandidate`          the effect's own ``regressors(q)`` (effects linear in their
                                     parameters whose regressors cover every equation they change:
                                     drag, rolling resistance, a user's linear effect)
:class:`MeasurementCandidate`        ``regressors(kin)`` of a sensor effect: m df/dtheta on the
                                     long/lat/vert force balance and the strapdown innovations
:class:`NumericCandidate`            central differences of the residual in each parameter at the
                                     effect's generic prior (steering compliance, load-dependent
                                     stiffness -- their regressors omit the roll moment -- and any
                                     user effect without regressors)
:class:`CrosswindCandidate`          the wind across the mean direction of travel: the side force and
                                     yaw moment, first order in the wind
:class:`LowPressureCandidate`        one tire's radius loss; the wheel (1..4) whose column fits best
:class:`MagicFormulaCandidate`       ``--add``'s tire: the peak friction mu itself, a profile of the
                                     identified model's objective (the ranking uses
                                     :class:`TireSaturationCandidate` instead)
:class:`TireSaturationCandidate`    the ranking's saturation column: s times the generic Magic
                                     Formula's pure-lateral departure from the linear tire (linear
                                     in s, judged beyond the re-identified stiffnesses)
:class:`ParameterCandidate`          one of the ten identified parameters (eq 20-23): finite
                                     differences of the residual in that parameter
===================================  ===============================================================

Generic priors: every adapter starts from the effect's ``ParamSpec`` defaults (never from a
truth file); ``prior_theta`` is the typical magnitude used to judge excitation.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from vdps_hil.model.effects import REGISTRY, EffectSet
from vdps_hil.model.effects.base import DynamicsEffect, Effect, MeasurementEffect, TireModel

__all__ = ["Candidate", "RegressorCandidate", "MeasurementCandidate", "NumericCandidate", "CrosswindCandidate",
           "LowPressureCandidate", "MagicFormulaCandidate", "TireSaturationCandidate", "saturation_columns",
           "ParameterCandidate", "candidate_for",
           "default_candidates", "BASE_PARAMS", "PARAM_LABELS"]

BASE_PARAMS: tuple[str, ...] = ("mass_kg", "inertia_x_kgm2", "inertia_y_kgm2", "inertia_z_kgm2",
                                "cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad",
                                "tracking_stiffness_1_n", "tracking_stiffness_2_n", "tracking_stiffness_3_n",
                                "tracking_stiffness_4_n")
"""The ten identified parameters (section 5.2), re-identified with every fit."""
PARAM_LABELS = {"mass_kg": "mass", "inertia_x_kgm2": "roll inertia", "inertia_y_kgm2": "pitch inertia",
                "inertia_z_kgm2": "yaw inertia", "cornering_stiffness_front_nprad": "front cornering stiffness",
                "cornering_stiffness_rear_nprad": "rear cornering stiffness",
                **{f"tracking_stiffness_{i}_n": f"wheel {i} slip stiffness" for i in range(1, 5)}}
PARAM_ALIASES = {"cornering_stiffness_front_nprad": "cornering_stiffness_front",
                 "cornering_stiffness_rear_nprad": "cornering_stiffness_rear", "mass_kg": "mass",
                 "inertia_x_kgm2": "inertia_x", "inertia_y_kgm2": "inertia_y", "inertia_z_kgm2": "inertia_z",
                 **{f"tracking_stiffness_{i}_n": f"tracking_stiffness_{i}" for i in range(1, 5)}}
"""Ranking names of the parameters (the JSON ``effect`` field)."""


class Candidate:
    """One candidate of the ranking. Subclasses set ``params`` and implement ``columns``."""

    kind = "effect"

    def __init__(self, effect_cls: type[Effect], params: Sequence[str] | None = None):
        self.effect_cls = effect_cls
        self.name = effect_cls.name
        specs = effect_cls.param_specs()
        self.params: tuple[str, ...] = tuple(params) if params is not None else tuple(specs)
        self.defaults = {p.name: p.default for p in effect_cls.PARAMS}
        self.family = effect_cls.family

    def prior_theta(self) -> np.ndarray:
        return np.array([self.defaults[p] for p in self.params], dtype=float)

    def columns(self, ctx) -> tuple[np.ndarray | None, np.ndarray | None]:
        raise NotImplementedError

    def effect(self, theta: Sequence[float]) -> Effect:
        vals = dict(self.defaults)
        vals.update({p: float(v) for p, v in zip(self.params, theta)})
        return self.effect_cls(**vals)

    def report_params(self, theta, sigma) -> dict[str, tuple[float, float]]:
        """Parameter name -> (value, sigma) in the effect's own parameters."""
        return {p: (float(v), float(s)) for p, v, s in zip(self.params, theta, sigma)}

    def plausible(self, theta) -> bool:
        try:
            eff = self.effect(theta)
        except ValueError:
            return False
        specs = self.effect_cls.param_specs()
        return all(specs[p].lower <= eff.params[p] <= specs[p].upper for p in self.params)

    # --- the joint (nonlinear) fit: parameters phi, columns re-linearised at phi
    linear: bool = True
    """True when the columns do not depend on the parameter values (regressors)."""

    def to_phi(self, theta) -> np.ndarray:
        """Screening parameters -> fit parameters (a start for the joint fit)."""
        return np.asarray(theta, dtype=float)

    def phi_effect(self, phi) -> Effect:
        return self.effect(phi)

    def phi_prior_sigma(self):
        """Gaussian prior sigmas of the fit parameters around the generic prior (None: none)."""
        return None

    def phi_plausible(self, phi) -> bool:
        return self.plausible(phi)

    def phi_report(self, phi, sigma) -> dict[str, tuple[float, float]]:
        return self.report_params(phi, sigma)

    def material(self, phi, fraction: float = 0.1) -> bool:
        """Large enough to matter: some parameter at least ``fraction`` of its generic prior size
        (a 0.03 % radius loss or a 0.2 m^2 x 1 % drag is no missing effect)."""
        prior = np.abs(self.prior_theta())
        ph = np.abs(np.asarray(phi, dtype=float))
        use = prior > 0
        return bool(np.any(ph[use] >= fraction * prior[use])) if use.any() else True

    def clip_phi(self, phi) -> np.ndarray:
        """Parameters moved into their physically plausible ranges (``ParamSpec`` bounds)."""
        specs = self.effect_cls.param_specs() if self.effect_cls is not None else {}
        out = np.array(phi, dtype=float)
        for j, p in enumerate(self.params):
            if p in specs:
                out[j] = min(max(out[j], specs[p].lower), specs[p].upper)
        return out

    def phi_steps(self, phi) -> np.ndarray:
        prior = self.prior_theta()
        return np.maximum(np.abs(np.asarray(phi, dtype=float)) * 0.05, np.abs(prior) * 0.05) + 1e-9

    def delta_columns(self, ctx, phi) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Columns of a change of phi at phi (the model already holds the effect at phi)."""
        if self.linear:
            return self.columns(ctx)
        steps = self.phi_steps(phi)
        cols = []
        for j, h in enumerate(steps):
            ph = np.array(phi, dtype=float)
            ph[j] += h
            cols.append(ctx.dyn_contribution(self.phi_effect(ph)) / h)
        return np.stack(cols, axis=2), None

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name})"


FIT_PARAMS: dict[str, tuple[str, ...]] = {"aero_drag": ("cda_m2",)}
"""Built-in effects whose other parameters are constants, not fitted (air density)."""


class RegressorCandidate(Candidate):
    """Columns from the effect's own ``regressors(q)`` (linear in its parameters); parameters
    without a column on this drive are dropped (held at their defaults)."""

    def __init__(self, effect_cls, params=None):
        if params is None and REGISTRY.get(effect_cls.name) is effect_cls:
            params = FIT_PARAMS.get(effect_cls.name)
        super().__init__(effect_cls, params)

    def columns(self, ctx):
        eff = self.effect_cls(**self.defaults)
        X = ctx.dyn_from_regressors(eff, self.params)
        used = np.any(X != 0.0, axis=(0, 1))
        if not used.all():
            keep = [p for p, u in zip(self.params, used) if u]
            if keep:
                X = X[:, :, used]
                self.params = tuple(keep)
        return X, None


class MeasurementCandidate(Candidate):
    """A sensor effect: m d f / d theta on the force balance and the strapdown innovations."""

    def columns(self, ctx):
        eff = self.effect_cls(**self.defaults)
        return ctx.dyn_from_fields(eff, self.params), ctx.innovation_columns(eff, self.params)


class NumericCandidate(Candidate):
    """Central differences of the residual in each parameter at the effect's generic prior
    (exact for effects linear in their parameters)."""

    def columns(self, ctx):
        base = dict(self.defaults)
        cols = []
        for p in self.params:
            h = max(abs(base[p]) * 0.1, 1e-6)
            lo = self.effect_cls(**{**base, p: base[p] - h}) if self._ok(p, base[p] - h) else self.effect_cls(**base)
            hi = self.effect_cls(**{**base, p: base[p] + h})
            dl = base[p] - h if self._ok(p, base[p] - h) else base[p]
            cols.append((ctx.dyn_contribution(hi) - ctx.dyn_contribution(lo)) / (base[p] + h - dl))
        inn = None
        if issubclass(self.effect_cls, MeasurementEffect):
            inn = ctx.innovation_columns(self.effect_cls(**base), self.params)
        return np.stack(cols, axis=2), inn

    def _ok(self, p, v) -> bool:
        try:
            self.effect_cls(**{**self.defaults, p: v})
            return True
        except ValueError:
            return False


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
        from vdps_hil.model.frames import dcm_gv_batch

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
        self.mu: float | None = None  # set by refine

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

    def refine(self, ctx, theta, fit_fn):
        """Golden-section search of mu on the held-in SSE (other shape factors at the prior)."""
        s = float(theta[0])
        if not (s > 0):
            return theta, None
        lo, hi = math.log(0.3), math.log(3.0)
        start = self._mu([s])
        if math.isfinite(start):
            lo, hi = math.log(max(0.3, start / 2.0)), math.log(min(3.0, start * 2.0))

        def sse(logmu):
            e = self.effect_cls(**{**self.defaults, "peak_friction": math.exp(logmu)})
            return fit_fn(ctx.dyn_contribution(e)[:, :, None])

        gr = (math.sqrt(5.0) - 1.0) / 2.0
        a, b = lo, hi
        c1, c2 = b - gr * (b - a), a + gr * (b - a)
        f1, f2 = sse(c1), sse(c2)
        for _ in range(14):
            if f1 < f2:
                b, c2, f2 = c2, c1, f1
                c1 = b - gr * (b - a)
                f1 = sse(c1)
            else:
                a, c1, f1 = c1, c2, f2
                c2 = a + gr * (b - a)
                f2 = sse(c2)
        self.mu = math.exp(0.5 * (a + b))
        return theta, self.mu

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

        dF_b,i = s [F_MF(alpha_i, F_z,i; mu_0) - C_alpha,i alpha_i]
               = s C_alpha,i alpha_i (g(Y_i) / Y_i - 1),   Y_i = C_alpha,i alpha_i / (mu(F_z,i) F_z,i)

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
    the peak friction itself (:class:`MagicFormulaCandidate`). Material: s >= ``fraction``."""

    def __init__(self, effect_cls):
        super().__init__(effect_cls, ("saturation_scale",))
        self.mu0 = float(self.defaults["peak_friction"])

    def prior_theta(self):
        return np.array([1.0])

    def columns(self, ctx):
        return saturation_columns(ctx.res, self.effect_cls(**self.defaults))[:, :, None], None

    def _mu(self, s: float) -> float:
        return self.mu0 / math.sqrt(s) if s > 1e-9 else math.inf

    def effect(self, theta):
        spec = self.effect_cls.param_specs()["peak_friction"]
        mu = self._mu(float(theta[0]))
        return self.effect_cls(**{**self.defaults, "peak_friction": min(max(mu, spec.lower), spec.upper)})

    def report_params(self, theta, sigma):
        return _saturation_report(float(theta[0]), float(sigma[0]), self._mu(float(theta[0])))

    def plausible(self, theta):
        s = float(theta[0])
        return s > 0 and self._mu(s) >= self.effect_cls.param_specs()["peak_friction"].lower

    def material(self, phi, fraction: float = 0.1) -> bool:
        return float(phi[0]) >= fraction

    def clip_phi(self, phi):
        lower = self.effect_cls.param_specs()["peak_friction"].lower
        return np.clip(np.asarray(phi, dtype=float), 0.0, (self.mu0 / lower) ** 2)


def saturation_columns(res, tire) -> np.ndarray:
    """(n, 14): the change of the model side of eq 13 when every tire's lateral force follows
    ``tire`` (pure lateral slip, kappa = 0) instead of the linear tire, at the rows' slip angles,
    normal loads and cornering stiffnesses (``TireSaturationCandidate``)."""
    n = len(res.t_s)
    out = np.zeros((n, 14))
    unit = res.lateral_unit
    if unit is None or not n:
        return out
    tf = tire.tire_forces
    for j, q in enumerate(res.quantities):
        for i in range(1, 5):
            a = q.get(f"slip_angle_rad_{i}")
            fz = q.get(f"normal_load_n_{i}")
            ca = q.get(f"cornering_stiffness_nprad_{i}")
            if a is None or fz is None or ca is None or not (fz > 0 and abs(a) > 1e-9):
                continue
            ratio = tf(fz, q[f"static_load_n_{i}"], 0.0, a, 1.0, ca)[1] / (ca * a) - 1.0
            # lateral_unit = d r / d C_alpha,i = -(direction) alpha_i; the model side moves by
            # (direction) dF_b = (direction) alpha_i C_alpha,i ratio
            out[j] -= unit[j, :, i - 1] * ca * ratio
    return np.nan_to_num(out)


class ParameterCandidate(Candidate):
    """One of the ten identified parameters (a re-identification, not an effect)."""

    kind = "parameter"

    def __init__(self, param: str, vehicle):
        self.param = param
        self.name = PARAM_ALIASES[param]
        self.params = (param,)
        self.family = "parameter"
        self.effect_cls = None
        self.defaults = {param: getattr(vehicle.params, param)}

    def columns(self, ctx):
        return ctx.param_columns(self.param), None

    def effect(self, theta):
        raise TypeError("a parameter is not an effect")

    def plausible(self, theta):
        return float(theta[0]) > 0.0

    def report_params(self, theta, sigma):
        return {self.param: (float(theta[0]), float(sigma[0]))}


_ADAPTERS = {"crosswind": CrosswindCandidate, "low_pressure_tire": LowPressureCandidate,
             "magic_formula_tire": MagicFormulaCandidate,
             # their regressors name only the lateral and yaw equations (the lateral force also moves
             # the roll moment at the contact height) and are first order; the core's own change
             # (central differences at the generic prior) covers every equation
             "load_dependent_cornering_stiffness": NumericCandidate,
             "steering_compliance": NumericCandidate}


def _has_regressors(cls) -> bool:
    if issubclass(cls, MeasurementEffect):
        return cls.regressors is not MeasurementEffect.regressors
    return cls.regressors is not DynamicsEffect.regressors


def candidate_for(effect_cls: type[Effect]) -> Candidate:
    """The adapter for an effect class (built-in special cases, then by its interface)."""
    if effect_cls.name in _ADAPTERS and REGISTRY.get(effect_cls.name) is effect_cls:
        return _ADAPTERS[effect_cls.name](effect_cls)
    params = getattr(effect_cls, "WORKBENCH_PARAMS", None)
    if issubclass(effect_cls, MeasurementEffect):
        if _has_regressors(effect_cls):
            return MeasurementCandidate(effect_cls, params)
        return NumericCandidate(effect_cls, params)
    if _has_regressors(effect_cls):
        return RegressorCandidate(effect_cls, params)
    return NumericCandidate(effect_cls, params)


def default_candidates(model_effects: EffectSet, extra: Sequence[type[Effect]] = (),
                       registry=None) -> list[Candidate]:
    """Every registered effect (plus ``extra`` user effects) not already in the model; tire laws
    other than the model's are offered only as the saturation candidate."""
    reg = dict(registry if registry is not None else REGISTRY)
    for cls in extra:
        reg[cls.name] = cls
    have = set(model_effects.names)
    out = []
    for name, cls in reg.items():
        if name in have or name == "linear_tire":
            continue
        if issubclass(cls, TireModel) and model_effects.tire is not None and model_effects.tire.name != "linear_tire":
            continue
        if cls is REGISTRY.get("magic_formula_tire"):
            out.append(TireSaturationCandidate(cls))  # the ranking's form; --add fits mu itself
            continue
        out.append(candidate_for(cls))
    return out
