#!/usr/bin/env python3
"""Fusion error standard deviations on the paper's scenario, as the paper's Figure 4: the
standard deviation of (fusion output - simulated truth) from the 5th to the 10th second, for the
corrected EKF and for the paper-faithful switches (each alone and all four), through the real
chain (wire formats -> ``record.decode`` -> ``VdpsSystem``; truth read only by this harness).

Per state: std over the window within each run, then the mean over ``--seeds`` runs. States:
the 12 of eq 7 (ENU position, velocity, absolute attitude, road bank and grade, psi_v) and the
road-relative vehicle angles (phi_v, theta_v) of eq 4; angles printed in degrees.

Usage::

    .venv/bin/python tools/fusion_figures.py [--seeds 5] [--profile table1-susp1k] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import nees_study  # noqa: E402  (the study harness next to this file)

from vdps_hil.estimation.ekf_config import PaperFaithful  # noqa: E402
from vdps_hil.estimation.states import STATE_NAMES  # noqa: E402
from vdps_hil.pipeline.node import default_pipeline_config  # noqa: E402
from vdps_hil.sim.profiles import load_profile  # noqa: E402

SETTINGS = {
    "corrected": PaperFaithful(),
    "a_psi_v_zero_rate": PaperFaithful.only("a_psi_v_zero_rate"),
    "b_y2_gps": PaperFaithful.only("b_y2_gps"),
    "c_y2_sus_single_plane": PaperFaithful.only("c_y2_sus_single_plane"),
    "d_accel_as_acceleration": PaperFaithful.only("d_accel_as_acceleration"),
    "paper_faithful_all": PaperFaithful.all(),
}
ANGLE = {n for n in STATE_NAMES if n.endswith("_rad")}


def fusion_std(setting: str, seeds, profile: str, window=(5.0, 10.0), scenario: str = "paper") -> dict:
    prof = load_profile(profile)
    pc = default_pipeline_config()
    pc = replace(pc, ekf=replace(pc.ekf, paper_faithful=SETTINGS[setting]))
    cfg = nees_study.study_config(prof, pipeline=pc)
    per_run = []
    for seed in seeds:
        r = nees_study.run_chain(scenario, seed, profile=prof, duration_s=window[1] + 0.5, config=cfg)
        sel = (r["t_s"] >= window[0]) & (r["t_s"] <= window[1])
        e = np.column_stack([r["err"][sel], r["err_vehicle_angles"][sel][:, :2]])
        per_run.append(np.std(e, axis=0))
    std = np.mean(per_run, axis=0)
    names = (*STATE_NAMES, "phi_v_rad", "theta_v_rad")
    out = {}
    for n, v in zip(names, std):
        out[n.replace("_rad", "_deg") if n.endswith("_rad") else n] = float(math.degrees(v)) if n.endswith("_rad") \
            else float(v)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--profile", default="table1-susp1k")
    ap.add_argument("--settings", default=",".join(SETTINGS))
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    seeds = list(range(1, a.seeds + 1))
    res = {}
    for st in a.settings.split(","):
        res[st] = fusion_std(st, seeds, a.profile)
        print(f"{st}: done", file=sys.stderr)
    names = list(next(iter(res.values())))
    cols = list(res)
    print(f"fusion error std, paper scenario, {a.profile}, 5-10 s, mean over {a.seeds} seeds")
    print(f"{'state':16s}" + "".join(f"{c[:14]:>15s}" for c in cols))
    for n in names:
        print(f"{n:16s}" + "".join(f"{res[c][n]:15.4g}" for c in cols))
    doc = {"profile": a.profile, "window_s": [5.0, 10.0], "seeds": seeds, "std": res,
           "wall_time_s": time.perf_counter() - t0}
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
