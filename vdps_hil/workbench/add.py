"""Add effects to the model, re-identify, and watch the error fall (``--add NAME ...``).

The added effects' parameters join the identification of the ten parameters: starting from the
generic priors in each effect (``ParamSpec`` defaults; never a truth file), the model vehicle,
the model's own effects and the added ones are fitted together on the residual equations
(:mod:`~vdps_hil.workbench.ranking`: Gauss-Newton on the MAP objective, the changes of the
added effects' parameters as always-on columns; two iterations with a sensor effect, else up to
four, each step kept only where it lowers the objective, ``_descend``). A sensor effect (IMU bias, lever
arm) is also taken out of the IMU readings and the estimator is run again, so the predictions
start from better estimates.

Before/after (the issue's ``before``/``after``):

* ``residual_rms`` per equation of eq 13 on the whole drive (in sample), model = identified
  parameters without / with the added effects, after the estimator's error directions are taken
  out (``cleaned_rms``: what the ranking sees, in N, N m and m/s); an equation whose residual
  rises beyond its noise is reported as made worse (``AddResult.worse``, ``WORSE_FRACTION``);
* ``simulation_error`` per horizon (0.5, 1, 2 s): the input-driven predictor started from the
  estimate every ``every_s``; the model used for a prediction starting at t0 is fitted **only on
  data before t0** (an expanding window refitted at ``refit_every_s`` boundaries; predictions
  start after ``min_train_s`` of data), so every prediction is made on held-out time; a quantity
  whose error rises by more than ``WORSE_FRACTION`` is reported as made worse
  (:func:`worse_predictions`: text, JSON, HTML).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import Effect, MeasurementEffect
from vdps_hil.model.params import Vehicle

from .added_params import IDENTIFIED_KEY, parameter_entries
from .candidate_base import Candidate
from .candidates import candidate_for
from .dataset import DriveTable
from .innovations import compute_innovations
from .ranking.config import RankingConfig
from .ranking.design import theta_of
from .ranking.sensor_fit import held_at, sensor_fit
from .ranking.identification import Point, apply_base, build_design, capped_design, effects_with, identify, interp_base
from .residuals import EQUATIONS, row_states
from .simulation_errors import HORIZONS_S, SimErrors, simulation_errors

__all__ = ["FittedModel", "fit_model", "AddResult", "add_effects", "cleaned_residuals", "before_after", "cleaned_rms",
           "rms_by_equation", "worse_predictions", "PREDICTED_UNITS"]


@dataclass
class FittedModel:
    """A model fitted on (part of) a drive: the vehicle with identified parameters, its effects
    (model's + added, with fitted values) and the parameters' sigmas."""

    vehicle: Vehicle
    effects: EffectSet
    sigmas: dict[str, dict[str, float]] = field(default_factory=dict)
    t_end_s: float = math.inf
    at_start: frozenset = frozenset()  # added dynamics effects no step of the fit moved (_descend)

    @property
    def added(self) -> list[str]:
        return list(self.sigmas)


def fit_model(table: DriveTable, vehicle: Vehicle, effects: EffectSet, add: Sequence[Candidate] = (),
              config: RankingConfig | None = None, mask: np.ndarray | None = None, iterations: int = 2,
              start: dict | None = None) -> FittedModel:
    """Identify the ten parameters and the added candidates' parameters jointly on the rows of
    ``mask`` (module docstring). ``start``: candidate name -> starting parameters (default the
    effect's generic prior); ``iterations``: Gauss-Newton steps when a sensor effect is added
    (dynamics effects alone: :func:`_descend`)."""
    cfg = config or RankingConfig()
    tab = table.slice(mask) if mask is not None else table
    states = row_states(tab, vehicle)
    if len(states.index) < 30:
        raise ValueError("too few usable rows to fit")
    inn = compute_innovations(tab)
    phis = {}
    eff = effects
    for c in add:
        phi = np.asarray(start[c.name], dtype=float) if start and c.name in start else c.to_phi(c.prior_theta())
        phis[c.name] = phi
        eff = effects_with(eff, c.phi_effect(phi))
    selected = {c.name: c for c in add}
    point, d, cols, _ = identify(tab, vehicle, eff, states, inn, cfg, reference=vehicle, phis=phis, selected=selected)
    sig: dict[str, dict[str, float]] = {}
    dynamics_only = bool(add) and not any(c.family == "measurement" for c in add)
    moved = True
    if dynamics_only:
        point, d, cols, moved = _descend(tab, vehicle, states, inn, cfg, selected, point, d, cols)
    for _ in range(iterations if add and not dynamics_only else 0):
        dh, ch, sensor = _held_sensors(d, cols, add)
        th, obj = dh.objective(ch)
        new_phis = dict(point.phis)
        new_eff = point.effects
        for c in add:
            dphi = sensor[c.name].phi if c.name in sensor else theta_of(dh, c.name, ch, th)
            ph = c.clip_phi(point.phis[c.name] + dphi)
            try:
                new_eff = effects_with(new_eff, c.phi_effect(ph))
                new_phis[c.name] = ph
            except ValueError:
                pass
        base = apply_base(point, dh, ch, th, cfg, vehicle)
        point = Point(base, new_eff, new_phis)
        _, d, cols = build_design(tab, states, inn, vehicle, point, cfg, selected)
    _, _, sensor = _held_sensors(d, cols, add)
    th, obj = d.objective(cols)
    s2 = obj / max(len(d.y) - len(cols), 1)
    G = d.stats()[0].sum(axis=(0, 1))
    A = G[np.ix_(cols, cols)] + np.diag([d.prior_w[k] * d.prior_scale for k in cols])
    try:
        cov = np.linalg.inv(A + np.eye(len(cols)) * 1e-12 * np.trace(A) / max(len(cols), 1))
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(A)
    pos = {k: j for j, k in enumerate(cols)}
    for c in add:
        ks = d.blocks[c.name]
        s = sensor[c.name].sigma if c.name in sensor else \
            np.array([math.sqrt(max(cov[pos[k], pos[k]] * s2, 0.0)) / d.scale[k] for k in ks])
        sig[c.name] = {k: v[1] for k, v in c.phi_report(point.phis[c.name], s).items()}
    t_end = float(tab.t_s[-1]) if len(tab.t_s) else math.inf
    return FittedModel(point.base, point.effects, sig, t_end, frozenset() if moved else frozenset(selected))


DESCENT_ITERATIONS = 4
"""Gauss-Newton iterations of a dynamics effect's ``--add`` fit (:func:`_descend`)."""
DESCENT_MIN_STEP = 1.0 / 16.0
"""The smallest fraction of a Gauss-Newton step :func:`_descend` tries before it stops."""


def _descend(tab, vehicle, states, inn, cfg, selected: dict[str, Candidate], point, d, cols):
    """Gauss-Newton on the added dynamics effects' parameters and the ten parameters, each step kept
    only where it lowers the MAP objective at the new point (the added effects' parameters held
    there, the ten parameters and the nuisance re-fitted: ``Design.objective`` without the added
    effects' step columns), else halved down to :data:`DESCENT_MIN_STEP` of it; at most
    :data:`DESCENT_ITERATIONS` steps. Full steps from the generic prior put the held-out refits on
    degenerate points (CommonRoad set 3's circle ramp, seed 1001: peak friction 0.11 +- 0.0007).
    ``selected``: the added candidates by name. Returns (point, design, columns, whether a step was
    kept: else the added parameters are their start, ``added_params`` "at start")."""
    add = list(selected.values())

    def at_point(d, cols) -> float:  # the objective at the point: the added effects' step columns held at zero
        own = {k for c in add for k in d.blocks.get(c.name, [])}
        return d.objective([k for k in cols if k not in own])[1]

    th, _ = d.objective(cols)
    obj = at_point(d, cols)
    moved = False
    for _ in range(DESCENT_ITERATIONS):
        base = apply_base(point, d, cols, th, cfg, vehicle)
        steps = {c.name: theta_of(d, c.name, cols, th) for c in add}
        w = 1.0
        while w >= DESCENT_MIN_STEP:
            phis, eff = dict(point.phis), point.effects
            for c in add:
                ph = c.clip_phi(point.phis[c.name] + w * steps[c.name])
                try:
                    eff = effects_with(eff, c.phi_effect(ph))
                    phis[c.name] = ph
                except ValueError:
                    pass
            trial = Point(interp_base(point.base, base, w, cfg), eff, phis)
            _, d2, cols2 = build_design(tab, states, inn, vehicle, trial, cfg, selected)
            obj2 = at_point(d2, cols2)
            if obj2 <= obj:
                th2, _ = d2.objective(cols2)
                point, d, cols, th, obj = trial, d2, cols2, th2, obj2
                moved = True
                break
            w /= 2.0
        else:
            break  # no fraction of the step lowers the objective: this point is kept
    return point, d, cols, moved


def _held_sensors(d, cols: list, add: Sequence[Candidate]):
    """(design, columns, {name: SensorFit}): each added sensor effect fitted on the GNSS
    innovations alone (``ranking.sensor_fit``: on all rows the balance equations' model error
    pulls its parameters) and held there; the other columns are fitted with it held."""
    sensor = {}
    for c in add:
        if c.family != "measurement" or c.name not in d.blocks:
            continue
        own = set(d.blocks[c.name])
        rest = [k for k in cols if k not in own]
        sf = sensor_fit(d, rest, c.name)
        if sf is not None:
            sensor[c.name] = sf
            d, cols = held_at(d, c.name, sf.th), rest
    return d, cols, sensor


@dataclass
class AddResult:
    """Before/after of adding effects (module docstring)."""

    added: list[str]
    fitted: FittedModel
    before: dict
    after: dict
    sim_before: SimErrors | None = None
    sim_after: SimErrors | None = None
    parameters: dict = field(default_factory=dict)
    noise_sigma: dict = field(default_factory=dict)
    """Equation -> its noise sigma (the ranking's row weight, equation units)."""

    def worse(self) -> dict[str, float]:
        """Equation -> relative rise, for the equations the added effects made worse."""
        return worse_equations(self.before, self.after, self.noise_sigma)

    def worse_predictions(self) -> dict[str, dict[str, float]]:
        """Horizon -> {quantity: relative rise} made worse (:func:`worse_predictions`)."""
        return worse_predictions(self.before, self.after)

    def to_json(self) -> dict:
        return {"added": list(self.added), "parameters": self.parameters, "before": self.before, "after": self.after,
                "residual_change": residual_change(self.before, self.after), "worse": sorted(self.worse()),
                "worse_predictions": self.worse_predictions(), "noise_sigma": dict(self.noise_sigma)}


WORSE_FRACTION = 0.10
"""An equation whose cleaned residual RMS rises by more than this fraction, and by more than
:data:`WORSE_NOISE` of its noise sigma, when effects are added is reported as made worse (text,
JSON, HTML), with both figures: either the effect does not explain that balance on this drive, or
the re-estimation with a sensor effect moved the states it uses (our simulator, a hidden 0.5
m/s^2 lateral accelerometer bias, `--add imu_bias`: every balance fell 41-89 % and two wheel-speed
rows rose from 2.3 / 2.7 to 5.8 / 4.6 mm/s; the real RAV4: yaw -50 %, lateral +46 %)."""
WORSE_NOISE = 0.5
"""The noise floor of "worse", in units of the equation's noise sigma (its high-frequency spread,
``residuals``): a smaller rise is not reported."""


def residual_change(before: dict, after: dict | None) -> dict[str, float | None]:
    """Relative change of each equation's residual RMS, (after - before) / before (None where
    either is missing or the before is zero)."""
    rb, ra = before.get("residual_rms", {}), (after or {}).get("residual_rms", {})
    out = {}
    for eq, b in rb.items():
        a = ra.get(eq)
        out[eq] = (a - b) / b if a is not None and b is not None and b > 0 else None
    return out


def worse_equations(before: dict, after: dict | None, noise_sigma: dict | None = None) -> dict[str, float]:
    """Equation -> relative rise, for the equations made worse: a rise above
    :data:`WORSE_FRACTION` and, where the equation's noise sigma is given, above
    :data:`WORSE_NOISE` of it."""
    rb, ra = before.get("residual_rms", {}), (after or {}).get("residual_rms", {})
    noise = noise_sigma or {}
    return {eq: c for eq, c in residual_change(before, after).items()
            if c is not None and c > WORSE_FRACTION and ra[eq] - rb[eq] > WORSE_NOISE * noise.get(eq, 0.0)}


PREDICTED_UNITS = {"position_m": "m", "yaw_deg": "deg", "roll_deg": "deg", "speed_mps": "m/s"}
"""The held-out prediction errors of ``simulation_error`` (per horizon) and their units."""


def worse_predictions(before: dict, after: dict | None) -> dict[str, dict[str, float]]:
    """Horizon -> {quantity: relative rise} of the held-out prediction errors (``simulation_error``)
    that rose by more than :data:`WORSE_FRACTION` with the added effects: the model with them
    predicts worse on time it was not fitted on (on CommonRoad set 3's circle ramp, tuning seed
    100, ``--add magic_formula_tire`` took the 2 s position error from 0.555 to 0.973 m). A
    diverged or missing figure is not compared (the diverged starts are said apart)."""
    sb = before.get("simulation_error") or {}
    sa = (after or {}).get("simulation_error") or {}
    out: dict[str, dict[str, float]] = {}
    for h, d in sb.items():
        a = sa.get(h) or {}
        for q in PREDICTED_UNITS:
            vb, va = d.get(q), a.get(q)
            if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (vb, va)) or vb <= 0:
                continue
            if (va - vb) / vb > WORSE_FRACTION:
                out.setdefault(h, {})[q] = (va - vb) / vb
    return out


def cleaned_residuals(table: DriveTable, model: FittedModel, vehicle: Vehicle, config: RankingConfig | None = None
                      ) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray]:
    """The residual the model leaves once the estimator's errors (the nuisance directions, the
    slow body velocity held as its fit held it: ``capped_design``) are taken out -- the residual
    the ranking works on, in equation units: (t_s (n,), table rows
    (n,), equation names (the evaluated ones), values (n, len(names)))."""
    return _cleaned(table, model, vehicle, config)[:4]


