"""Benchmark: real-time factor of the truth simulator's physics on a scenario (default `paper`).

Physics alone: the core stepped at 1 ms with 100 Hz truth snapshots and the rollover monitor,
no sensor models. Prints the best of N repeats per integrator.

    .venv/bin/python tools/bench_sim.py [--scenario paper] [--seconds 15] [--repeats 3]
"""

from __future__ import annotations

import argparse
import time

from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import Simulator


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--seconds", type=float, default=None, help="simulated time (default: scenario duration)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    dur = args.seconds or sc.duration_s
    for integ in ("rk2", "rk4"):
        for dof in (True, False):
            best = float("inf")
            for _ in range(args.repeats):
                sim = Simulator(scenario=sc, integrator=integ, unsprung_dof=dof)
                t0 = time.perf_counter()
                sim.run(dur)
                best = min(best, time.perf_counter() - t0)
            label = "truth (unsprung DOF)" if dof else "reduced (eq 13-16)"
            print(f"{args.scenario}: {integ} {label:22s} {sim.t_s:6.2f} s simulated in {best:6.3f} s"
                  f" -> real-time factor {sim.t_s / best:6.1f}x  ({best / sim.n * 1e6:5.1f} us/step)")


if __name__ == "__main__":
    main()
