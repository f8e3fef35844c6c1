#!/usr/bin/env python3
"""Benchmark and figures of the estimator (issue 5). Prints; ``--json FILE`` also writes them.

Sections (all on the synthetic Table-1 manoeuvre of ``vdps_hil.experiments.synthetic``):

* ``cycle``: EKF cycle time per predict (10 ms mean-input step) and per update kind [us].
* ``replay``: real-time factor of the pipeline on a 60 s Table-1-rate stream (IMU and
  tachometers 1 kHz, GNSS 5 Hz position + attitude, suspension 1 Hz): bar >= 20x, goal 100x.
* ``figures`` (``--figures``): fusion error std per state with the corrected filter, each
  paper_faithful switch alone and all of them (windows 5-10 s as the paper's Fig 4, and
  5-30 s; mean of the per-run std over ``--seeds`` runs); NEES over ``--runs`` seeded runs
  (fraction of epochs after 5 s inside the two-sided 95 % band); a 10 s GNSS outage (error
  growth and recovery).

Usage::

    .venv/bin/python tools/bench_ekf.py                   # cycle + replay
    .venv/bin/python tools/bench_ekf.py --figures --runs 25 --seeds 10 --json bench_ekf.json
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from vdps_hil.experiments import synthetic as syn
from vdps_hil.estimation.ekf import MultiRateEKF
from vdps_hil.estimation.ekf_config import EkfConfig, PaperFaithful
from vdps_hil.estimation.measurements import suspension_measurement, y2_gps_measurement
from vdps_hil.estimation.observations import ObsKind, make_models
from vdps_hil.estimation.pipeline import EstimatorPipeline
from vdps_hil.estimation.pipeline_config import PipelineConfig
from vdps_hil.estimation.states import STATE_NAMES
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.model.params import load_vehicle

VEH = load_vehicle("sedan-model")
SIG0 = np.array([2.0, 2.0, 4.0, 1.0, 1.0, 1.0, 0.02, 0.02, 0.02, 0.05, 0.05, 0.05])


def _best(fn, repeat=3):
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def cycle_times() -> dict:
    """Microseconds per predict and per update kind, mid-run, initialised at the truth."""
    m = syn.Maneuver(duration_s=5.0)
    data = syn.make_sensor_data(m, VEH, seed=0)
    res = {}
    for label, cfg in (("corrected", EkfConfig()), ("paper_faithful", EkfConfig(paper_faithful=PaperFaithful.all()))):
        ekf = MultiRateEKF.from_vehicle(VEH, cfg)
        x0, p0 = syn.initial_state(m, ekf.layout, 0.0, SIG0 * 0.1, np.random.default_rng(0))
        ekf.initialize(0, x0, p0)
        syn.drive_ekf(ekf, data, VEH)
        n = 2000
        ekf.set_input(data.specific_force[-10:].mean(0), data.angular_rate[-10:].mean(0))
        t0 = ekf.t_ns
        dt = _best(lambda: [ekf.predict_to(t0 + (k + 1) * 10_000_000) for k in range(n)], 1)
        out = {"predict_us": dt / n * 1e6}
        xf, _ = ekf.full_state()
        models = make_models(VEH.mounting.gnss_lever_arm_m)
        geo = VEH.geometry
        sm = suspension_measurement(data.susp_deflection[-1], geo.l_f_m, geo.l_r_m, geo.track_half_front_m,
                                    geo.track_half_rear_m, 0.001)
        meas = {
            ObsKind.GNSS_POS: (models[ObsKind.GNSS_POS].h(xf), np.diag([1.0, 1.0, 9.0]), None),
            ObsKind.GNSS_ATT: (xf[6:9], np.eye(3) * 4.9e-5, None),
            ObsKind.GNSS_VEL: (models[ObsKind.GNSS_VEL].h(xf), np.diag([0.01, 1e-4]), None),
            ObsKind.Y1_SUS: (models[ObsKind.Y1_SUS].h(xf), sm.r_y1, None),
            ObsKind.Y2_SUS_RATE: (models[ObsKind.Y2_SUS_RATE].h(xf), np.array([[0.0025]]), None),
            ObsKind.Y2_SUS_PLANE: (models[ObsKind.Y2_SUS_PLANE].h(xf), np.array([[1e-6]]), None),
            ObsKind.Y2_GPS: (*y2_gps_measurement(xf[7], xf[8], 0.007, 0.007), None),
        }
        for kind, (z, r, aux) in meas.items():
            if kind not in ekf.kinds:
                continue
            k = 300
            dt = _best(lambda: [ekf.update(kind, z, r, aux=aux) for _ in range(k)], 1)
            out[f"update_{kind.value}_us"] = dt / k * 1e6
        res[label] = out
    return res


def replay_rtf(duration_s: float = 60.0, repeat: int = 3) -> dict:
    m = syn.Maneuver(duration_s=duration_s)
    data = syn.make_sensor_data(m, VEH, seed=3)
    samples = syn.to_samples(data, DEFAULT_ORIGIN)
    res = {"duration_s": duration_s, "samples": len(samples)}
    for label, cfg in (("estimates_every_predict", PipelineConfig()),
                       ("estimates_10hz", PipelineConfig(output_period_s=0.1))):
        def run():
            p = EstimatorPipeline(VEH, cfg, origin=DEFAULT_ORIGIN)
            for s in samples:
                p.handle(s)
        wall = _best(run, repeat)
        res[label] = {"wall_time_s": wall, "realtime_factor": duration_s / wall,
                      "us_per_sample": wall / len(samples) * 1e6}
    return res


def _run(cfg, seed, m, outage=None, y2_floor=None):
    data = syn.make_sensor_data(m, VEH, seed=seed, gnss_outage_s=outage)
    ekf = MultiRateEKF.from_vehicle(VEH, cfg)
    x0, p0 = syn.initial_state(m, ekf.layout, 0.0, SIG0, np.random.default_rng(1000 + seed))
    ekf.initialize(0, x0, p0)
    return ekf, syn.drive_ekf(ekf, data, VEH, y2_gps_floor=y2_floor)


def figures(seeds: int, runs: int) -> dict:
    m = syn.Maneuver()
    variants = {"corrected": PaperFaithful()}
    for name in PaperFaithful.__dataclass_fields__:
        variants[f"faithful_{name}"] = PaperFaithful.only(name)
    variants["faithful_a_and_b"] = PaperFaithful(a_psi_v_zero_rate=True, b_y2_gps=True)
    variants["faithful_all"] = PaperFaithful.all()
    variants["faithful_b_y2_gps_no_floor"] = PaperFaithful.only("b_y2_gps")
    variants["faithful_a_and_b_no_floor"] = PaperFaithful(a_psi_v_zero_rate=True, b_y2_gps=True)
    std = {}
    for label, pf in variants.items():
        w1, w2, nees_v, gated = [], [], [], 0
        floor = 1e-4 if label.endswith("no_floor") else None  # y2_gps R = J R_att J^T (+ 1e-4^2 I)
        for s in range(seeds):
            ekf, tr = _run(EkfConfig(paper_faithful=pf), s, m, y2_floor=floor)
            e = tr.errors_full()
            for w, (a, b) in ((w1, (5.0, 10.0)), (w2, (5.0, 30.0))):
                sel = (tr.t_s >= a) & (tr.t_s <= b)
                w.append(e[sel].std(axis=0))
            nees_v.append(float(tr.nees()[tr.t_s >= 5.0].mean()) / tr.x.shape[1])
            gated += sum(ekf.rejected().values())
        conv = np.array([1.0] * 6 + [180 / math.pi] * 6)
        std[label] = {"window_5_10s": dict(zip(STATE_NAMES, (np.mean(w1, axis=0) * conv).tolist())),
                      "window_5_30s": dict(zip(STATE_NAMES, (np.mean(w2, axis=0) * conv).tolist())),
                      "nees_per_state": float(np.mean(nees_v)), "rejected_updates": gated}
    # NEES: filter noise model = truth (constant road)
    cfg = EkfConfig(road_angle_rw=1e-5)
    trs = [_run(cfg, 100 + s, m)[1] for s in range(runs)]
    n = trs[0].x.shape[1]
    nees_all = np.array([tr.nees() for tr in trs])
    nees = nees_all.mean(axis=0)
    sel = trs[0].t_s >= 5.0
    lo, hi = chi2.ppf(0.025, runs * n) / runs, chi2.ppf(0.975, runs * n) / runs
    nees_doc = {"runs": runs, "n_states": n, "band": [lo, hi], "mean_after_5s": float(nees[sel].mean()),
                "fraction_inside_after_5s": float(np.mean((nees[sel] >= lo) & (nees[sel] <= hi))),
                "default_config_mean_after_5s": None}
    trs_d = [_run(EkfConfig(), 100 + s, m)[1] for s in range(min(runs, 10))]
    nees_doc["default_config_mean_after_5s"] = float(np.mean([tr.nees()[sel].mean() for tr in trs_d]))
    # outage 12-22 s
    grow, rec = [], []
    for s in range(seeds):
        _, tr = _run(EkfConfig(), 200 + s, m, outage=(12.0, 22.0))
        t, e, sg = tr.t_s, tr.errors_full(), tr.sigma_full
        eh, sh = np.hypot(e[:, 0], e[:, 1]), np.hypot(sg[:, 0], sg[:, 1])
        k_end = np.searchsorted(t, 22.0) - 1
        grow.append({"eh_at_12s": float(eh[np.searchsorted(t, 12.0)]), "eh_at_17s": float(eh[np.searchsorted(t, 17.0)]),
                     "eh_at_22s": float(eh[k_end]), "sigma_h_at_22s": float(sh[k_end]),
                     "ez_at_22s": float(abs(e[k_end, 2]))})
        after = np.nonzero((t >= 22.0) & (eh < 3 * sh) & (sh < 2 * sh[np.searchsorted(t, 12.0) - 1]))[0]
        rec.append(float(t[after[0]] - 22.0) if after.size else math.inf)
    outage = {"mean": {k: float(np.mean([g[k] for g in grow])) for k in grow[0]},
              "max_eh_at_22s": float(max(g["eh_at_22s"] for g in grow)),
              "recovery_s_max": float(max(rec)), "recovery_s_mean": float(np.mean(rec))}
    return {"error_std": std, "nees": nees_doc, "outage_12_22s": outage}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--figures", action="store_true", help="also compute the error/NEES/outage figures")
    ap.add_argument("--runs", type=int, default=25, help="seeded runs for NEES (default 25)")
    ap.add_argument("--seeds", type=int, default=10, help="seeded runs per error-std figure (default 10)")
    ap.add_argument("--json", default=None, help="write all figures to this JSON file")
    a = ap.parse_args(argv)
    doc = {"cycle": cycle_times()}
    for label, d in doc["cycle"].items():
        print(f"EKF cycle ({label}): " + ", ".join(f"{k} {v:.0f}" for k, v in d.items()))
    doc["replay"] = replay_rtf()
    r = doc["replay"]
    for label in ("estimates_every_predict", "estimates_10hz"):
        d = r[label]
        print(f"replay 60 s Table-1 stream ({r['samples']} samples, {label}): {d['wall_time_s']:.2f} s wall, "
              f"real-time factor {d['realtime_factor']:.0f}x ({d['us_per_sample']:.1f} us/sample; bar 20x, goal 100x)")
    if a.figures:
        doc["figures"] = figures(a.seeds, a.runs)
        f = doc["figures"]
        for win in ("window_5_10s", "window_5_30s"):
            print(f"\nfusion error std ({win}, mean over {a.seeds} seeds; m, m/s, deg)")
            short = [n.rsplit("_", 1)[0] for n in STATE_NAMES]
            print(f"{'variant':34s}" + "".join(f"{n:>11s}" for n in short))
            for label, d in f["error_std"].items():
                print(f"{label:34s}" + "".join(f"{d[win][n]:11.4g}" for n in STATE_NAMES))
        print("\nNEES / n (5-30 s, mean over seeds) and rejected updates per variant:")
        for label, d in f["error_std"].items():
            print(f"  {label:34s} {d['nees_per_state']:10.3g} {d['rejected_updates']:8d}")
        nd = f["nees"]
        print(f"\nNEES ({nd['runs']} runs, {nd['n_states']} states): mean {nd['mean_after_5s']:.2f}, band "
              f"[{nd['band'][0]:.2f}, {nd['band'][1]:.2f}], inside for {100 * nd['fraction_inside_after_5s']:.1f} % "
              f"of epochs after 5 s (default road noise: mean {nd['default_config_mean_after_5s']:.2f})")
        o = f["outage_12_22s"]
        om = o["mean"]
        print(f"outage 12-22 s: horizontal error {om['eh_at_12s']:.2f} m -> {om['eh_at_17s']:.2f} m (5 s) -> "
              f"{om['eh_at_22s']:.2f} m (10 s, max {o['max_eh_at_22s']:.2f} m, sigma {om['sigma_h_at_22s']:.2f} m), "
              f"vertical {om['ez_at_22s']:.2f} m; recovered (< 3 sigma) {o['recovery_s_mean']:.2f} s after "
              f"(max {o['recovery_s_max']:.2f} s)")
    if a.json:
        Path(a.json).write_text(json.dumps(doc, indent=2, default=float) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
