#!/usr/bin/env python3
"""Fault campaign (issue 20): every fault kind over a grid of magnitudes and onset times on
several scenarios, through the real chain (wire formats -> ``record.decode`` -> ``VdpsSystem``
with prediction and warning), scored against the simulator's truth HERE (never by the chain).

Per run (fault window [t_f, t_b]: onset and the sensor's return)::

    peak errors       max over t >= t_f of |horizontal position|, |horizontal velocity| and the
                      largest of |roll|, |pitch|, |yaw| error (filter estimate - truth)
    in 3 sigma        share of (epoch, state) pairs after 1 s, states x, y, vx, vy, roll, pitch,
                      yaw, with |error| <= 3 x the filter's own sigma
    recover_s         time after t_b until every one of those errors stays at its pre-fault
                      level (below max(2 x its 95th percentile over the 2 s before t_f, 3 x its
                      mean sigma then); a fault within 1 s of the start: below 3 x its own
                      sigma) to the end of the drive; 0: never left it; inf: not by the end;
                      "not back": the sensor returns after the drive ends
    rejected          gated GNSS updates (pos + vel + att) and rejected IMU samples
    valid warnings    VDPS_Warning frames of level >= 2 with status valid (0); on the rollover
                      drive the lead time of the first one to the truth point of no return

The system predicts with the model file's parameters (``start_params``, what ``--params`` does,
without identification): the warning is valid from the start, so validity is decided by the
fault handling alone.

Usage::

    .venv/bin/python tools/fault_campaign.py [--quick] [--scenario NAME] [--fault TEXT] [--per-state]
                                             [--truth commonroad-mb:1|3] [--json FILE] [--seed 21]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
import time

import can
import numpy as np

from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.estimation.estimates import Estimate
from vdps_hil.experiments.scoring import evaluate_warning_frames, truth_at
from vdps_hil.experiments.workbench_study import model_file
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.pipeline.outputs import CanFrame
from vdps_hil.record.decode import decode_recording
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.profiles import load_profile

TRUTH_KEYS = ("pos_e_m", "pos_n_m", "pos_u_m", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u", "roll_g_rad",
              "pitch_g_rad", "yaw_g_rad")
ERR_STATES = (0, 1, 3, 4, 6, 7, 8)
ERR_NAMES = ("x", "y", "vx", "vy", "roll", "pitch", "yaw")
SCENARIOS = {"paper": ("sedan-model", 10.0), "lane-change-iso3888": ("sedan-model", 10.0),
             "fishhook-suv": ("suv-model", None)}
"""Scenario -> (model vehicle file, duration [s]; None: the scenario's own)."""
CR_SCENARIOS = {"cr-lane-change": 12.0, "cr-sine-accel": 12.0}
"""With ``--truth commonroad-mb:N`` (CommonRoad's multibody model, parameter set N; flat road):
scenario -> duration [s]; the model vehicle file is ``crN-model``."""
ONSETS = {"paper": (3.0, 5.0), "lane-change-iso3888": (2.5, 4.0), "fishhook-suv": (0.4,),
          "cr-lane-change": (2.0, 4.0), "cr-sine-accel": (3.0, 5.0)}


def fault_grid() -> list[tuple[str, float]]:
    """(fault spec without t_s, duration of the fault [s]) per kind and magnitude; the onset is
    added per run."""
    grid = [("serial_disconnect:device=imu,duration_s=0.2", 0.2), ("serial_disconnect:device=imu,duration_s=2", 2.0),
            ("serial_disconnect:device=imu,duration_s=5", 5.0),
            ("gyro_spike:duration_s=0.002,amplitude_degps=200", 0.002),
            ("gyro_spike:duration_s=0.05,amplitude_degps=200", 0.05),
            ("gyro_spike:duration_s=0.2,amplitude_degps=200", 0.2),
            ("gyro_spike:duration_s=0.2,amplitude_degps=20", 0.2),
            ("gyro_spike:axis=x,duration_s=0.05,amplitude_degps=100", 0.05),
            ("gnss_outage:duration_s=2", 2.0)]
    return grid


def run_one(scenario: str, spec: str, t_f: float, absent_s: float, seed: int, truth: str | None = None) -> dict:
    if truth is None:
        model_name, dur = SCENARIOS[scenario]
    else:  # CommonRoad's multibody truth: its own vehicle, the matching model file
        model_name, dur = model_file(truth), CR_SCENARIOS[scenario]
    prof = load_profile("table1-susp1k")
    full = f"{spec},t_s={t_f:g}"
    buf = io.BytesIO()
    Drive(scenario, profile=prof, seed=seed, duration_s=dur, faults=[full], truth=truth).run(buf)
    buf.seek(0)
    reader = RecordingReader(buf)
    truth = {t: d["values"] for _, t, d in reader.iter_messages(["/truth/state"])}  # harness only
    events = [d["values"] for _, _, d in reader.iter_messages(["/truth/events"])]
    grid = min(b - a for a, b in zip(sorted(truth), sorted(truth)[1:]))
    model = load_vehicle(model_name, "model")
    cfg = SystemConfig.for_profile(prof.suspension.rate_hz, prof.suspension.sigma_m, start_params=model.params,
                                   identify=False)
    system = VdpsSystem(model, cfg, origin=DEFAULT_ORIGIN)
    rows_t, rows_e, rows_s, frames = [], [], [], []
    for s in decode_recording(reader):
        outs = system.handle(s)
        system.clear_input_log()
        for o in outs:
            if isinstance(o, CanFrame):
                frames.append(can.Message(timestamp=o.t_ns / 1e9, arbitration_id=o.arbitration_id,
                                          data=o.data, is_extended_id=False))
            elif isinstance(o, Estimate):
                tv = truth_at(truth, o.t_ns, grid)
                if tv is None:
                    continue
                e = np.array(o.x[:9]) - np.array([tv[k] for k in TRUTH_KEYS])
                e[8] = math.remainder(e[8], 2 * math.pi)
                rows_t.append(o.t_ns / 1e9)
                rows_e.append(np.abs(e))
                rows_s.append(np.array(o.sigma[:9]))
    return score(np.array(rows_t), np.array(rows_e), np.array(rows_s), frames, events, t_f, t_f + absent_s,
                 system, scenario, full)


def score(t, e, s, frames, events, t_f, t_b, system, scenario, spec) -> dict:
    """The campaign's figures of one run (module docstring)."""
    live = t >= t[0] + 0.8
    inside = float(np.mean([(e[live, i] <= 3.0 * s[live, i]) for i in ERR_STATES]))
    late = t >= t_f
    by_state = {}  # per state: share within 3 sigma, first/last epoch outside it, the worst epoch
    for name, i in zip(ERR_NAMES, ERR_STATES):
        el, sl, tl = e[live, i], s[live, i], t[live]
        out = el > 3.0 * sl
        k = int(np.argmax(el / np.maximum(sl, 1e-12)))
        by_state[name] = {"inside_3sigma": float(np.mean(~out)),
                          "outside_s": [float(tl[out][0]), float(tl[out][-1])] if out.any() else None,
                          "worst": {"t_s": float(tl[k]), "error": float(el[k]), "sigma": float(sl[k])}}
    before = (t >= max(t_f - 2.0, t[0] + 0.8)) & (t < t_f)
    worst_t = t_b
    for i in ERR_STATES:
        if before.sum() >= 20:
            lim = max(2.0 * np.percentile(e[before, i], 95), 3.0 * s[before, i].mean())
        else:  # a fault right after the start: within the filter's own 3 sigma
            lim = 3.0 * s[:, i]
        over = t[late & (e[:, i] > lim)]
        if len(over):
            worst_t = max(worst_t, float(over[-1]))
    if t_b >= t[-1]:
        recover = None  # the sensor is not back before the drive ends (nothing to recover from)
    else:
        recover = worst_t - t_b if worst_t < t[-1] - 0.05 else math.inf
    dec = VdpsCanDecoder()
    lvl_valid = [d.t_ns / 1e9 for m in frames for d in dec.decode(int(m.timestamp * 1e9), m.arbitration_id, m.data)
                 if int(d.fields["warning_level"]) >= 2 and int(d.fields["warning_status"]) == 0]
    o = evaluate_warning_frames(frames, events)
    rej = system.pipeline.rejected()
    return {"scenario": scenario, "fault": spec,
            "peak_pos_m": float(np.hypot(e[late, 0], e[late, 1]).max()),
            "peak_vel_mps": float(np.hypot(e[late, 3], e[late, 4]).max()),
            "peak_att_deg": float(np.degrees(e[late, 6:9].max())), "inside_3sigma": inside, "by_state": by_state,
            "recover_s": recover, "gated_gnss": sum(rej[f"ekf.{k}"] for k in ("gnss_pos", "gnss_vel", "gnss_att")),
            "imu_rejected": rej["imu"], "inflations": system.pipeline.counters["inflations"],
            "valid_warnings": len(lvl_valid),
            "rollover": not math.isnan(o.truth_point_of_no_return_t_s),
            "lead_time_s": None if o.lead_time_s is None or math.isnan(o.lead_time_s) else o.lead_time_s}


def per_state(rows: list[dict]) -> str:
    """Per run, the states that left their 3 sigma: share inside, when, and at the worst epoch
    (largest error / sigma) the error against the filter's sigma (m, m/s, deg)."""
    out = []
    for r in rows:
        bad = []
        for n, d in r["by_state"].items():
            if d["outside_s"] is None:
                continue
            w = d["worst"]
            f = math.degrees if n in ("roll", "pitch", "yaw") else float
            bad.append(f"{n} {100 * d['inside_3sigma']:.1f} % (t {d['outside_s'][0]:.2f}-{d['outside_s'][1]:.2f} s; "
                       f"worst at {w['t_s']:.2f} s: error {f(w['error']):.3g}, sigma {f(w['sigma']):.3g})")
        out.append(f"{r['scenario']} `{r['fault']}`: " + ("; ".join(bad) if bad else "every state within 3 sigma"))
    return "\n".join(out)


def table(rows: list[dict]) -> str:
    head = ("| scenario | fault | peak pos m | peak vel m/s | peak att deg | in 3 sigma | recover s | gated GNSS "
            "| IMU rejected | valid warnings (lead s) |\n|---|---|---|---|---|---|---|---|---|---|")
    out = [head]
    for r in rows:
        w = str(r["valid_warnings"]) + (f" ({r['lead_time_s']:.2f})" if r["lead_time_s"] is not None else "")
        rec = "not back" if r["recover_s"] is None else f"{r['recover_s']:.2f}"
        out.append(f"| {r['scenario']} | `{r['fault']}` | {r['peak_pos_m']:.2f} | {r['peak_vel_mps']:.2f} | "
                   f"{r['peak_att_deg']:.2f} | {100 * r['inside_3sigma']:.1f} % | {rec} | "
                   f"{r['gated_gnss']} | {r['imu_rejected']} | {w} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one onset per scenario (the first)")
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--scenario", action="append", default=None, help="only these scenarios")
    ap.add_argument("--fault", action="append", default=None,
                    help="only the grid's faults whose spec contains this text (repeatable)")
    ap.add_argument("--per-state", action="store_true",
                    help="also print, per run, which states left their 3 sigma, when, and by how much")
    ap.add_argument("--truth", default=None, choices=("commonroad-mb:1", "commonroad-mb:3"),
                    help="CommonRoad's multibody model as the truth (scenarios " + ", ".join(CR_SCENARIOS) + ")")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    rows = []
    t0 = time.perf_counter()
    for scen in a.scenario or (CR_SCENARIOS if a.truth else SCENARIOS):
        for spec, absent in fault_grid():
            if a.fault and not any(f in spec for f in a.fault):
                continue
            for t_f in ONSETS[scen][:1] if a.quick else ONSETS[scen]:
                rows.append(run_one(scen, spec, t_f, absent, a.seed, a.truth))
                print(table(rows[-1:]).splitlines()[-1], file=sys.stderr, flush=True)
    print(table(rows))
    if a.per_state:
        print("\n" + per_state(rows))
    print(f"\n{len(rows)} runs, {time.perf_counter() - t0:.0f} s wall")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
