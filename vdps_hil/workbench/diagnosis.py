"""``vdps diagnose`` as a function: recording + model vehicle -> :class:`Diagnosis`.

Steps (each in its own module): decode the ``/raw/`` topics and run the estimator
(``dataset``), identify the ten parameters and rank the effect candidates (``ranking``), the
residuals and the input-driven simulation error of the identified model (``residuals``,
``simulation_errors``), where it fails (``regimes``), optionally add effects and measure
before/after (``add``), optionally save the model (``model_file``). Only ``/raw/`` topics and
the model vehicle file are read (plus a ``--model`` file and user effect code the user names).

JSON (``Diagnosis.to_json``), the issue's keys::

    ranking         [{effect, explained_fraction, parameters {name: {value, sigma}}, plausible,
                      excited, group}]   (effects, best first)
    recommendation  effect name or null
    equivalent_to   names that explain the recommendation equally on this drive (or [])
    before, after   {residual_rms {equation: value}, simulation_error {horizon_s: {position_m,
                      yaw_deg, roll_deg, speed_mps}}}; after is null without --add
    workbench       everything else (identified parameters, equivalence groups, messages,
                      worst windows, regime bins, estimator NIS, timings)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import Effect
from vdps_hil.model.params import Vehicle
from vdps_hil.record.schemas import clean_json

from .add import PREDICTED_UNITS, AddResult, FittedModel, add_effects, cleaned_residuals, residual_change, rms_by_equation
from .added_params import added_parameter_lines, at_bound, not_fitted
from .dataset import DatasetConfig, DriveTable, load_drive, reestimator
from .fit_budget import FitSubset, add_window, fit_subset
from .memory import release_freed_memory
from .ranking.config import RankingConfig
from .ranking.results import Ranking
from .ranking.selection import rank
from .regimes import RegimeBins, Window, regime_bins, worst_windows
from .residuals import EQUATION_UNITS, EquationResiduals, compute_residuals
from .simulation_errors import SimErrors, simulation_errors

__all__ = ["Diagnosis", "diagnose"]


@dataclass
class Diagnosis:
    """Everything ``vdps diagnose`` found (module docstring)."""

    source: str
    vehicle: Vehicle
    model_effects: EffectSet
    table: DriveTable
    ranking: Ranking
    residuals: EquationResiduals
    windows: list[Window]
    regimes: dict[str, RegimeBins]
    sim: SimErrors | None
    before: dict
    add: AddResult | None = None
    timings: dict = field(default_factory=dict)
    saved_model: str | None = None
    cleaned: tuple | None = field(repr=False, default=None)
    """The identified model's cleaned residual (``add.cleaned_residuals``): (t_s, equation
    names, values); ``before["residual_rms"]`` without ``--add`` is its RMS."""
    fit_subset: FitSubset | None = field(repr=False, default=None)
    """The segments a long drive was fitted on (``fit_budget``), None when fitted whole."""

    def to_json(self) -> dict:
        rk = self.ranking
        ranking = []
        for e in rk.entries:
            ranking.append({"effect": e.effect, "explained_fraction": _num(e.explained_fraction),
                            "parameters": {k: {"value": _num(v), "sigma": _num(s)} for k, (v, s) in e.parameters.items()},
                            "plausible": bool(e.plausible), "excited": bool(e.excited), "group": list(e.group)})
        extra = {"source": self.source, "vehicle": self.vehicle.name,
                 "model_effects": [{"name": e.name, "params": e.params} for e in self.model_effects],
                 "messages": list(rk.messages),
                 "ranking_details": [e.to_json() for e in rk.entries],
                 "identified_parameters": [e.to_json() for e in rk.parameters],
                 "groups": rk.groups, "selected": list(rk.selected), "n_eff": rk.n_eff,
                 "worst_windows": [w.to_json() for w in self.windows],
                 "regimes": {k: v.to_json() for k, v in self.regimes.items()},
                 "estimator_nis": _nis(self.table), "sensor_set": clean_json(dict(self.table.sensors)),
                 "duration_s": self.table.duration_s,
                 "timings_s": dict(self.timings), "saved_model": self.saved_model,
                 "simulation_notes": self.simulation_notes()}
        if self.table.rls is not None:  # the identifier's outcome on the drive (``ranking.rls_check``)
            extra["identifier"] = self.table.rls.to_json()
        if self.add is not None:
            extra["added"] = self.add.to_json()
        if self.fit_subset is not None:  # only a drive longer than the row budget has the key
            extra["fit_subset"] = self.fit_subset.to_json()
        return {"ranking": ranking, "recommendation": rk.recommendation, "equivalent_to": list(rk.equivalent_to),
                "before": self.before, "after": self.add.after if self.add is not None else None,
                "workbench": extra}

    def summary_lines(self) -> list[str]:
        """The human summary (vehicle-dynamics words)."""
        from .words import EFFECT_LABELS, describe_entry

        rk = self.ranking
        out = [f"{self.source}: {self.table.duration_s:.1f} s of drive, {len(self.residuals.t_s)} rows, "
               f"model {self.vehicle.name}" + (f" + {', '.join(self.model_effects.names)}" if len(self.model_effects) else "")]
        out += rk.messages
        out.append("identified parameters (the workbench's fit, checked against the identifier):")
        for p in rk.parameters:
            out.append("  " + describe_entry(rk, p).split(";")[0])
        out.append("candidates (held-out explained fraction, noise-weighted):")
        for e in rk.entries:
            tag = "*" if e.selected else " "
            ef = e.explained_fraction
            out.append(f" {tag}{EFFECT_LABELS.get(e.effect, e.effect):38s} {100 * ef:6.1f} %"
                       + ("" if e.excited else "  (not excited)") + ("" if e.plausible else "  (implausible)"))
        if self.windows:
            out.append("worst windows: " + "; ".join(f"{w.t_start_s:.1f}-{w.t_end_s:.1f} s ({w.equation})"
                                                      for w in self.windows))
        if self.add is not None:
            out += _added_lines(self.add)
        out += _before_after_lines(self.before, self.add.after if self.add else None)
        if self.add is not None:
            out += _worse_lines(self.add)
        out += self.simulation_notes()
        if self.saved_model:
            out.append(f"model written to {self.saved_model}")
        return out


    def simulation_notes(self) -> list[str]:
        """Why a simulation error is missing or partial (missing inputs, diverged predictions)."""
        sims = [self.sim] if self.add is None else [self.add.sim_before, self.add.sim_after]
        out = []
        for label, sim in zip(("", "before: ", "after: ")[0 if self.add is None else 1:], sims):
            out += [label + n for n in (sim.notes() if sim is not None else [])]
        return out


def _num(v):
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _nis(table: DriveTable) -> dict:
    out = {}
    for kind, t in table.innovations.items():
        ok = t["accepted"] & np.isfinite(t["nis"])
        if ok.any():
            out[kind] = {"mean_nis": float(np.mean(t["nis"][ok])), "dof": float(np.mean(t["dof"][ok])),
                         "n": int(ok.sum())}
    return out


def _before_after_lines(before: dict, after: dict | None) -> list[str]:
    out = []
    rb = before.get("residual_rms", {})
    ra = (after or {}).get("residual_rms", {})
    changes = residual_change(before, after)
    if rb:
        out.append("residual RMS per equation" + (" (before -> after)" if after else "") + ":")
        for eq, v in rb.items():
            if v is None:
                continue
            unit = EQUATION_UNITS.get(eq, "")
            a = ra.get(eq)
            c = changes.get(eq)
            change = f"  ({100 * c:+.0f} %)" if c is not None else ""
            out.append(f"  {eq:14s} {v:10.4g}" + (f" -> {a:10.4g}" if a is not None else "") + f" {unit}" + change)
    sb = before.get("simulation_error", {})
    sa = (after or {}).get("simulation_error", {})
    if sb:
        out.append("simulation error (input-driven predictor, RMS over starts)" + (" before -> after" if after else "") + ":")
        for h, d in sb.items():
            a = sa.get(h, {})
            parts = []
            for k, unit in PREDICTED_UNITS.items():
                s = f"{k.split('_')[0]} {_sim_value(d, k, unit)}"
                if a:
                    s += f" -> {_sim_value(a, k, unit)}"
                parts.append(s)
            out.append(f"  {h:>4s} s  " + ", ".join(parts) + _diverged_phrase(d, a))
    return out


def _added_lines(add) -> list[str]:
    """The added effects' parameters with their status (``added_params``)."""
    from .words import EFFECT_LABELS

    return added_parameter_lines(add.parameters, EFFECT_LABELS)


