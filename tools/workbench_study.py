#!/usr/bin/env python3
"""Hidden-effect study of the model workbench (issue 9): hit rates per effect with Wilson 95 %
intervals, the null rate with nothing hidden, detection probability against magnitude, and the
--add reductions of the attributable simulation error.

Each drive is simulated (``vdps_hil.experiments.workbench_study``: maneuver and magnitude per effect),
written to a temporary MCAP, and diagnosed from its /raw/ topics and the model vehicle file
only (the truth file is never passed to the workbench). A *hit* is the hidden effect recommended,
named by the recommendation as equivalent, or in the top equivalence group together with the
recommendation (``study.is_hit``; since 2026-12-02 a top group with nothing recommended is not a
hit: the hit rates measured before counted it and are overstated where that happened).

Usage::

    .venv/bin/python tools/workbench_study.py --seeds 20 --jobs 2 --json study.json
    .venv/bin/python tools/workbench_study.py --effects aero_drag,crosswind --seeds 5
    .venv/bin/python tools/workbench_study.py --magnitude aero_drag:cda_m2=0.1,0.2,0.35,0.7 --seeds 10
    .venv/bin/python tools/workbench_study.py --add --seeds 5     # --add reductions per effect
    .venv/bin/python tools/workbench_study.py --seeds 20 --jobs 1 --runs study.jsonl   # resumable
    .venv/bin/python tools/workbench_study.py --effects imu_bias --scenario shipped:sine-sweep --scenario shipped:lane-change-iso3888
    .venv/bin/python tools/workbench_study.py ... --runs after.jsonl --cache /tmp/drives   # the same drives again

``--runs FILE.jsonl`` makes the study incremental: every finished drive is appended to the file
as one JSON line, and a later call with the same file skips the drives already there (same kind,
effect, maneuver, seed, magnitude and --add); stop it at any time and call it again. The summary
is always over every matching run in the file, so a 20-seed study can be built up in pieces
(``--first-seed`` and ``--seeds`` select which seeds a call adds).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from concurrent.futures import as_completed

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from vdps_hil.app.children import spawned_pool  # noqa: E402
from vdps_hil.experiments.workbench_study import HIDDEN, MANEUVERS, run_job, wilson_interval  # noqa: E402
from vdps_hil.experiments.seeds import refused_by_tool  # noqa: E402


def _one(job: dict) -> dict:
    return run_job(job)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--tuning", action="store_true",
                    help="allow tuning seeds (experiments.seeds): a tuning run, not an acceptance figure")
    ap.add_argument("--effects", default=",".join(HIDDEN))
    ap.add_argument("--no-null", action="store_true", help="skip the nothing-hidden drives")
    ap.add_argument("--null-only", action="store_true", help="only the nothing-hidden drives (every study maneuver)")
    ap.add_argument("--magnitude", action="append", default=[],
                    help="EFFECT:param=v1,v2,...: detection probability against magnitude")
    ap.add_argument("--add", action="store_true", help="also run --add on hidden and null drives")
    ap.add_argument("--scenario", action="append", default=[],
                    help="shipped:NAME, a scenario of configs/scenarios with its own truth (e.g. shipped:sine-sweep, Magic "
                         "Formula tire): the --effects hidden on it instead of on their study maneuvers, and its "
                         "nothing-hidden drives; repeatable")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--json", default=None)
    ap.add_argument("--runs", default=None, help="JSON-lines file of finished runs: append, skip what is there")
    ap.add_argument("--summary-only", action="store_true", help="summarize the --runs file, run nothing")
    ap.add_argument("--cache", default=None,
                    help="directory of simulated drives: kept and reused (a drive is deterministic in its maneuver, "
                         "effects and seed), so a re-run after a workbench change only diagnoses")
    a = ap.parse_args(argv)
    if a.null_only and a.no_null:
        ap.error("--null-only and --no-null exclude each other")
    effects = [] if a.null_only else [e for e in a.effects.split(",") if e]
    if refused_by_tool(range(a.first_seed, a.first_seed + a.seeds), "workbench_study", a.tuning):  # experiments.seeds
        return 2
    seeds = list(range(a.first_seed, a.first_seed + a.seeds))
    jobs = []
    for eff in effects:
        man, spec = HIDDEN[eff]
        for m in a.scenario or [man]:
            for s in seeds:
                jobs.append({"kind": "hidden", "effect": eff, "maneuver": m, "specs": [spec], "seed": s,
                             "add": eff if a.add else None})
    if a.scenario and not a.no_null:
        jobs += [{"kind": "null", "effect": None, "maneuver": m, "specs": [], "seed": s, "add": None}
                 for m in a.scenario for s in seeds]
    elif not a.no_null:
        every = a.null_only or a.effects == ",".join(HIDDEN)
        mans = sorted(MANEUVERS) if every else sorted({HIDDEN[e][0] for e in effects})
        for m in mans:
            for s in seeds:
                null_eff = next((e for e in effects if HIDDEN[e][0] == m), None) if a.add else None
                jobs.append({"kind": "null", "effect": None, "maneuver": m, "specs": [], "seed": s,
                             "add": null_eff})
    for spec in a.magnitude:
        eff, _, rest = spec.partition(":")
        param, _, vals = rest.partition("=")
        for v in vals.split(","):
            for s in seeds:
                jobs.append({"kind": "magnitude", "effect": eff, "maneuver": HIDDEN[eff][0],
                             "specs": [f"{eff}:{param}={v}"], "seed": s, "magnitude": float(v), "add": None})
    t0 = time.perf_counter()
    done = _load_runs(a.runs) if a.runs else {}
    wanted = {_job_key(j) for j in jobs}
    results = [r for k, r in done.items() if k in wanted]
    # seed by seed, so a stopped study covers every effect and maneuver about equally
    todo = sorted((j for j in jobs if _job_key(j) not in done), key=lambda j: j["seed"])
    for j in todo:
        j["cache"] = a.cache
    if a.summary_only:
        todo = []
    if done:
        print(f"{len(results)} of {len(jobs)} drives already in {a.runs}; {len(todo)} to run", flush=True)
    with spawned_pool(a.jobs) as ex:
        futs = [ex.submit(_one, j) for j in todo]
        for f in as_completed(futs):
            r = f.result()
            results.append(r)
            if a.runs:
                with open(a.runs, "a") as fh:
                    fh.write(json.dumps(r, default=str) + "\n")
            tag = r.get("effect") or f"null/{r['maneuver']}"
            print(f"  {r['kind']:9s} {tag:36s} seed {r['seed']}: rec {r.get('recommendation')} "
                  f"hit {r.get('hit')} ({r.get('wall_s', 0):.1f} s)", flush=True)
    summary = summarize(results)
    print_summary(summary)
    print(f"wall time {time.perf_counter() - t0:.0f} s for {len(todo)} new drives ({len(results)} in the summary)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"summary": summary, "runs": results}, f, indent=1, default=str)
    return 0


def _job_key(job: dict) -> str:
    return json.dumps([job["kind"], job.get("effect"), job["maneuver"], int(job["seed"]), job.get("magnitude"),
                       job.get("add")])


def _load_runs(path: str, key=None) -> dict[str, dict]:
    """Finished runs of an earlier call by ``key(run)`` (default ``_job_key``; a torn last line,
    from a stopped run, is ignored)."""
    key = key or _job_key
    out: dict[str, dict] = {}
    if not os.path.exists(path):
        return out
    with open(path) as fh:
        for line in fh:
            try:
                r = json.loads(line)
            except ValueError:
                continue
            out[key(r)] = r
    return out


def _label(r: dict) -> str:
    """A hidden run's row in the summary: the effect, with ``@maneuver`` when not on its study maneuver."""
    return r["effect"] if r["maneuver"] == HIDDEN[r["effect"]][0] else f"{r['effect']}@{r['maneuver']}"