def _cleaned(table: DriveTable, model: FittedModel, vehicle: Vehicle, config: RankingConfig | None):
    """:func:`cleaned_residuals` and the evaluated equations' noise sigmas (the ranking's row
    weights, equation units)."""
    cfg = config or RankingConfig()
    states = row_states(table, model.vehicle)
    inn = compute_innovations(table)
    d, cols, th = capped_design(table, states, inn, vehicle, Point(model.vehicle, model.effects, {}), cfg)
    r = d.y - d.predict(cols, th)
    ctx = d.ctx
    n, e = ctx.y_dyn.shape
    dyn = r[:d.n_dyn_rows].reshape(n, e) * ctx.sig[None, :]
    names = [q for q, a in zip(EQUATIONS, ctx.avail) if a]
    return ctx.res.t_s[ctx.rows], ctx.res.index[ctx.rows], names, dyn, ctx.sig


def rms_by_equation(names: Sequence[str], values: np.ndarray) -> dict[str, float | None]:
    """RMS per equation of residual columns ``values`` (n, len(names)); None without rows."""
    return {q: float(np.sqrt(np.mean(values[:, k] ** 2))) if len(values) else None for k, q in enumerate(names)}


def cleaned_rms(table: DriveTable, model: FittedModel, vehicle: Vehicle, config: RankingConfig | None = None
                ) -> dict[str, float | None]:
    """RMS per equation of :func:`cleaned_residuals` (the before/after tables)."""
    _, _, names, dyn = cleaned_residuals(table, model, vehicle, config)
    return rms_by_equation(names, dyn)