def _worse_lines(add) -> list[str]:
    """A line per equation, and per prediction horizon, the added effects made worse
    (``AddResult.worse``, ``AddResult.worse_predictions``)."""
    from .words import EFFECT_LABELS

    names = ", ".join(EFFECT_LABELS.get(a, a) for a in add.added)
    rb, ra = add.before["residual_rms"], add.after["residual_rms"]
    out = [f"worse with {names}: the {eq} residual rose {100 * c:.0f} % ({rb[eq]:.4g} -> {ra[eq]:.4g} "
           f"{EQUATION_UNITS.get(eq, '')})" for eq, c in add.worse().items()]
    sb, sa = add.before.get("simulation_error", {}), add.after.get("simulation_error", {})
    for h, qs in add.worse_predictions().items():
        out.append(f"worse with {names}: the held-out {h} s prediction error rose: " + ", ".join(
            f"{q.split('_')[0]} {sb[h][q]:.3g} -> {sa[h][q]:.3g} {PREDICTED_UNITS[q]} (+{100 * c:.0f} %)"
            for q, c in qs.items()))
    return out


def _sim_value(d: dict, k: str, unit: str) -> str:
    """One simulation-error figure: the number, or why there is none (never ``nan``)."""
    v = _num(d.get(k))
    if v is not None:
        return f"{v:.3f} {unit}"
    return "diverged" if d.get("n_diverged") else "none"


