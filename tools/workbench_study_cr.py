#!/usr/bin/env python3
"""Issue 18's acceptance on the independent truth: the model workbench on drives of CommonRoad's
multibody model (``--truth commonroad-mb:N``, sets 1 and 3; the model file ``crN-model``).

Per parameter set and seed (each drive simulated, then diagnosed from its /raw/ topics and the
model file only, ``experiments.workbench_study.run_job``):

* ``saturation``: ``cr-circle-ramp`` with nothing injected, the truth's Pacejka tires saturating
  (a_y ramped to 7.5 m/s^2); a hit is tire saturation (``magic_formula_tire``) recommended, named
  equivalent, or in the top group with the recommendation (``is_hit``);
* ``null``: the four CommonRoad maneuvers with nothing injected; counted: runs where a *sensor*
  effect (a measurement effect: ``imu_bias``, ``imu_lever_arm``, ``steering_offset``) is
  recommended or selected;
* ``imu_bias`` (on ``cr-sine-accel``) and ``imu_lever_arm`` (0.5 m forward, on
  ``cr-lane-change``) injected into the sensor models: hit as above.
* ``add``: ``vdps diagnose --add magic_formula_tire`` on the saturation drive and on the same
  maneuver and seed of ``commonroad-mb:N:linear-lateral`` (the truth with its tires' lateral law
  linear: no saturation). The 2 s prediction error (position, yaw; held-out blocks, the model
  refitted on the data before each) *attributable* to saturation is the saturation drive's
  error minus the linear drive's, both of the base model (as "hidden minus nothing hidden" on our
  own simulator, ``tests/test_add.py``); the goal is that adding the effect removes >= 50 % of it.
  The linear drive is also a null check: saturation recommended there is counted.

The issue's goals: saturation >= 90 % of seeds; no sensor effect on >= 95 % of the null runs; each
injected sensor effect >= 90 %. Rates with Wilson 95 % intervals.

Last measured, ``add`` (2026-12-07, ``--sets 1 3 --seeds 10 --first-seed 1000 --kinds add --jobs 2
--cache DIR``, 2065 s wall, quiet 2-core machine): set 1 10/10 seeds with >= 50 % of the
attributable 2 s position and yaw errors removed (pooled 132 % / 163 %); set 3 0/10 and 3/10, every
prediction worse with the effect (README, "Measured against the attributable part"). After the
fit's steps had to lower the objective (``workbench.add._descend``), seeds 1000-1009: set 1
10/10 and 10/10 (pooled 150 % / 199 %), set 3 8/10 and 8/10 (142 % / 146 %; the two misses have
nothing attributable). Seeds 1010-1019, the same command: set 1 10/10 and 10/10 (143 % / 180 %;
the peak friction at its 1.6 bound on all ten), set 3 5/10 and 6/10 (119 % / 126 %), every miss a
seed whose linear-tire twin predicts worse than the saturating drive (nothing attributable).

Usage::

    .venv/bin/python tools/workbench_study_cr.py [--sets 1 3] [--seeds 3] [--first-seed 1000]
                                                  [--jobs 1] [--runs FILE.jsonl] [--json FILE]
                                                  [--kinds saturation null injected] [--cache DIR]
                                                  [--model-effect SPEC ...]

``--model-effect`` gives the model an effect for every run (ranked against and added to): the
README's load-proportional tire split under ``--add`` was measured with
``--model-effect load_dependent_cornering_stiffness:load_slope=1,load_degression=0``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import as_completed

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # workbench_study.py, also under -P

from vdps_hil.app.children import spawned_pool  # noqa: E402
from vdps_hil.experiments.ident_study import CR_SCENARIOS  # noqa: E402
from vdps_hil.experiments.seeds import refused_by_tool  # noqa: E402
from vdps_hil.experiments.workbench_study import model_effect_set, run_job, wilson_interval  # noqa: E402
from vdps_hil.model.effects.base import MeasurementEffect  # noqa: E402
from vdps_hil.model.effects.registry import REGISTRY  # noqa: E402
from vdps_hil.workbench.added_params import added_entries, at_bound, parameter_entries  # noqa: E402

from workbench_study import _load_runs  # noqa: E402  (tools/, inserted above)

SENSOR_EFFECTS = tuple(n for n in REGISTRY.names() if issubclass(REGISTRY[n], MeasurementEffect))
INJECTED = {"imu_bias": ("shipped:cr-sine-accel", "imu_bias"),
            "imu_lever_arm": ("shipped:cr-lane-change", "imu_lever_arm:lever_x_m=0.5")}
"""Sensor effect -> (maneuver, spec injected into the sensor models)."""


def jobs_for(set_id: int, seed: int) -> list[dict]:
    truth = f"commonroad-mb:{set_id}"
    base = {"truth": truth, "seed": seed, "set": set_id}
    out = [dict(base, kind="saturation", maneuver="shipped:cr-circle-ramp", specs=[], effect="magic_formula_tire")]
    out += [dict(base, kind="null", maneuver=f"shipped:{m}", specs=[]) for m in CR_SCENARIOS if m != "cr-circle-ramp"]
    out += [dict(base, kind="injected", maneuver=man, specs=[spec], effect=eff) for eff, (man, spec) in INJECTED.items()]
    out += [dict(base, kind="add", maneuver="shipped:cr-circle-ramp", specs=[], effect="magic_formula_tire",
                 add="magic_formula_tire"),
            dict(base, kind="add-null", truth=f"{truth}:linear-lateral", maneuver="shipped:cr-circle-ramp", specs=[],
                 add="magic_formula_tire")]
    return out


ADD_HORIZON = "2"
"""The prediction horizon [s] of the ``add`` goal (the issue's 2 s prediction error)."""
ADD_QUANTITIES = ("position_m", "yaw_deg")


def add_figures(add: dict, null: dict) -> dict[str, dict[str, float]]:
    """Per quantity of :data:`ADD_QUANTITIES` at :data:`ADD_HORIZON`: the base model's error on
    the saturation drive (``before``) and on the linear drive (``null``), with the effect added
    (``after``), the attributable part ``before - null`` and the fraction of it removed
    ``(before - after) / (before - null)`` (NaN when nothing is attributable)."""
    out = {}
    for q in ADD_QUANTITIES:
        b = add["add_before"][ADD_HORIZON][q]
        a = add["add_after"][ADD_HORIZON][q]
        n = null["add_before"][ADD_HORIZON][q]
        att = b - n
        out[q] = {"before": b, "after": a, "null": n, "attributable": att,
                  "removed": (b - a) / att if att > 0 else float("nan")}
    return out


def _at_bound(run: dict) -> list[tuple[str, str]]:
    """The added parameters of an ``add`` run at a bound (``workbench.added_params``); a run
    recorded before the status existed is judged from its values and the effect's ranges."""
    params = {}
    for e, ps in added_entries(run.get("add_parameters") or {}):
        if e not in REGISTRY:
            continue
        if all("status" in d for d in ps.values()):
            params[e] = ps
        else:
            eff = REGISTRY[e](**{k: d["value"] for k, d in ps.items()})
            params[e] = parameter_entries(eff, {k: d["sigma"] for k, d in ps.items() if d.get("sigma") is not None})
    return at_bound(params)


def _key(job: dict) -> str:
    """A run's identity in a ``--runs`` file (the model's effects only when it has some, so the
    files written before ``--model-effect`` keep their keys)."""
    key = [job["kind"], job.get("effect"), job["maneuver"], job["truth"], int(job["seed"])]
    return json.dumps(key + ([list(job["model_effects"])] if job.get("model_effects") else []))


def sensor_named(run: dict) -> list[str]:
    """The sensor effects a run recommends or selects."""
    names = [run.get("recommendation")] + list(run.get("selected") or [])
    return sorted({n for n in names if n in SENSOR_EFFECTS})


def summary(runs: list[dict]) -> list[str]:
    lines = []

    def rate(label, k, n, goal):
        if not n:  # a kind this run did not include
            return
        lo, hi = wilson_interval(k, n)
        lines.append(f"{label:<44} {k:3d}/{n:<3d} {100 * k / max(n, 1):5.1f} %  Wilson95 {100 * lo:5.1f}-{100 * hi:5.1f} %"
                     f"  (goal {goal})")

    for set_id in sorted({r["set"] for r in runs}):
        rs = [r for r in runs if r["set"] == set_id]
        sat = [r for r in rs if r["kind"] == "saturation"]
        rate(f"cr{set_id}: tire saturation on cr-circle-ramp", sum(bool(r.get("hit")) for r in sat), len(sat), ">= 90 %")
        nulls = [r for r in rs if r["kind"] in ("null", "saturation")]
        rate(f"cr{set_id}: no sensor effect, nothing injected", sum(not sensor_named(r) for r in nulls), len(nulls),
             ">= 95 %")
        for eff in INJECTED:
            inj = [r for r in rs if r["kind"] == "injected" and r["effect"] == eff]
            rate(f"cr{set_id}: {eff} injected", sum(bool(r.get("hit")) for r in inj), len(inj), ">= 90 %")
        adds = {r["seed"]: r for r in rs if r["kind"] == "add" and "add_before" in r}
        linear = {r["seed"]: r for r in rs if r["kind"] == "add-null" and "add_before" in r}
        seeds = sorted(set(adds) & set(linear))
        if seeds:
            figs = {s: add_figures(adds[s], linear[s]) for s in seeds}
            for q in ADD_QUANTITIES:
                ok = sum(figs[s][q]["removed"] >= 0.5 for s in seeds)
                rate(f"cr{set_id}: --add takes >= 50 % off the {q.split('_')[0]}", ok, len(seeds), ">= 90 %")
                pos = [s for s in seeds if figs[s][q]["attributable"] > 0]
                lines.append(f"    of the {len(pos)} seeds with an attributable part: "
                             f"{sum(figs[s][q]['removed'] >= 0.5 for s in pos)} with >= 50 % removed")
                att = sum(figs[s][q]["attributable"] for s in pos)
                cut = sum(figs[s][q]["before"] - figs[s][q]["after"] for s in pos)
                lines.append(f"    pooled over the {len(pos)} seeds with an attributable part: {cut:.3g} of {att:.3g}"
                             f" removed ({100 * cut / att if att > 0 else float('nan'):.0f} %)")
                lines.append(f"    {q} at {ADD_HORIZON} s, per seed (before / null / after, removed): " + "; ".join(
                    f"{s}: {figs[s][q]['before']:.3g} / {figs[s][q]['null']:.3g} / {figs[s][q]['after']:.3g}, "
                    f"{100 * figs[s][q]['removed']:.0f} %" for s in seeds))
            bound = [s for s in seeds if _at_bound(adds[s])]
            lines.append(f"    --add's fitted parameters at a bound of their range (not identified) on {len(bound)} "
                         f"of {len(seeds)} seeds" + (f": {', '.join(str(s) for s in bound)}" if bound else ""))
            false_sat = sum(linear[s].get("recommendation") == "magic_formula_tire" for s in seeds)
            rate(f"cr{set_id}: no saturation recommended without it", len(seeds) - false_sat, len(seeds), ">= 95 %")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, nargs="+", default=[1, 3], choices=[1, 3])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--tuning", action="store_true",
                    help="allow tuning seeds (experiments.seeds): a tuning run, not an acceptance figure")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--runs", default=None, help="JSON-lines file of finished runs: append, skip what is there")
    ap.add_argument("--json", default=None)
    ap.add_argument("--kinds", nargs="+", default=["saturation", "null", "injected", "add"],
                    choices=["saturation", "null", "injected", "add"], help="which runs of each seed (default all)")
    ap.add_argument("--cache", default=None, help="directory of simulated drives: kept and reused, so a re-run "
                    "after a workbench change diagnoses the same files")
    ap.add_argument("--model-effect", action="append", default=[], metavar="SPEC",
                    help="an effect the model carries (NAME or NAME:param=value,...; repeatable), e.g. "
                    "load_dependent_cornering_stiffness:load_slope=1,load_degression=0 (each tire's cornering "
                    "stiffness proportional to its load, as CommonRoad's tires)")
    a = ap.parse_args(argv)
    try:
        model_effect_set(a.model_effect)
    except ValueError as e:
        print(f"workbench_study_cr: {e}", file=sys.stderr)
        return 2
    if refused_by_tool(range(a.first_seed, a.first_seed + a.seeds), "workbench_study_cr", a.tuning):  # experiments.seeds
        return 2
    extra = {**({"cache": a.cache} if a.cache else {}), **({"model_effects": a.model_effect} if a.model_effect else {})}
    jobs = [dict(j, **extra)
            for seed in range(a.first_seed, a.first_seed + a.seeds) for s in a.sets for j in jobs_for(s, seed)
            if j["kind"] in a.kinds or (j["kind"] == "add-null" and "add" in a.kinds)]
    done = _load_runs(a.runs, _key) if a.runs else {}
    runs = [done[_key(j)] for j in jobs if _key(j) in done]
    todo = [j for j in jobs if _key(j) not in done]
    t0 = time.perf_counter()
    with spawned_pool(max(1, a.jobs)) as ex:
        for f in as_completed([ex.submit(run_job, j) for j in todo]):
            r = f.result()
            runs.append(r)
            if a.runs:
                with open(a.runs, "a") as fh:
                    fh.write(json.dumps(r, default=str) + "\n")
            print(f"  cr{r['set']} seed {r['seed']} {r['kind']:10s} {r['maneuver']:24s} {r.get('effect') or '':18s} "
                  f"rec {r.get('recommendation')} hit {r.get('hit')} sensor {sensor_named(r)} "
                  f"{r.get('error', '')} ({r.get('wall_s', 0):.0f} s)", flush=True)
    print("\n".join(summary(runs)))
    print(f"{len(runs)} runs ({len(todo)} new, {time.perf_counter() - t0:.0f} s wall)")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(runs, fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