def _expanding_models(table: DriveTable, vehicle: Vehicle, effects: EffectSet, add: Sequence[Candidate],
                      cfg: RankingConfig, boundaries: Sequence[float]) -> list[FittedModel]:
    out = []
    for tb in boundaries:
        mask = table.t_s < tb
        try:
            out.append(fit_model(table, vehicle, effects, [_fresh(c) for c in add], cfg, mask=mask))
        except ValueError:
            continue
    return out


def _fresh(c: Candidate) -> Candidate:
    """A new adapter of the same effect (adapters keep per-fit state, e.g. the chosen wheel)."""
    if c.kind == "parameter":
        return c
    return candidate_for(c.effect_cls)


def before_after(table: DriveTable, vehicle: Vehicle, effects: EffectSet, add: Sequence[Candidate], *,
                 config: RankingConfig | None = None, horizons_s: Sequence[float] = HORIZONS_S,
                 every_s: float = 0.5, refit_every_s: float = 2.0, min_train_s: float | None = None,
                 table_after: DriveTable | None = None, with_simulation: bool = True,
                 progress: Callable[[str], None] | None = None) -> AddResult:
    """The before/after tables (module docstring). ``table_after``: the drive re-estimated with the
    added sensor effects taken out of the IMU readings (default ``table``)."""
    cfg = config or RankingConfig()
    say = progress or (lambda s: None)
    tab_after = table_after if table_after is not None else table
    say("fitting the model without the added effects")
    m0 = fit_model(table, vehicle, effects, (), cfg)
    say("fitting the model with the added effects")
    m1 = fit_model(tab_after, vehicle, effects, [_fresh(c) for c in add], cfg)
    _, _, names0, dyn0, sig0 = _cleaned(table, m0, vehicle, cfg)
    before = {"residual_rms": rms_by_equation(names0, dyn0)}
    noise = {q: float(v) for q, v in zip(names0, sig0)}
    after = {"residual_rms": cleaned_rms(tab_after, m1, vehicle, cfg)}
    sim0 = sim1 = None
    if with_simulation:
        t = table.t_s
        dur = float(t[-1] - t[0])
        hmax = max(horizons_s)
        train = min_train_s if min_train_s is not None else max(4.0, 0.35 * dur)
        first = float(t[0]) + train
        last = float(t[-1]) - hmax
        if last > first:
            bounds = list(np.arange(first, last + 1e-9, refit_every_s))
            say(f"refitting on data before each of {len(bounds)} prediction blocks")
            ms0 = _expanding_models(table, vehicle, effects, (), cfg, bounds)
            ms1 = _expanding_models(tab_after, vehicle, effects, add, cfg, bounds)
            starts = np.arange(first, last + 1e-9, every_s)

            def picker(models):
                ends = [m.t_end_s for m in models]

                def veh_at(t0):
                    return _latest(models, ends, t0).vehicle

                def eff_at(t0):
                    return _latest(models, ends, t0).effects
                return veh_at, eff_at

            if ms0 and ms1:
                v0, e0 = picker(ms0)
                v1, e1 = picker(ms1)
                say(f"predicting from {len(starts)} starts")
                sim0 = simulation_errors(table, vehicle, effects, starts_s=starts, horizons_s=horizons_s,
                                         vehicle_at=v0, effects_at=e0)
                sim1 = simulation_errors(tab_after, vehicle, effects, starts_s=starts, horizons_s=horizons_s,
                                         vehicle_at=v1, effects_at=e1)
                if not sim0.missing_inputs:  # else only the note naming the missing inputs
                    before["simulation_error"] = sim0.summary()
                    after["simulation_error"] = sim1.summary()
    params = {}
    for e in m1.effects:
        if e.name in m1.sigmas:
            params[e.name] = parameter_entries(e, m1.sigmas[e.name], at_start=e.name in m1.at_start)
    params[IDENTIFIED_KEY] = {k: {"before": getattr(m0.vehicle.params, k), "after": getattr(m1.vehicle.params, k)}
                            for k in cfg.identify}
    return AddResult([c.name for c in add], m1, before, after, sim0, sim1, params, noise)


