"""Lead time vs false alarms of the rollover warning over a set of near-miss maneuvers.

Families of maneuvers (truth simulator; the predictor is initialised from the truth state, with
the TRUE parameters on the model file, held inputs, the configured cadence and latency):

* ``fishhook``: ``fishhook-suv`` with the steering amplitude scaled by k (k = 1: the rollover
  scenario, 154 deg); small k are near misses (two-wheel lift without rollover, or nothing).
* ``torque``: ``paper-rollover`` (sedan) with the right-hand wheels' torque T2 = T3 varied.

For each run it prints the truth outcome (tip-up / point of no return / spin-out / stable), the
earliest predicted point of no return, and, for the configured policy, the first warning, the
lead time to the truth PONR and to the tip-up, or a false alarm. Then the curve: for warning
times T_w = reaction + margin from 0.25 s to 3 s (the stored predictions are replayed through
the node with each policy), the number of rollover runs warned, their minimum / median lead time
and the number of non-rollover runs with a warning (false alarms).

Usage::

    .venv/bin/python tools/warning_curve.py [--family fishhook|torque|all] [--effects NAME ...]
                                            [--json out.json]

``--effects`` replaces the predictor's effect set (default: the config's, the paper's
``linear_tire``), e.g. ``--effects magic_formula_tire`` (effect defaults, peak friction 1.0: NOT
the truth's 1.1) to see what a saturating tire model would change.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.experiments.scoring import evaluate_warning_frames  # noqa: E402
from vdps_hil.experiments.truth_init import initial_state_from_truth  # noqa: E402
from vdps_hil.model.core import Inputs  # noqa: E402
from vdps_hil.model.effects import effects_from_names  # noqa: E402
from vdps_hil.model.params import load_vehicle  # noqa: E402
from vdps_hil.model.rollover import assess  # noqa: E402
from vdps_hil.prediction.config import load_predictor_config  # noqa: E402
from vdps_hil.prediction.predictor import Predictor  # noqa: E402
from vdps_hil.prediction.warning import (WarningChain, WarningPolicy, load_warning_config,  # noqa: E402
                                         replay_assessments)
from vdps_hil.sim.scenarios import load_scenario  # noqa: E402
from vdps_hil.sim.simulator import Simulator  # noqa: E402

FISHHOOK_SCALES = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1)
TORQUES_NM = (200.0, 400.0, 600.0, 800.0, 1000.0, 1200.0)
WARNING_TIMES_S = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0)


def fishhook_runs():
    sc = load_scenario("fishhook-suv")
    sched = sc.schedule_function()
    for k in FISHHOOK_SCALES:
        def src(t, x, k=k):
            u = sched(t)
            return Inputs(k * u.steer_wheel_angle_rad, u.wheel_torque_nm, u.brake_torque_nm)
        yield f"fishhook x{k:.2f}", sc, src, "suv-model"


def torque_runs():
    sc = load_scenario("paper-rollover")
    sched = sc.schedule_function()
    for tq in TORQUES_NM:
        def src(t, x, tq=tq):
            u = sched(t)
            if t < 10.25:
                return u
            w = u.wheel_torque_nm
            return Inputs(u.steer_wheel_angle_rad, (w[0], tq, tq, w[3]), u.brake_torque_nm)
        yield f"T2=T3={tq:.0f} N m", sc, src, "sedan-model"


def run_one(label, sc, src, model, effects, policy, node_cfg):
    sim = Simulator(scenario=sc, inputs=src)
    sim.run()
    cfg = load_predictor_config()
    pred = Predictor(load_vehicle(model).with_params(**sc.vehicle.params.as_dict()), cfg, effects)
    chain = WarningChain(pred, policy, node_cfg)
    for s in sim.truth:
        chain.handle(s["t_ns"], initial_state_from_truth(s))
    o = evaluate_warning_frames(chain.frames, sim.events)
    a = assess(sim)
    pn = [x.t0_ns / 1e9 + x.time_to_point_of_no_return_s for x in chain.assessments
          if x.time_to_point_of_no_return_s is not None]
    return {"label": label, "outcome": a.outcome, "truth_tip_up_t_s": a.tip_up_t_s,
            "truth_ponr_t_s": a.point_of_no_return_t_s, "max_abs_ltr": a.max_abs_ltr,
            "first_predicted_ponr_at_t_s": min((x.t0_ns / 1e9 for x in chain.assessments
                                                if x.time_to_point_of_no_return_s is not None), default=math.nan),
            "earliest_predicted_ponr_t_s": min(pn, default=math.nan),
            "outcome_default": o, "assessments": chain.assessments, "times_ns": [s["t_ns"] for s in sim.truth],
            "events": sim.events}


def fmt(v, w=7, p=2):
    return f"{v:{w}.{p}f}" if isinstance(v, float) and not math.isnan(v) else f"{'-':>{w}s}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", choices=("fishhook", "torque", "all"), default="all")
    ap.add_argument("--effects", nargs="*", default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    policy, node_cfg = load_warning_config()
    effects = effects_from_names(args.effects) if args.effects else None
    gens = {"fishhook": fishhook_runs, "torque": torque_runs}
    fams = ("fishhook", "torque") if args.family == "all" else (args.family,)
    runs = []
    t_start = time.perf_counter()
    print(f"policy: T_w = {policy.warning_time_s:.2f} s (reaction {policy.reaction_time_s} + margin "
          f"{policy.margin_s}), imminent {policy.imminent_time_s} s, hold {policy.hold_s} s; predictor effects: "
          f"{', '.join(effects.names) if effects else ', '.join(load_predictor_config().effects)}")
    print(f"\n{'maneuver':20s} {'truth':>9s} {'tip-up':>7s} {'PONR':>7s} {'max|LTR|':>8s} {'pred@':>7s} "
          f"{'warn@':>7s} {'lead':>7s} {'lead tip':>8s} {'lead side':>9s} {'false':>5s}")
    for fam in fams:
        for label, sc, src, model in gens[fam]():
            r = run_one(label, sc, src, model, effects, policy, node_cfg)
            r["family"] = fam
            runs.append(r)
            o = r["outcome_default"]
            print(f"{label:20s} {r['outcome']:>9s} {fmt(r['truth_tip_up_t_s'])} {fmt(r['truth_ponr_t_s'])} "
                  f"{fmt(r['max_abs_ltr'], 8)} {fmt(r['first_predicted_ponr_at_t_s'])} {fmt(o.first_warning_t_s)} "
                  f"{fmt(o.lead_time_s)} {fmt(o.lead_to_tip_up_s, 8)} {fmt(o.lead_time_matched_side_s, 9)} "
                  f"{o.false_alarms:5d}")
    print(f"\n(pred@: first prediction start that foresaw a PONR; warn@: first valid frame at level >= warning; "
          f"{time.perf_counter() - t_start:.0f} s)")
    print(f"\nlead time vs false alarms ({len(runs)} runs, "
          f"{sum(1 for r in runs if not math.isnan(r['truth_ponr_t_s']))} with a truth point of no return)")
    print(f"{'T_w s':>6s} {'warned':>7s} {'lead>=1s':>8s} {'min lead':>8s} {'median':>7s} {'false alarms':>12s} "
          f"{'(runs)':>7s}")
    curve = []
    for tw in WARNING_TIMES_S:
        pol = WarningPolicy(reaction_time_s=tw, margin_s=0.0, imminent_time_s=min(policy.imminent_time_s, tw),
                            caution_ltr=policy.caution_ltr, hold_s=policy.hold_s)
        leads, false_runs, false_eps, warned, n_roll = [], 0, 0, 0, 0
        for r in runs:
            frames = replay_assessments(r["assessments"], r["times_ns"], pol, node_cfg)
            o = evaluate_warning_frames(frames, r["events"])
            if not math.isnan(r["truth_ponr_t_s"]):
                n_roll += 1
                if not math.isnan(o.lead_time_s):
                    warned += 1
                    leads.append(o.lead_time_s)
            false_eps += o.false_alarms
            false_runs += 1 if o.false_alarms else 0
        row = {"warning_time_s": tw, "rollover_runs": n_roll, "warned": warned,
               "lead_ge_1s": sum(1 for x in leads if x >= 1.0),
               "min_lead_s": min(leads, default=math.nan),
               "median_lead_s": statistics.median(leads) if leads else math.nan,
               "false_alarm_runs": false_runs, "false_alarm_episodes": false_eps}
        curve.append(row)
        print(f"{tw:6.2f} {warned:3d}/{n_roll:<3d} {row['lead_ge_1s']:8d} {fmt(row['min_lead_s'], 8)} "
              f"{fmt(row['median_lead_s'])} {false_eps:12d} {false_runs:7d}")
    if args.json:
        out = {"policy": dataclasses.asdict(policy), "runs": [
            {k: (v.to_json() if k == "outcome_default" else v) for k, v in r.items()
             if k not in ("assessments", "times_ns")} for r in runs], "curve": curve}
        args.json.write_text(json.dumps(out, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
