"""Benchmark of the predictor: time of one prediction over the configured horizon, and the
accuracy cost of the integrator/step against the explicit RK2 reference at 1 ms.

For each case (a scenario, a start time t0, the truth-initialised state and the TRUE
parameters on the model file) it runs

* the reference: explicit Heun (RK2) at 1 ms (the truth simulator's integrator and step);
* the candidates: ROS2 (linearly implicit wheel spin, see ``vdps_hil.prediction.predictor``)
  at several steps and Jacobian refresh intervals, and the configured default;

* the configured default on the generic core path (``Predictor(..., fast=False)``: every step
  calls ``Model.f``, the wheel-spin Jacobian by forward difference), the implementation before
  the specialised reduced core (:mod:`vdps_hil.model.reduced`) and the reference it is checked
  against,

and prints per candidate: the CPU time (``time.process_time``) of one prediction, median and
best of ``--repeat``, f-evaluations, and the largest differences to the reference over the common
span (position [m], road-relative angles [deg]) and of the predicted point-of-no-return time [s].
The last line of each case compares the configured (fast) path with the generic one.

Usage::

    .venv/bin/python tools/bench_predictor.py [--repeat 15] [--json out.json]

First bar: <= 20 ms for a 5 s prediction; goal 5 ms. Measured (CPU time, best of 15, Python
3.11, shared 2-core VM at load average 5-6; 5 s horizon, 500 steps)::

                                    left turn (Fig 8)   T2 = T3 = 1000 N m   fishhook-suv (to PONR)
    generic core path (Model.f)     15.0 ms (1251 f)    14.7 ms              2.8 ms
    configured (reduced core)        7.3 ms (1001 f)     7.3 ms              1.4 ms
    configured vs generic           2e-14 m, 2e-13 deg  1e-13 m, 2e-13 deg   5e-14 deg, same PONR

(the code before this change: 14.6 ms for the left turn at load 0.3; the generic path here
already has the RolloverMonitor early exit of this change.)
The 5 ms goal was not met in pure Python: one evaluation of the reduced core cost ~4.2 us
(1000 per prediction, ~4.2 ms), the ROS2 bookkeeping ~2 us per step. Since issue 19 the whole
loop is one compiled call (:mod:`vdps_hil.prediction.integration_kernel`): 0.64 ms for the left
turn against 68 ms with ``VDPS_JIT=0``, measured side by side by ``tools/bench_jit.py`` (README).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.experiments.truth_init import initial_state_from_truth  # noqa: E402
from vdps_hil.model.params import load_vehicle  # noqa: E402
from vdps_hil.prediction.config import PredictorConfig, load_predictor_config  # noqa: E402
from vdps_hil.prediction.metrics import PoseTrajectory  # noqa: E402
from vdps_hil.prediction.predictor import Predictor  # noqa: E402
from vdps_hil.sim.scenarios import load_scenario  # noqa: E402
from vdps_hil.sim.simulator import Simulator  # noqa: E402

CASES = (
    ("paper-left-turn", 10.25, "sedan-model", "left turn held (Fig 8)", None),
    ("paper-rollover", 10.25, "sedan-model", "T2 = T3 = 1000 N m (Fig 9)", None),
    ("fishhook-suv", 1.90, "suv-model", "fishhook, after the reversal", None),
    ("cr-circle-ramp", 30.0, "cr1-model", "CommonRoad set 1 on the circle ramp, half way; its model file's "
     "chassis parts (anti-roll bar, parallel steer)", 1),
)
"""(scenario, t0 [s], model file, label, CommonRoad parameter set of the truth or None: ours). Our
cases run the model file with the truth's parameters; the CommonRoad case the model file as it is
(its priors: the truth's parameters are not this project's schema)."""


def truth_snapshot(name: str, t0: float, cr_set: int | None = None):
    if cr_set is not None:
        from vdps_hil.sim.truth_cr import CommonRoadTruth

        truth = CommonRoadTruth(cr_set, load_scenario(name))
        truth.step_to(t0 + 1e-9)
        return truth.snapshot(), None
    sim = Simulator(scenario=load_scenario(name))
    sim.step_to(t0 + 1e-9)
    return sim.snapshot(), sim.scenario


def timed(pred: Predictor, init, repeat: int):
    """(median, best) CPU time of one prediction [s], and the last result."""
    times, r = [], None
    for _ in range(repeat):
        t = time.process_time()
        r = pred.predict(init)
        times.append(time.process_time() - t)
    return statistics.median(times), min(times), r


def diff(ref, r) -> dict:
    a = PoseTrajectory.from_prediction(ref)
    b = PoseTrajectory.from_prediction(r)
    keep = b.t_s <= a.t_s[-1] + 1e-9
    ai = a.at(b.t_s[keep])
    dp = np.linalg.norm(b.pos_g_m[keep] - ai.pos_g_m, axis=1)
    de = b.euler_v_rad[keep] - ai.euler_v_rad
    de[:, 2] = (de[:, 2] + math.pi) % (2 * math.pi) - math.pi
    pn_a, pn_b = ref.point_of_no_return_t_s, r.point_of_no_return_t_s
    dpn = (pn_b - pn_a) if (pn_a is not None and pn_b is not None) else (0.0 if pn_a == pn_b else math.nan)
    return {"max_pos_diff_m": float(dp.max()), "end_pos_diff_m": float(dp[-1]),
            "max_angle_diff_deg": float(np.degrees(np.abs(de)).max()), "ponr_diff_s": dpn}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    default = load_predictor_config()
    candidates = [("rk2 1 ms (reference)", PredictorConfig(integrator="rk2", step_s=0.001, output_every=10))]
    for step in (0.002, 0.005, 0.01, 0.02):
        for je, coup in ((1, False), (1, True), (2, True), (4, True)):
            candidates.append((f"ros2 {step * 1e3:g} ms J/{je}{' +cpl' if coup else ' diag'}",
                               PredictorConfig(integrator="ros2", step_s=step, jacobian_every=je,
                                               jacobian_coupling=coup,
                                               output_every=max(1, int(round(0.01 / step))))))
    candidates.append((f"configured ({default.integrator} {default.step_s * 1e3:g} ms J/{default.jacobian_every})",
                       default))
    candidates.append(("configured, generic core path", default))
    report = {"horizon_s": default.horizon_s, "cases": []}
    for name, t0, model, label, cr_set in CASES:
        snap, sc = truth_snapshot(name, t0, cr_set)
        vehicle = load_vehicle(model)
        if sc is not None:
            vehicle = vehicle.with_params(**sc.vehicle.params.as_dict())
        init = initial_state_from_truth(snap)
        params = "true parameters" if sc is not None else "the model file's priors"
        print(f"\n== {name} from t0 = {t0} s: {label}; {params}, truth initial state, held inputs, "
              f"horizon {default.horizon_s} s")
        print(f"{'case':34s} {'median ms':>9s} {'best ms':>7s} {'f-evals':>7s} {'stop':>18s} {'max dpos m':>10s} "
              f"{'end dpos m':>10s} {'max dang deg':>12s} {'dPONR s':>8s}")
        ref = fast = None
        rows = []
        for lab, cfg in candidates:
            cfg = PredictorConfig(**{**cfg.__dict__, "horizon_s": default.horizon_s})
            generic = lab.endswith("generic core path")
            pred = Predictor(vehicle, cfg, fast=not generic)
            rep = 1 if cfg.step_s < 0.002 else args.repeat
            med, mn, r = timed(pred, init, rep)
            if ref is None:
                ref = r
            d = diff(ref, r)
            if lab.startswith("configured ("):
                fast = r
            if generic:
                d["vs_configured"] = diff(r, fast)
            rows.append({"case": lab, "median_ms": med * 1e3, "min_ms": mn * 1e3, "f_evals": r.n_f_evals,
                         "stop": r.stop_reason, **d})
            print(f"{lab:34s} {med * 1e3:9.1f} {mn * 1e3:7.1f} {r.n_f_evals:7d} {r.stop_reason:>18s} "
                  f"{d['max_pos_diff_m']:10.4f} {d['end_pos_diff_m']:10.4f} {d['max_angle_diff_deg']:12.4f} "
                  f"{d['ponr_diff_s']:8.3f}")
            if generic:
                v = d["vs_configured"]
                print(f"{'  configured vs generic path':34s} {'':9s} {'':7s} {'':7s} {'':>18s} "
                      f"{v['max_pos_diff_m']:10.1e} {v['end_pos_diff_m']:10.1e} {v['max_angle_diff_deg']:12.1e} "
                      f"{v['ponr_diff_s']:8.3f}")
        report["cases"].append({"scenario": name, "t0_s": t0, "rows": rows})
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