def _diverged_phrase(d: dict, a: dict) -> str:
    parts = [f"{w}{x['n_diverged']} of {x['n'] + x['n_diverged']} predictions diverged"
             for x, w in ((d, "" if not a else "before: "), (a, "after: ")) if x and x.get("n_diverged")]
    return ("  (" + "; ".join(parts) + ", left out)") if parts else ""


def _save_fitted(target, path, add, add_res, base: FittedModel, rk: Ranking) -> str:
    """``--save-model``: the fitted model (with the added effects when there are any); an added
    parameter at a bound keeps the value the model used, without a sigma, and the file's source
    line names it as not identified (``added_params``)."""
    from .model_file import save_model as _save

    fm = add_res.fitted if add_res is not None else base
    sig = {p.param if hasattr(p, "param") else next(iter(p.parameters)): next(iter(p.parameters.values()))[1]
           for p in rk.parameters}
    src = f"vdps diagnose {Path(path).name}" + "".join(f" --add {a}" for a in add)
    esig = fm.sigmas
    bound = at_bound(add_res.parameters) if add_res is not None else []
    dropped = not_fitted(add_res.parameters) if add_res is not None else []
    unmoved = [ek for ek in dropped if ek not in bound]
    if dropped:
        esig = {e: {k: v for k, v in ps.items() if (e, k) not in dropped} for e, ps in fm.sigmas.items()}
    if bound:
        src += "; at bound, not identified: " + ", ".join(f"{e}.{k}" for e, k in bound)
    if unmoved:
        src += "; at the generic prior, not fitted: " + ", ".join(f"{e}.{k}" for e, k in unmoved)
    return str(_save(target, fm.vehicle, fm.effects, sigmas=sig, effect_sigmas=esig, source=src))