def _latest(models: list[FittedModel], ends: list[float], t0: float) -> FittedModel:
    return ([m for m, e in zip(models, ends) if e <= t0 + 1e-9] or models[:1])[-1]


def vertical_velocity_drift(table: DriveTable) -> float | None:
    """Slope a [m/s^2] of the least-squares line v_u(t) = c + a t through the estimate's vertical
    velocity over the drive (None below 5 s or 10 rows).

    A vertical accelerometer bias b_z (z up) is integrated by the estimator's vertical channel
    (height aided only weakly by GNSS): the estimated v_u drifts at a = k (b_z - b_z,removed),
    0 < k <= 1. A road vehicle's true vertical velocity (speed times grade) has no sustained
    trend over a drive, so a ~ 0 once the right bias is taken out; a drive with a long vertical
    curve (sag or crest) breaks this assumption."""
    if "vel_g_mps_u" not in table.columns:
        return None
    v = table.columns["vel_g_mps_u"]
    ok = np.isfinite(v)
    if ok.sum() < 10 or float(table.t_s[ok][-1] - table.t_s[ok][0]) < 5.0:
        return None
    return float(np.polyfit(table.t_s[ok], v[ok], 1)[0])


def _with_bias_z(effects: list[MeasurementEffect], bz: float) -> list[MeasurementEffect]:
    out = []
    for e in effects:
        if "accel_bias_z_mps2" in e.params:
            spec = next(p for p in e.PARAMS if p.name == "accel_bias_z_mps2")
            e = type(e)(**{**e.params, "accel_bias_z_mps2": min(max(bz, spec.lower), spec.upper)})
        out.append(e)
    return out


