"""Rollover outcome map: a scenario over tire peak friction x static stability factor.

For each (mu, SSF) the scenario's vehicle gets its CG height set to t_half / SSF
(``rollover.with_static_stability_factor``; everything else kept) and the Magic Formula peak
friction mu; the run is classified as tip-up, spin-out or stable (``rollover.assess``) with the
tip-up and point-of-no-return times.

    .venv/bin/python tools/rollover_map.py [--scenario paper-rollover] [--vehicle FILE]
        [--mu 0.8,0.9,1.0,1.1,1.2] [--ssf 1.0,1.1,1.2,1.3,1.4,1.5] [--json FILE] [--png FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import time

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import load_vehicle
from vdps_hil.model.rollover import assess, with_static_stability_factor
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import Simulator


def outcome_map(scenario_name: str, mus, ssfs, vehicle_name: str | None = None) -> list[dict]:
    sc = load_scenario(scenario_name)
    base = load_vehicle(vehicle_name, "truth") if vehicle_name else sc.vehicle
    out = []
    for mu in mus:
        for ssf in ssfs:
            veh = with_static_stability_factor(base, ssf)
            eff = sc.effect_set(veh)
            if "magic_formula_tire" not in eff:
                eff = eff + sc.effect_set(veh, extra=("magic_formula_tire",))["magic_formula_tire"]
            eff = EffectSet(e.replace(peak_friction=mu) if e.name == "magic_formula_tire" else e for e in eff)
            sim = Simulator(veh, scenario=sc, effects=eff, stop_at_point_of_no_return=True)
            sim.run()
            a = assess(sim)
            out.append({"peak_friction": mu, "ssf": ssf, "h_cg_m": veh.geometry.h_cg_m, **a.to_json()})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper-rollover")
    ap.add_argument("--vehicle", default=None, help="truth vehicle file (default: the scenario's)")
    ap.add_argument("--mu", default="0.8,0.9,1.0,1.1,1.2")
    ap.add_argument("--ssf", default="1.0,1.1,1.2,1.3,1.4,1.5")
    ap.add_argument("--json", default=None)
    ap.add_argument("--png", default=None)
    args = ap.parse_args()
    mus = [float(v) for v in args.mu.split(",")]
    ssfs = [float(v) for v in args.ssf.split(",")]
    t0 = time.perf_counter()
    rows = outcome_map(args.scenario, mus, ssfs, args.vehicle)
    veh = args.vehicle or load_scenario(args.scenario).vehicle_name
    print(f"outcome map of {args.scenario} ({veh}); cells: outcome tip-up/PONR time [s]  "
          f"({time.perf_counter() - t0:.1f} s)")
    print("mu \\ SSF " + "".join(f"{s:>22.2f}" for s in ssfs))
    for mu in mus:
        cells = []
        for r in rows:
            if r["peak_friction"] == mu:
                tu, pn = r["tip_up_t_s"], r["point_of_no_return_t_s"]
                times = "" if math.isnan(tu) else f" {tu:.2f}" + ("" if math.isnan(pn) else f"/{pn:.2f}")
                cells.append(f"{r['outcome'] + times:>22s}")
        print(f"{mu:8.2f} " + "".join(cells))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"scenario": args.scenario, "vehicle": veh, "cells": rows}, fh, indent=2,
                      default=lambda o: None)
    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        colour = {"stable": "tab:green", "spin-out": "tab:orange", "tip-up": "tab:red"}
        fig, ax = plt.subplots(figsize=(6, 4))
        for r in rows:
            ax.scatter(r["ssf"], r["peak_friction"], s=400, marker="s", color=colour[r["outcome"]])
            if not math.isnan(r["point_of_no_return_t_s"]):
                ax.annotate("PONR", (r["ssf"], r["peak_friction"]), ha="center", va="center", fontsize=7)
        for k, c in colour.items():
            ax.scatter([], [], marker="s", color=c, label=k)
        ax.set_xlabel("static stability factor t/(2h) [-]")
        ax.set_ylabel("tire peak friction [-]")
        ax.set_title(f"{args.scenario} ({veh})")
        ax.legend(loc="upper right", fontsize=8)
        fig.tight_layout()
        fig.savefig(args.png, dpi=100)


if __name__ == "__main__":
    main()
