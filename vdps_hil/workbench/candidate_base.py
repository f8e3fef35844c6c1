"""The candidate interface and its generic adapters: how an effect offers columns to the ranking.

A candidate turns an effect into regressor columns over the residual rows of
:mod:`~vdps_hil.workbench.residuals` -- ``dyn`` (rows x 14 equations x parameters, the change
of the eq 13 residuals the effect explains per unit of each fitted parameter) and ``inn`` (GNSS
innovation rows x parameters, :mod:`~vdps_hil.workbench.innovations`) -- and back into an
:class:`~vdps_hil.model.effects.Effect` with fitted values. The residual convention: r =
measured - model, so an effect present in the car but missing in the model leaves
r = sum_p column_p theta_p.

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
:class:`ParameterCandidate`          one of the ten identified parameters (eq 20-23): finite
                                     differences of the residual in that parameter
===================================  ===============================================================

The adapters of built-in effects that need their own: :mod:`~vdps_hil.workbench.builtin_candidates`;
which adapter an effect gets: :mod:`~vdps_hil.workbench.candidates`.

Generic priors: every adapter starts from the effect's ``ParamSpec`` defaults (never from a
truth file); ``prior_theta`` is the typical magnitude used to judge excitation.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from vdps_hil.model.effects import REGISTRY
from vdps_hil.model.effects.base import Effect, MeasurementEffect

__all__ = ["Candidate", "RegressorCandidate", "MeasurementCandidate", "NumericCandidate", "ParameterCandidate",
           "BASE_PARAMS", "PARAM_LABELS", "PARAM_ALIASES", "FIT_PARAMS"]

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


def param_unit(p: str) -> tuple[str, float]:
    """(display unit, scale) of one of the ten parameters from its name's SI suffix."""
    if p.endswith("_nprad"):
        return "kN/rad", 1e3
    if p.endswith("_kgm2"):
        return "kg m^2", 1.0
    if p.endswith("_kg"):
        return "kg", 1.0
    if p.endswith("_n"):
        return "kN", 1e3
    return "", 1.0


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
    (exact for effects linear in their parameters), with steps of ``STEP`` times the prior; a
    sensor effect's innovation columns too unless ``INNOVATIONS`` is False."""

    STEP = 0.1
    INNOVATIONS = True

    def columns(self, ctx):
        base = dict(self.defaults)
        cols = []
        for p in self.params:
            h = max(abs(base[p]) * self.STEP, 1e-6)
            lo = self.effect_cls(**{**base, p: base[p] - h}) if self._ok(p, base[p] - h) else self.effect_cls(**base)
            hi = self.effect_cls(**{**base, p: base[p] + h})
            dl = base[p] - h if self._ok(p, base[p] - h) else base[p]
            cols.append((ctx.dyn_contribution(hi) - ctx.dyn_contribution(lo)) / (base[p] + h - dl))
        inn = None
        if self.INNOVATIONS and issubclass(self.effect_cls, MeasurementEffect):
            inn = ctx.innovation_columns(self.effect_cls(**base), self.params)
        return np.stack(cols, axis=2), inn

    def _ok(self, p, v) -> bool:
        try:
            self.effect_cls(**{**self.defaults, p: v})
            return True
        except ValueError:
            return False


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