def _refine_vertical_bias(fitted: list[MeasurementEffect], table: DriveTable, reestimate
                          ) -> tuple[list[MeasurementEffect], DriveTable]:
    """The fitted sensor effects with the vertical accelerometer bias b_z re-solved so that the
    re-estimated vertical velocity does not drift (:func:`vertical_velocity_drift`), and the drive
    re-estimated with them. The equations of eq 13 see b_z only through the heave balance, where
    it is confounded with the sprung mass and the suspension forces (on the study's drives the
    fit is off by 100 % and more); an error in it makes the estimated vertical velocity drift,
    which moves the estimated position by about 1 m in 2 s -- the target of every prediction.

    One secant step on a(b_z): a0 at the fitted b_z0, a1 at b_z1 = b_z0 + a0, then
    b_z = b_z1 - a1 (b_z1 - b_z0) / (a1 - a0); kept only if a(b_z) is falling (k > 0) and the
    drift at b_z is smaller than a0; otherwise the fitted effects and ``table`` are returned."""
    bz0 = next((e.params["accel_bias_z_mps2"] for e in fitted if "accel_bias_z_mps2" in e.params), None)
    a0 = vertical_velocity_drift(table) if bz0 is not None else None
    if a0 is None or a0 == 0.0:
        return fitted, table
    bz1 = bz0 + a0
    a1 = vertical_velocity_drift(reestimate(_with_bias_z(fitted, bz1)))
    if a1 is None or not (a1 - a0) / (bz1 - bz0) < 0.0:
        return fitted, table
    bz = bz1 - a1 * (bz1 - bz0) / (a1 - a0)
    new = _with_bias_z(fitted, bz)
    tab = reestimate(new)
    a = vertical_velocity_drift(tab)
    if a is None or abs(a) >= abs(a0):
        return fitted, table
    return new, tab


