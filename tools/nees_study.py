#!/usr/bin/env python3
"""Estimator consistency through the real chain (issue 5 acceptance): simulated drives on the wire
formats -> ``record.decode`` (``/raw/`` only) -> ``VdpsSystem`` -> NEES against the simulator's
truth. The truth (``/truth/state``) is read HERE, by the study harness, never by the chain.

Averaged NEES (Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, section 5.4.2)::

    e_k,i   = x_hat_k,i - x_k,i                     filter states (11: position, velocity, attitude,
                                                    road bank and grade; yaw wrapped)
    eps_k,i = e_k,i^T P_k,i^-1 e_k,i                run i, epoch k (the filter's own P)
    eps_k   = (1/N) sum_i eps_k,i
    N eps_k ~ chi2(N n)   ->  95 % two-sided band [chi2.ppf(0.025, N n) / N, chi2.ppf(0.975, N n) / N]

Reported: the fraction of epochs after 5 s with eps_k inside the band (goal >= 90 %), the mean
of eps_k / n, and the per-state normalised error variance mean(e^2 / sigma^2) (1 when consistent).

Also here (``--outage``): a 10 s GNSS outage (fault ``gnss_outage``) -- the horizontal position
error growth during the outage, and the time after GNSS returns until the error is back at its
pre-outage level -- below max(2 x its 95th percentile over the 3 s before the outage, 3 x the
mean sigma then) -- and stays there for 1 s (``recovery_s``).

Usage::

    .venv/bin/python tools/nees_study.py [--runs 25] [--scenario lane-change-iso3888]
        [--profile table1-susp1k] [--duration 12] [--outage] [--json FILE]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
import time
from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from vdps_hil.experiments.scoring import truth_at
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem, default_pipeline_config
from vdps_hil.record.decode import decode_recording
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive

TRUTH_KEYS = ("pos_e_m", "pos_n_m", "pos_u_m", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u", "roll_g_rad",
              "pitch_g_rad", "yaw_g_rad", "road_bank_rad", "road_grade_rad", "yaw_v_rad")
"""Truth names of the 12 states of eq 7 (``STATE_NAMES`` order)."""
WRAPPED = (8, 11)


def study_config(profile, **kw) -> SystemConfig:
    """The chain as ``vdps replay`` runs it, sized for the profile's suspension (a sensor data
    sheet: rate and noise), without identification and prediction (not part of the NEES)."""
    pc = kw.pop("pipeline", default_pipeline_config())
    return SystemConfig.for_profile(profile.suspension.rate_hz, profile.suspension.sigma_m, pipeline=pc,
                                    identify=False, predict=False, **kw)


def run_chain(scenario: str, seed: int, *, profile="table1-susp1k", duration_s: float | None = None,
              faults=(), config: SystemConfig | None = None, vehicle: str = "sedan-model") -> dict:
    """One simulated drive through decode + system; per estimate: time, filter error (full
    12-vector; the truth interpolated to the estimate's time), NEES and sigmas."""
    from vdps_hil.sim.profiles import load_profile

    prof = load_profile(profile) if isinstance(profile, str) else profile
    buf = io.BytesIO()
    Drive(scenario, profile=prof, seed=seed, duration_s=duration_s, faults=list(faults)).run(buf)
    buf.seek(0)
    reader = RecordingReader(buf)
    truth = {t: d["values"] for _, t, d in reader.iter_messages(["/truth/state"])}  # harness only
    grid = min(b - a for a, b in zip(sorted(truth), sorted(truth)[1:]))
    cfg = config or study_config(prof)
    system = VdpsSystem(load_vehicle(vehicle, "model"), cfg, origin=DEFAULT_ORIGIN)
    ekf = system.pipeline.ekf
    rows_t, rows_e, rows_nees, rows_sig, rows_ev = [], [], [], [], []
    from vdps_hil.estimation.estimates import Estimate

    idx = None
    for s in decode_recording(reader):
        outs = system.handle(s)
        system.clear_input_log()
        for o in outs:
            if not isinstance(o, Estimate) or not ekf.initialized:
                continue
            tv = truth_at(truth, o.t_ns, grid)
            if tv is None:
                continue
            xt = np.array([tv[k] for k in TRUTH_KEYS])
            if idx is None:
                idx = ekf.layout.full_index
            e_full = np.array(o.x) - xt
            for i in WRAPPED:
                e_full[i] = math.remainder(e_full[i], 2 * math.pi)
            ef = e_full[idx]
            P = ekf.P
            try:
                nees = float(ef @ np.linalg.solve(P, ef))
            except np.linalg.LinAlgError:
                nees = math.nan
            rows_t.append(o.t_ns / 1e9)
            rows_e.append(e_full)
            rows_nees.append(nees)
            rows_sig.append(np.array(o.sigma))
            ev = np.array(o.vehicle_angles_rad) - np.array([tv["roll_v_rad"], tv["pitch_v_rad"], tv["yaw_v_rad"]])
            ev[2] = math.remainder(ev[2], 2 * math.pi)
            rows_ev.append(ev)
    return {"t_s": np.array(rows_t), "err": np.array(rows_e), "nees": np.array(rows_nees),
            "err_vehicle_angles": np.array(rows_ev),
            "sigma": np.array(rows_sig), "n_states": len(idx) if idx is not None else 0,
            "state_index": None if idx is None else idx.tolist(), "counters": system.status()["counters"],
            "pipeline_counters": system.pipeline.counters, "rejected": system.pipeline.rejected()}


def nees_summary(runs: list[dict], t_min_s: float = 5.0) -> dict:
    """Averaged NEES over runs on their common epochs after ``t_min_s`` (module docstring)."""
    n = runs[0]["n_states"]
    common = set(np.round(runs[0]["t_s"], 6))
    for r in runs[1:]:
        common &= set(np.round(r["t_s"], 6))
    ts = np.array(sorted(t for t in common if t >= t_min_s))
    if not len(ts):
        return {"epochs": 0}
    stack, errs, sigs = [], [], []
    for r in runs:
        pos = {t: i for i, t in enumerate(np.round(r["t_s"], 6))}
        sel = [pos[t] for t in ts]
        stack.append(r["nees"][sel])
        errs.append(r["err"][sel])
        sigs.append(r["sigma"][sel])
    nees = np.vstack(stack)
    N = len(runs)
    avg = nees.mean(axis=0)
    lo, hi = chi2.ppf(0.025, N * n) / N, chi2.ppf(0.975, N * n) / N
    inside = (avg >= lo) & (avg <= hi)
    e = np.concatenate(errs)
    s = np.concatenate(sigs)
    idx = runs[0]["state_index"]
    from vdps_hil.estimation.states import STATE_NAMES

    with np.errstate(invalid="ignore", divide="ignore"):
        nev = {STATE_NAMES[i]: float(np.nanmean((e[:, i] / s[:, i]) ** 2)) for i in idx}
    bins = np.floor(ts * 2.0) / 2.0  # averaged NEES per 0.5 s, to see where it leaves the band
    profile = {f"{b:.1f}": float(avg[bins == b].mean()) for b in np.unique(bins)}
    return {"runs": N, "n_states": n, "epochs": int(len(ts)), "band": [lo, hi], "profile_0p5s": profile,
            "fraction_inside": float(inside.mean()), "fraction_above": float((avg > hi).mean()),
            "fraction_below": float((avg < lo).mean()), "mean_nees_per_state": float(avg.mean() / n),
            "median_nees": float(np.median(avg)), "normalised_error_variance": nev}


def outage_study(seed: int = 1, *, scenario: str = "paper", t_out_s: float = 5.0,
                 outage_s: float = 10.0, duration_s: float = 20.0, profile="table1-susp1k") -> dict:
    """A ``gnss_outage`` of ``outage_s`` from ``t_out_s``: horizontal error growth and recovery."""
    spec = f"gnss_outage:t_s={t_out_s},duration_s={outage_s}"
    r = run_chain(scenario, seed, profile=profile, duration_s=duration_s, faults=[spec])
    t, e, s = r["t_s"], r["err"], r["sigma"]
    eh = np.hypot(e[:, 0], e[:, 1])
    sh = np.hypot(s[:, 0], s[:, 1])
    t_back = t_out_s + outage_s
    before = (t >= t_out_s - 3.0) & (t < t_out_s)
    during = (t >= t_out_s) & (t < t_back)
    after = t >= t_back
    base95 = float(np.percentile(eh[before], 95)) if before.any() else math.nan
    sigma_before = float(np.mean(sh[before])) if before.any() else math.nan
    limit = max(2.0 * base95, 3.0 * sigma_before)  # back to the pre-outage error level
    ok = eh <= limit
    rec = math.nan
    ta, oka = t[after], ok[after]
    for k in range(len(ta)):  # first instant from which the error stays recovered for 1 s
        window = (ta >= ta[k]) & (ta < ta[k] + 1.0)
        if oka[window].all():
            rec = float(ta[k] - t_back)
            break
    grow = eh[during]
    return {"scenario": scenario, "seed": seed, "outage": [t_out_s, t_back],
            "error_before_p95_m": base95, "sigma_before_m": sigma_before, "recovered_below_m": limit, "error_at_outage_end_m": float(grow[-1]) if len(grow) else math.nan,
            "max_error_during_m": float(grow.max()) if len(grow) else math.nan,
            "growth_m_per_s": float((grow[-1] - grow[0]) / (t[during][-1] - t[during][0])) if len(grow) > 1 else math.nan,
            "sigma_at_outage_end_m": float(sh[during][-1]) if len(grow) else math.nan,
            "max_error_over_3sigma_during": float((eh[during] / (3.0 * sh[during])).max()) if len(grow) else math.nan,
            "recovery_s": rec, "error_2s_after_m": float(np.interp(t_back + 2.0, t, eh)),
            "counters": r["counters"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=25)
    ap.add_argument("--scenario", default="lane-change-iso3888")
    ap.add_argument("--profile", default="table1-susp1k")
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--seed0", type=int, default=100)
    ap.add_argument("--outage", action="store_true", help="also run the 10 s GNSS outage study")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    runs = []
    for k in range(a.runs):
        runs.append(run_chain(a.scenario, a.seed0 + k, profile=a.profile, duration_s=a.duration))
        print(f"run {k + 1}/{a.runs}: {len(runs[-1]['t_s'])} epochs, median NEES "
              f"{np.nanmedian(runs[-1]['nees']):.2f}", file=sys.stderr)
    doc = {"scenario": a.scenario, "profile": a.profile, "duration_s": a.duration,
           "nees": nees_summary(runs), "wall_time_s": None}
    if a.outage:
        doc["outage"] = outage_study(a.seed0)
    doc["wall_time_s"] = time.perf_counter() - t0
    print(json.dumps(doc, indent=2))
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
