"""Benchmark (issue 19): one 5 s prediction against integrating CommonRoad's multibody model over
the same horizon, side by side in one process.

Rounds alternate the two workloads so that both see the same machine load:

* ``prediction``: the configured predictor (``configs/prediction``: ROS2 on the reduced core,
  compiled) over its 5 s horizon from the truth state of ``paper-left-turn`` at 10.25 s (Fig 8's
  held left turn), the model file with the truth's parameters (``tools/bench_predictor.py``'s
  first case);
* ``commonroad-mb:N``: CommonRoad's ``vehicle_dynamics_mb`` (29 states, Pacejka tires; the
  truth backend ``sim.truth_cr.CommonRoadTruth`` with its default integrator) over the same 5 s
  of ``cr-sine-accel``, for each parameter set given.

It prints the CPU time (``time.process_time``) of each, best and median over the rounds, and the
ratio CommonRoad / prediction of the medians. The process is pinned to one CPU where the OS
allows it.

Usage::

    .venv/bin/python tools/bench_predict_vs_cr.py [--rounds 5] [--predictions 20] [--sets 1 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))  # its sibling tools, also in safe-path mode (-P)

from vdps_hil.experiments.truth_init import initial_state_from_truth  # noqa: E402
from vdps_hil.model.params import load_vehicle  # noqa: E402
from vdps_hil.prediction.config import load_predictor_config  # noqa: E402
from vdps_hil.prediction.predictor import Predictor  # noqa: E402
from vdps_hil.sim.scenarios import load_scenario  # noqa: E402
from vdps_hil.sim.simulator import Simulator  # noqa: E402
from vdps_hil.sim.truth_cr import CommonRoadTruth  # noqa: E402

from bench_sim_drive import pin_one_core  # noqa: E402  (tools/, inserted above)


def prediction_workload():
    """() -> None running one configured prediction from the held left turn (module docstring)."""
    sim = Simulator(scenario=load_scenario("paper-left-turn"))
    sim.step_to(10.25 + 1e-9)
    snap, sc = sim.snapshot(), sim.scenario
    vehicle = load_vehicle("sedan-model").with_params(**sc.vehicle.params.as_dict())
    cfg = load_predictor_config()
    pred = Predictor(vehicle, cfg)
    init = initial_state_from_truth(snap)
    pred.predict(init)  # compiled kernels warm (their cache is filled at set-up)
    return cfg.horizon_s, lambda: pred.predict(init)


def cpu_s(fn) -> float:
    t = time.process_time()
    fn()
    return time.process_time() - t


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--predictions", type=int, default=20, help="predictions timed per round")
    ap.add_argument("--sets", type=int, nargs="+", default=[1, 3])
    a = ap.parse_args(argv)
    pin = pin_one_core()
    horizon_s, predict = prediction_workload()
    sc = load_scenario("cr-sine-accel")
    times = {"prediction": []} | {f"commonroad-mb:{s}": [] for s in a.sets}
    for _ in range(a.rounds):
        for _ in range(a.predictions):
            times["prediction"].append(cpu_s(predict))
        for s in a.sets:
            times[f"commonroad-mb:{s}"].append(cpu_s(lambda: CommonRoadTruth(s, sc).run(horizon_s)))
    med_p = statistics.median(times["prediction"])
    print(f"horizon {horizon_s:g} s, {a.rounds} rounds alternating ({pin}; CPU time of this process)")
    for name, ts in times.items():
        med = statistics.median(ts)
        ratio = "" if name == "prediction" else f"   {med / med_p:7.0f}x the prediction"
        print(f"{name:<18} best {min(ts) * 1e3:9.2f} ms   median {med * 1e3:9.2f} ms{ratio}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
