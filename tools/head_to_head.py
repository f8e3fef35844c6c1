#!/usr/bin/env python3
"""Head to head: the workbench's ranking against PySINDy on the same residuals (issue 9).

For each hidden-effect drive (``vdps_hil.experiments.workbench_study``) both methods see the same data: the
residual of eq 13 that the identified model leaves once the estimator's error directions are
taken out (the workbench's own identification step), on the longitudinal, lateral, yaw and four
wheel-speed equations. PySINDy (``STLSQ`` sparse regression on a ``PolynomialLibrary`` of degree 3
of the motion variables v_x, v_y, r, r_dot, a_y and the front road-wheel angle, plus each
wheel's apparent speed r omega_i for the wheel-speed rows) picks the terms that explain each
residual; the largest term (noise-weighted) is mapped to the effect a vehicle-dynamics engineer
would read from it (table ``TERM_TO_EFFECT``). The workbench's answer is its recommendation (or
its top equivalence group). Hit rates of both are printed.

PySINDy is an optional dependency (``pip install pysindy``, extra ``study``).

Usage::

    .venv/bin/python tools/head_to_head.py --seeds 2 --jobs 2 --json h2h.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402

from vdps_hil.experiments.workbench_study import HIDDEN, is_hit  # noqa: E402

VARS = ("v_x", "v_y", "r", "r_dot", "a_y", "delta")


def term_to_effect(eq: str, term: str) -> str | None:
    """The effect an engineer would read from a SINDy term on an equation (crude by design: SINDy
    names polynomial terms, not physical effects)."""
    parts = [p for p in term.replace("*", " ").split() if p and p != "1"]
    deg = sum(int(p.split("^")[1]) if "^" in p else 1 for p in parts)
    t = "*".join(parts) if parts else "1"
    if eq.startswith("wheel_speed"):
        return "low_pressure_tire" if "romega" in t else None
    if eq == "long":
        if t == "1":
            return "rolling_resistance"
        if t in ("v_x^2", "v_x*v_x"):
            return "aero_drag"
        return None
    if eq in ("lat", "yaw"):
        if t == "1":
            return "crosswind"
        if "r_dot" in t and deg == 1:
            return "imu_lever_arm"
        if deg == 3 and ("a_y" in t or "delta" in t or "v_y" in t):
            return "magic_formula_tire"
        if deg == 1 and ("delta" in t or "a_y" in t):
            return "steering_compliance"
        if deg == 3:
            return "load_dependent_cornering_stiffness"
    return None


def _one(job: dict) -> dict:
    import pysindy as ps

    from vdps_hil.model.effects import EffectSet
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.workbench.dataset import load_drive
    from vdps_hil.workbench.innovations import compute_innovations
    from vdps_hil.workbench.ranking.config import RankingConfig
    from vdps_hil.workbench.ranking.identification import identify
    from vdps_hil.workbench.ranking.selection import rank
    from vdps_hil.workbench.residuals import EQUATIONS, row_states
    from vdps_hil.experiments.workbench_study import cached_drive

    veh = load_vehicle("sedan-model")
    path = cached_drive(job["cache"], job["maneuver"], job["specs"], job["seed"])
    tab = load_drive(path, veh)
    rk = rank(tab, veh)
    out = {"effect": job["effect"], "seed": job["seed"], "ours": rk.recommendation, "ours_hit": is_hit(rk, job["effect"])}
    # the same residual, cleaned of the estimator's error directions, in equation units
    cfg = RankingConfig()
    states = row_states(tab, veh)
    inn = compute_innovations(tab)
    point, d, cols, _ = identify(tab, veh, EffectSet(), states, inn, cfg, reference=veh)
    th, _ = d.objective(cols)
    r = d.y - d.matrix(cols) @ th
    ctx = d.ctx
    n, e = ctx.y_dyn.shape
    res = r[:d.n_dyn_rows].reshape(n, e)  # whitened: noise-weighted already
    names = [q for q, a in zip(EQUATIONS, ctx.avail) if a]
    idx = ctx.res.index[ctx.rows]
    c = tab.columns
    X = np.column_stack([c["vel_b_mps_x"][idx], c["vel_b_mps_y"][idx], c["rate_b_radps_z"][idx],
                         c["angular_accel_b_radps2_z"][idx], c["specific_force_b_mps2_y"][idx],
                         c["steer_wheel_angle_rad"][idx] / veh.geometry.steer_ratio])
    scale = np.std(X, axis=0) + 1e-9
    best = (0.0, None, None)
    for eq in ("long", "lat", "yaw", "wheel_speed_1", "wheel_speed_2", "wheel_speed_3", "wheel_speed_4"):
        if eq not in names:
            continue
        y = res[:, names.index(eq)]
        if eq.startswith("wheel_speed"):
            i = int(eq[-1])
            xs = np.column_stack([X[:, 0] / scale[0], c[f"wheel_speed_radps_{i}"][idx] * veh.tire.rolling_radius_m / scale[0]])
            lib = ps.PolynomialLibrary(degree=1, include_bias=True)
            feat_names = ["v_x", "romega"]
        else:
            xs = X / scale
            lib = ps.PolynomialLibrary(degree=3, include_bias=True)
            feat_names = list(VARS)
        theta = lib.fit_transform(xs)
        terms = lib.get_feature_names(feat_names)
        opt = ps.STLSQ(threshold=0.05, alpha=1e-3)
        opt.fit(theta, y)
        coef = np.asarray(opt.coef_).reshape(-1)
        contrib = np.array([np.sqrt(np.mean((theta[:, k] * coef[k]) ** 2)) for k in range(len(coef))])
        k = int(np.argmax(contrib))
        if contrib[k] > best[0]:
            best = (float(contrib[k]), eq, terms[k])
    eff = term_to_effect(best[1], best[2]) if best[1] else None
    # SINDy has no notion of "nothing missing": a term explaining < 1 noise sigma counts as none
    if best[0] < 1.0:
        eff = None
    out.update(sindy_term=f"{best[1]}: {best[2]}" if best[1] else None, sindy=eff, sindy_hit=eff == job["effect"],
               sindy_strength=best[0])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=300)
    ap.add_argument("--effects", default=",".join(e for e in HIDDEN if e not in ("imu_bias",)))
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--cache", default=None, help="directory for the simulated drives (default: a temp dir)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    import tempfile

    cache = a.cache or tempfile.mkdtemp(prefix="vdps_h2h_")
    jobs = [{"effect": e, "maneuver": HIDDEN[e][0], "specs": [HIDDEN[e][1]], "seed": s, "cache": cache}
            for e in a.effects.split(",") for s in range(a.first_seed, a.first_seed + a.seeds)]
    with ProcessPoolExecutor(max_workers=a.jobs) as ex:
        res = list(ex.map(_one, jobs))
    print(f"{'effect':36s} {'seed':>4s}  {'workbench':36s} {'PySINDy (term -> effect)'}")
    for r in res:
        print(f"{r['effect']:36s} {r['seed']:4d}  {str(r['ours']):28s} {'hit ' if r['ours_hit'] else 'miss'}    "
              f"{str(r['sindy_term']):34s} -> {str(r['sindy']):20s} {'hit' if r['sindy_hit'] else 'miss'}")
    for who in ("ours", "sindy"):
        k = sum(1 for r in res if r[f"{who}_hit"])
        print(f"{'workbench' if who == 'ours' else 'PySINDy'}: {k}/{len(res)} hits")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1, default=str)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
