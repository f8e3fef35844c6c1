"""The inertia problem's I_z budget on one simulated drive with truth (issue 17;
``vdps_hil.experiments.yaw_budget``): which part of eq 23's yaw moment moves I_z.

    python tools/yaw_budget.py --scenario cr-lane-change --truth commonroad-mb:3 --model cr3-model --seed 101 [--yaw-row]
    python tools/yaw_budget.py --seed 1 --t-end 10.25            # our own simulator, paper-left-turn

Simulates the drive through the chain (``experiments.paper_chain.chain_run``, table1-susp1k),
runs a fresh ``Identifier`` over its inputs up to ``--t-end``, prints the identified I_z and
C_alpha against the truth and the budget; ``--truth-slip`` reruns the identifier with the
truth's slip angles in the inputs (which share of the error the slip estimate makes),
``--truth-steer`` with the estimated ones moved by the road-wheel angle's error only.
Use tuning seeds (``experiments.ident_study.TUNING_SEEDS``) to look for causes.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys

import numpy as np


def _identify(veh, cfg, inputs, t_end_s):
    from vdps_hil.identification.identifier import Identifier

    idf = Identifier(veh, cfg)
    for inp in inputs:
        if inp.t_ns / 1e9 > t_end_s:
            break
        idf.update(inp)
    return idf


def _with_truth(inputs, truth, part: str):
    """The inputs with the truth's slip angles (``part`` "slip"), or with the estimated ones
    moved by the truth's road-wheel angle error (``"steer"``: alpha + delta_true - delta_est,
    alpha = delta - atan(...) of a steered wheel)."""
    t = np.array([s["t_ns"] for s in truth], dtype=float)
    key = "slip_angle_rad" if part == "slip" else "road_wheel_angle_rad"
    tr = [np.array([s[f"{key}_{i}"] for s in truth]) for i in (1, 2, 3, 4)]
    out = []
    for inp in inputs:
        v = [float(np.interp(inp.t_ns, t, a)) for a in tr]
        al = v if part == "slip" else [a + d - e for a, d, e in zip(inp.slip_angle_rad, v, inp.wheel_angle_rad)]
        out.append(dataclasses.replace(inp, slip_angle_rad=tuple(al)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper-left-turn")
    ap.add_argument("--truth", default="ours", help='"ours" or a truth backend spec (commonroad-mb:1)')
    ap.add_argument("--model", default="sedan-model")
    ap.add_argument("--truth-vehicle", default="sedan-truth", help="truth figures for --truth ours")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--t-end", type=float, default=math.inf)
    ap.add_argument("--yaw-row", action="store_true", help="the cornering problem with its yaw row")
    ap.add_argument("--truth-slip", action="store_true", help="also identify with the truth's slip angles")
    ap.add_argument("--truth-steer", action="store_true",
                    help="also identify with the slip angles moved by the truth's road-wheel angle error")
    a = ap.parse_args(argv)
    from vdps_hil.experiments.ident_study import yaw_row_config
    from vdps_hil.experiments.paper_chain import chain_run
    from vdps_hil.experiments.yaw_budget import yaw_budget
    from vdps_hil.identification.config import load_ident_config
    from vdps_hil.model.params import load_vehicle

    run = chain_run(a.scenario, "table1-susp1k", a.seed, model=a.model, predict=False, record_inputs=True,
                    truth_backend=None if a.truth == "ours" else a.truth)
    if a.truth == "ours":
        tp = load_vehicle(a.truth_vehicle).params.as_dict()
    else:
        from vdps_hil.sim.cr_model import truth_figures
        tp = truth_figures(int(a.truth.split(":")[1]))
    cfg = yaw_row_config() if a.yaw_row else load_ident_config()
    veh = load_vehicle(a.model)
    names = ("inertia_z_kgm2", "cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad")
    runs = [("estimated slip", run["inputs"])]
    runs += [(f"truth {part}", _with_truth(run["inputs"], run["truth"], part))
             for part, on in (("slip", a.truth_slip), ("steer", a.truth_steer)) if on]
    for tag, inputs in runs:
        idf = _identify(veh, cfg, inputs, a.t_end)
        p = idf.params.as_dict()
        print(tag, {n: f"{100 * (p[n] / tp[n] - 1):+.1f} %" for n in names})
    idf = _identify(veh, cfg, run["inputs"], a.t_end)
    b = yaw_budget(run["truth"], run["inputs"], veh, idf.params, cfg, a.t_end)
    if not b["rows"]:
        print("no yaw row used")
        return 1
    iz = tp["inertia_z_kgm2"]
    print(f"rows {b['rows']}; least-squares I_z against the truth's wd_z, % of the truth figure {iz:.1f} kg m^2:")
    for k in ("iz_truth_forces", "iz_model", "iz_model_est_accel"):
        print(f"  {k:20s} {100 * (b[k] / iz - 1):+6.1f} %")
    print("shares of iz_model - iz_truth_forces, % of I_z:",
          {k: round(100 * v / iz, 1) for k, v in (*b["shares"].items(), ("other", b["other"]))})
    print("sensitivity, % of I_z per % of C_alpha:", {k: round(v, 2) for k, v in b["sensitivity"].items()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