def _rank_in_budget(table: DriveTable, vehicle: Vehicle, model_effects: EffectSet, user_effects, ranking_config):
    """The ranking on the drive, or on its row-budget segments (``fit_budget``); its fitted
    parameters carry the identifier's verdict (``table.rls``, ``ranking.rls_check``): (ranking,
    config, the fit subset or None, the table fitted)."""
    cfg = ranking_config or RankingConfig()
    sub = fit_subset(table, cfg.max_fit_s, cfg.fit_segment_s)
    fit_table = sub.table if sub is not None else table
    rk = rank(fit_table, vehicle, model_effects, user_effects=user_effects, config=ranking_config)
    if sub is not None:
        rk.messages = [sub.message()] + rk.messages
    return rk, cfg, sub, fit_table


def diagnose(path: str | Path, vehicle: Vehicle, *, model: str | Path | None = None, dbc=None, signalmap=None,
             add: Sequence[str] = (), user_effects: Sequence[type[Effect]] = (), save_model: str | Path | None = None,
             dataset_config: DatasetConfig | None = None, ranking_config: RankingConfig | None = None,
             with_simulation: bool = True, progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Run the whole diagnosis (module docstring)."""
    say = progress or (lambda s: None)
    tm = {}
    t0 = time.perf_counter()
    model_effects = EffectSet()
    if model is not None:
        from .model_file import load_model

        vehicle, model_effects, _ = load_model(model, vehicle, user_effects)
    say("decoding /raw/ topics and running the estimator and the identifier")
    ds = dataset_config or DatasetConfig()
    table = load_drive(path, vehicle, dbc=dbc, signalmap=signalmap, config=replace(ds, identify=True))
    release_freed_memory()  # each stage's freed arrays back to the OS (``memory``): the peak is the largest stage's
    tm["decode_estimator"] = time.perf_counter() - t0
    say(f"{table.counters.get('samples', 0)} samples, {len(table)} rows")
    say("identifying the model and ranking the candidates")
    t1 = time.perf_counter()
    rk, cfg, sub, fit_table = _rank_in_budget(table, vehicle, model_effects, user_effects, ranking_config)
    release_freed_memory()
    tm["ranking"] = time.perf_counter() - t1
    base = FittedModel(rk.base_vehicle, model_effects)
    res = compute_residuals(table, base.vehicle, base.effects)
    wins = worst_windows(res)
    regs = regime_bins(table, res)
    release_freed_memory()
    t_c, rows_c, names_c, vals_c = cleaned_residuals(fit_table, base, vehicle, ranking_config)
    if sub is not None:
        t_c = sub.drive_times(rows_c)  # the segments' rows at their times in the drive
    del fit_table
    release_freed_memory()
    cleaned = (t_c, names_c, vals_c)
    before = {"residual_rms": rms_by_equation(names_c, vals_c)}
    sim = None
    if with_simulation and not add:
        say("simulation error of the identified model")
        t1 = time.perf_counter()
        sim = simulation_errors(table, base.vehicle, base.effects)
        if not sim.missing_inputs:  # else no figures, only the note naming the missing inputs
            before["simulation_error"] = sim.summary()
        tm["simulation"] = time.perf_counter() - t1
    add_res = None
    if add:
        say(f"adding {', '.join(add)} and re-identifying")
        t1 = time.perf_counter()
        win = add_window(table, cfg.max_fit_s)
        if win is not None:
            rk.messages.append(win.message())
        cut = win.cut if win is not None else (lambda tab: tab)

        again = reestimator(path, vehicle, dbc=dbc, signalmap=signalmap, config=ds)

        def reestimate(meas_effects):
            say("re-running the estimator with the sensor effects taken out of the IMU readings")
            return cut(again(meas_effects))

        add_res = add_effects(cut(table), vehicle, model_effects, list(add),
                              user_effects=user_effects,
                              reestimate=reestimate, config=ranking_config, with_simulation=with_simulation,
                              progress=say)
        before = add_res.before
        tm["add"] = time.perf_counter() - t1
    saved = None
    if save_model is not None:
        saved = _save_fitted(save_model, path, add, add_res, base, rk)
    tm["total"] = time.perf_counter() - t0
    return Diagnosis(str(path), vehicle, model_effects, table, rk, res, wins, regs, sim, before, add_res, tm, saved,
                     cleaned, sub)