def add_effects(table: DriveTable, vehicle: Vehicle, effects: EffectSet, names: Sequence[str], *,
                registry=None, user_effects: Sequence[type[Effect]] = (), reestimate=None, **kw) -> AddResult:
    """``--add NAME ...``: build the candidates by name and compute the before/after tables.
    ``reestimate(measurement_effects) -> DriveTable``: re-runs the estimator with sensor effects
    taken out of the IMU readings (the diagnosis passes one that decodes the recording again)."""
    from vdps_hil.model.effects import REGISTRY

    reg = dict(registry if registry is not None else REGISTRY)
    for cls in user_effects:
        reg[cls.name] = cls
    cands = []
    for n in names:
        if n not in reg:
            raise ValueError(f"unknown effect {n!r} (known: {', '.join(sorted(reg))})")
        if n in effects:
            raise ValueError(f"effect {n!r} is already in the model")
        cands.append(candidate_for(reg[n]))
    tab_after = table
    meas = [c for c in cands if issubclass(c.effect_cls, MeasurementEffect)]
    if meas and reestimate is not None:
        m = fit_model(table, vehicle, effects, [_fresh(c) for c in cands], kw.get("config"))
        fitted = [e for e in m.effects if isinstance(e, MeasurementEffect) and e.name in m.sigmas]
        tab_after = reestimate(fitted)
        fitted, tab_after = _refine_vertical_bias(fitted, tab_after, reestimate)
        # the sensor effect is now out of the readings: keep it out of the model fitted on them
        cands = [c for c in cands if not issubclass(c.effect_cls, MeasurementEffect)]
        res = before_after(table, vehicle, effects, cands, table_after=tab_after, **kw)
        res.added = list(names)
        for e in fitted:
            res.parameters[e.name] = parameter_entries(e, m.sigmas[e.name])
        res.fitted = FittedModel(res.fitted.vehicle, res.fitted.effects + EffectSet(fitted),
                                 {**res.fitted.sigmas, **{e.name: m.sigmas[e.name] for e in fitted}},
                                 res.fitted.t_end_s, res.fitted.at_start)
        return res
    return before_after(table, vehicle, effects, cands, **kw)