def summarize(results: list[dict]) -> dict:
    out = {"hit_rate": {}, "null": {}, "magnitude": {}, "add": {}}
    for eff in sorted({_label(r) for r in results if r["kind"] == "hidden"}):
        rs = [r for r in results if r["kind"] == "hidden" and _label(r) == eff]
        k = sum(1 for r in rs if r.get("hit"))
        lo, hi = wilson_interval(k, len(rs))
        out["hit_rate"][eff] = {"hits": k, "n": len(rs), "rate": k / len(rs), "wilson95": [lo, hi],
                                "recommended": sum(1 for r in rs if r.get("recommendation") == rs[0]["effect"])}
    nulls = [r for r in results if r["kind"] == "null"]
    if nulls:
        k = sum(1 for r in nulls if r.get("recommendation") is None)
        lo, hi = wilson_interval(k, len(nulls))
        false = {}
        for r in nulls:
            if r.get("recommendation"):
                false[r["recommendation"]] = false.get(r["recommendation"], 0) + 1
        out["null"] = {"null_recommendations": k, "n": len(nulls), "rate": k / len(nulls), "wilson95": [lo, hi],
                       "false_recommendations": false,
                       "per_maneuver": {m: sum(1 for r in nulls if r["maneuver"] == m and r.get("recommendation") is None)
                                        for m in sorted({r["maneuver"] for r in nulls})}}
    for eff in sorted({r["effect"] for r in results if r["kind"] == "magnitude"}):
        curve = {}
        for r in results:
            if r["kind"] == "magnitude" and r["effect"] == eff:
                c = curve.setdefault(r["magnitude"], [0, 0])
                c[0] += 1 if r.get("hit") else 0
                c[1] += 1
        out["magnitude"][eff] = {str(m): {"detected": c[0], "n": c[1], "rate": c[0] / c[1],
                                          "wilson95": list(wilson_interval(c[0], c[1]))} for m, c in sorted(curve.items())}
    for eff in sorted({r["effect"] for r in results if r["kind"] == "hidden" and r.get("add_before")}):
        rs = [r for r in results if r["kind"] == "hidden" and r["effect"] == eff and r.get("add_before")]
        red = {}
        for h in ("0.5", "1", "2"):
            b = [r["add_before"][h]["position_m"] for r in rs if r["add_before"].get(h)]
            af = [r["add_after"][h]["position_m"] for r in rs if r["add_after"].get(h)]
            if b and af:
                red[h] = {"before_position_m": sum(b) / len(b), "after_position_m": sum(af) / len(af)}
        out["add"][eff] = red
    return out


def print_summary(s: dict) -> None:
    print("\nhit rate per effect (hidden effect recommended, named equivalent, or in the top group with the recommendation):")
    for eff, d in s["hit_rate"].items():
        print(f"  {eff:36s} {d['hits']:3d}/{d['n']:<3d} = {100 * d['rate']:5.1f} %  Wilson 95 % "
              f"[{100 * d['wilson95'][0]:5.1f}, {100 * d['wilson95'][1]:5.1f}]  (recommended {d['recommended']})")
    if s["null"]:
        n = s["null"]
        print(f"null (nothing hidden): recommendation null in {n['null_recommendations']}/{n['n']} = "
              f"{100 * n['rate']:.1f} %  Wilson 95 % [{100 * n['wilson95'][0]:.1f}, {100 * n['wilson95'][1]:.1f}]"
              f"  false: {n['false_recommendations']}")
    for eff, curve in s["magnitude"].items():
        print(f"detection probability of {eff} against magnitude:")
        for m, d in curve.items():
            print(f"  {m:>8s}: {d['detected']}/{d['n']} = {100 * d['rate']:.0f} %  [{100 * d['wilson95'][0]:.0f}, "
                  f"{100 * d['wilson95'][1]:.0f}]")
    for eff, d in s["add"].items():
        print(f"--add {eff}: " + ", ".join(f"{h} s {v['before_position_m']:.3f} -> {v['after_position_m']:.3f} m"
                                        for h, v in d.items()))


if __name__ == "__main__":
    raise SystemExit(main())
