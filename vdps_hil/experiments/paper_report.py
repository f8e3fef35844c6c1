"""The paper's published values beside ours (``vdps paper``): the document of one profile from its
task results (JSON, ``profile_doc``) and the side-by-side text table (``format_report``).

Aggregation over the seeds: medians and 90th percentiles of |e| (e = (identified - true) / true,
``experiments.scoring.relative_errors``), ``within_2_sigma`` = the fraction of seeds with
|identified - true| <= 2 sigma; medians skip None and NaN (``finite_median``). The experiments
and their definitions: ``experiments.paper_tasks``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from vdps_hil.experiments.paper_tasks import INERTIA, LEFT_TURN_END_S, SNR_TARGETS_DB, T0_S

if TYPE_CHECKING:
    from vdps_hil.experiments.paper_run import PaperOptions

__all__ = ["PAPER", "DEFINITIONS", "aggregate_identification", "finite_median", "profile_doc", "format_report"]

PAPER: dict[str, Any] = {
    "identification_rel_err_pct": {"mass_kg": 5.17e-3, "inertia_x_kgm2": 0.12, "inertia_y_kgm2": 5.05,
                                   "inertia_z_kgm2": 4.37},
    "left_turn_inaccuracy_pct": 0.51,
    "rollover_inaccuracy_pct": 27.3,
    # Table 2: relative inaccuracy of I_x, I_y, I_z [%] per SNR [dB] (None = "infinite")
    "snr_table": {None: (1.94, 2.68, 0.33), 30.0: (2.50, 14.62, 1.52), 20.0: (14.91, 60.28, 10.41),
                  10.0: (69.05, 93.63, 54.11)},
    # Table 3: time to 90 % of the real value of I_x, I_y, I_z [s] per Q4 = diag(q, q, q) (nan = "Nan")
    "weighting_table": {0.625: (0.08, 1.63, 0.24), 0.125: (6.19, 18.2, 3.32), 0.025: (36.0, math.nan, 25.0),
                        0.005: (math.nan, math.nan, math.nan)},
}
"""The paper's published figures (section 7.2-7.3, section 8 Tables 2-3)."""

DEFINITIONS = {
    "rel_err": "(identified - true) / true; true = the truth vehicle file (harness only)",
    "identification": "at t = 10.25 s of paper-left-turn; median / p90 of |rel_err| over the seeds; "
                      "within_2_sigma = fraction of seeds with |identified - true| <= 2 sigma",
    "snr_db": "-10 log10(mean_c var(s_k,c - s_0,c) / var(s_k,c)), s = (omega_dot_x,y,z, M_x,y,z) of the inertia "
              "problem over 5-10.25 s, s_0 the same drive with zero-noise sensors (noise-free = zero-noise sensors, "
              "never /truth/)",
    "inaccuracy_pct": "mean over xa ya za psi_v theta_v phi_v of RMS(pred - true) / max(range(true - true(t0)), "
                      "1 m or 1 deg) (prediction.metrics)",
    "lead_time_s": "t(point of no return, truth) - t(first valid VDPS_Warning frame with level >= warning)",
    "convergence_s": "first time from which |I - I_true| <= 10 % I_true holds to the end (Table 3 footnote a)",
}


def aggregate_identification(docs: Sequence[dict]) -> dict:
    """Per parameter over the seeds: median and 90th percentile of |e| at 10.25 s and of the
    window mean, the prior error, the worst seed's |e| / |prior e|, within_2_sigma."""
    docs = [d for d in docs if "rel_err" in d]
    out = {}
    if not docs:
        return out
    for k in docs[0]["rel_err"]:
        e = np.abs([d["rel_err"][k] for d in docs]) * 100.0
        em = np.abs([d["rel_err_mean_window"][k] for d in docs]) * 100.0
        prior = abs(docs[0]["prior_rel_err"][k]) * 100.0
        out[k] = {"median_rel_err_pct": float(np.median(e)), "p90_rel_err_pct": float(np.percentile(e, 90)),
                  "median_rel_err_mean_5_10_pct": float(np.median(em)),
                  "p90_rel_err_mean_5_10_pct": float(np.percentile(em, 90)),
                  "signed_median_rel_err_pct": float(np.median([d["rel_err"][k] for d in docs]) * 100.0),
                  "prior_rel_err_pct": prior, "max_over_prior": float(np.max(e) / prior) if prior else math.nan,
                  "within_2_sigma": float(np.mean([d["sigma_ratio"][k] <= 2.0 for d in docs])),
                  "paper_rel_err_pct": PAPER["identification_rel_err_pct"].get(k)}
    return out


def finite_median(vals):
    """The median of the values that are neither None nor NaN (NaN when none is left)."""
    v = [x for x in vals if x is not None and not (isinstance(x, float) and math.isnan(x))]
    return float(np.median(v)) if v else math.nan


def profile_doc(prof: str, per: dict, opt: PaperOptions, seeds) -> dict:
    """The document of one profile (``run_paper``'s JSON) from its task results ``per``: kind ->
    result(s) of ``paper_tasks`` ("ident", "false_alarm", "rollover", "table3", "snr0", "snr1",
    "snr_k", "snr_rows")."""
    doc: dict = {"profile": prof, "seeds": list(seeds)}
    ident = [d for d in per["ident"] if d]
    if ident:
        doc["identification"] = aggregate_identification(ident)
        fs = [d["fusion_std"] for d in ident if d.get("fusion_std")]
        if fs:
            doc["fusion_std"] = {k: float(np.mean([f[k] for f in fs])) for k in fs[0]}
        lt = [d["left_turn"] for d in ident if "left_turn" in d]
        if lt:
            doc["prediction"] = {"left_turn": {
                "position_err_m": finite_median([x["position_err_m"] for x in lt]),
                "yaw_err_deg": finite_median([abs(x["yaw_err_deg"]) for x in lt]),
                "inaccuracy_pct": finite_median([x["inaccuracy_pct"] for x in lt]),
                "p90_position_err_m": float(np.percentile([x["position_err_m"] for x in lt], 90)),
                "p90_yaw_err_deg": float(np.percentile([abs(x["yaw_err_deg"]) for x in lt], 90)),
                "horizon_s": LEFT_TURN_END_S - T0_S, "paper_inaccuracy_pct": PAPER["left_turn_inaccuracy_pct"]}}
        doc["per_seed"] = [{k: d.get(k) for k in ("seed", "rel_err", "sigma_ratio", "left_turn", "warning")}
                           for d in ident]
    fa_total = 0
    fa_rows = {}
    if opt.false_alarms:
        lt_fa = sum(d.get("warning", {}).get("false_alarms", 0) for d in ident)
        fa_rows["paper-left-turn"] = {"runs": len(ident), "false_alarms": lt_fa, "valid_fraction":
                                      finite_median([d.get("warning", {}).get("valid_fraction") for d in ident])}
        fa_total += lt_fa
        for d in per["false_alarm"]:
            fa_rows[d["scenario"]] = {"runs": 1, "false_alarms": d["false_alarms"], "duration_s": d["duration_s"],
                                      "max_level": d["max_level"], "valid_fraction": d["valid_fraction"]}
            fa_total += d["false_alarms"]
    roll = per.get("rollover")
    if roll:
        doc.setdefault("prediction", {})["rollover"] = {
            "predicted": roll["predicted"], "inaccuracy_pct": roll.get("inaccuracy_pct", math.nan),
            "scenario": "fishhook-suv", "prediction_t0_s": roll.get("prediction_t0_s"),
            "prediction_end_s": roll.get("prediction_end_s"),
            "held_inputs": roll.get("held_inputs"),
            "inaccuracy_held_inputs_pct": (roll.get("held_inputs") or {}).get("inaccuracy_pct", math.nan),
            "paper_inaccuracy_pct": PAPER["rollover_inaccuracy_pct"]}
        doc["warning"] = {"lead_time_s": roll["lead_time_s"], "lead_to_tipup_s": roll["lead_to_tipup_s"],
                          "lead_time_matched_side_s": roll["lead_time_matched_side_s"],
                          "truth_point_of_no_return_t_s": roll["truth_point_of_no_return_t_s"],
                          "first_warning_t_s": roll["first_warning_t_s"]}
    if opt.false_alarms:
        doc.setdefault("warning", {})["false_alarms"] = fa_total
        doc["warning"]["false_alarm_runs"] = fa_rows
    if opt.snr_table and per.get("snr1"):
        rows = []

        def row(label, k, docs):
            errs = [d["rel_err"] for d in docs if d.get("rel_err")]
            return {"label": label, "noise_scale": k, "snr_db": finite_median([d["snr_db"] for d in docs]),
                    "rel_err_pct": {n: finite_median([abs(e[n]) * 100 for e in errs]) for n in INERTIA}}
        rows.append(dict(row("zero-noise", 0.0, per["snr0"]), paper_snr_db=None,
                         paper_rel_err_pct=dict(zip(INERTIA, PAPER["snr_table"][None]))))
        rows.append(dict(row("profile (k = 1)", 1.0, per["snr1"]), paper_snr_db=None, paper_rel_err_pct=None))
        for target in SNR_TARGETS_DB:
            rows.append(dict(row(f"{target:g} dB target", per["snr_k"][target],
                                 per.get("snr_rows", {}).get(target, [])),
                             paper_snr_db=target, paper_rel_err_pct=dict(zip(INERTIA, PAPER["snr_table"][target]))))
        doc["snr_table"] = rows
    t3 = per.get("table3")
    if t3:
        doc["weighting_table"] = [
            {"q": q, "min_eigenvalue": v["min_eigenvalue"], "convergence_s": dict(zip(INERTIA, v["convergence_s"])),
             "final_rel_err_pct": dict(zip(INERTIA, (100 * e for e in v["final_rel_err"]))),
             "paper_convergence_s": dict(zip(INERTIA, PAPER["weighting_table"][q])), "duration_s": t3["duration_s"]}
            for q, v in t3["rows"].items()]
    return doc


def _f(v, fmt="{:.3g}") -> str:
    if v is None:
        return "-"
    if isinstance(v, float) and math.isnan(v):
        return "NaN"
    return fmt.format(v)


def format_report(doc: dict) -> str:
    """The side-by-side table (paper vs ours) of a ``run_paper`` document."""
    docs = doc["profiles"] if "profiles" in doc else {doc["profile"]: doc}
    lines = []
    for prof, d in docs.items():
        seeds = d.get("seeds", [])
        which = f" ({', '.join(map(str, seeds))}: no tuning seed)" if 0 < len(seeds) <= 3 else \
            f" ({seeds[0]}-{seeds[-1]} without the tuning seeds)" if seeds else ""
        lines.append(f"== profile {prof}: {len(seeds)} seeds{which} ==")
        if "fusion_std" in d:
            lines.append("Fusion (Fig 4): std of estimate - truth over 5-10 s, mean over seeds "
                         "(the paper gives these only in its figure)")
            lines.append("  " + "  ".join(f"{k} {_f(v)}" for k, v in d["fusion_std"].items()))
        if "identification" in d:
            lines.append("Identification at 10.25 s, |rel err| % over seeds (paper: section 7.2)")
            lines.append(f"  {'parameter':32s} {'prior':>7s} {'median':>8s} {'p90':>8s} {'mean5-10':>9s} "
                         f"{'<=2sig':>7s} {'paper':>8s}")
            for k, v in d["identification"].items():
                lines.append(f"  {k:32s} {_f(v['prior_rel_err_pct'], '{:7.1f}')} "
                             f"{_f(v['median_rel_err_pct'], '{:8.3f}')} {_f(v['p90_rel_err_pct'], '{:8.3f}')} "
                             f"{_f(v['median_rel_err_mean_5_10_pct'], '{:9.3f}')} "
                             f"{_f(v['within_2_sigma'], '{:7.2f}')} {_f(v['paper_rel_err_pct'], '{:8.4g}')}")
        pr = d.get("prediction", {})
        if "left_turn" in pr:
            lt = pr["left_turn"]
            lines.append(f"Left turn (Fig 8), predicted from 10.25 s for {lt['horizon_s']:.2f} s, median over seeds: "
                         f"position {_f(lt['position_err_m'], '{:.2f}')} m (p90 {_f(lt['p90_position_err_m'], '{:.2f}')})"
                         f", yaw {_f(lt['yaw_err_deg'], '{:.2f}')} deg (p90 {_f(lt['p90_yaw_err_deg'], '{:.2f}')}), "
                         f"inaccuracy {_f(lt['inaccuracy_pct'], '{:.2f}')} %   (paper: 0.51 %)")
        if "rollover" in pr:
            ro = pr["rollover"]
            lines.append(f"Rollover ({ro['scenario']}): predicted {ro['predicted']}, first forecasting prediction "
                         f"t0 {_f(ro['prediction_t0_s'], '{:.2f}')} s, inaccuracy {_f(ro['inaccuracy_pct'], '{:.1f}')} %"
                         f"   (paper Fig 9: 27.3 %)")
            hi = ro.get("held_inputs") or {}
            lines.append(f"  first prediction after the last input change (inputs truly held, as the paper's Fig 9): "
                         f"t0 {_f(hi.get('prediction_t0_s'), '{:.2f}')} s, inaccuracy "
                         f"{_f(hi.get('inaccuracy_pct'), '{:.1f}')} %   (paper Fig 9: 27.3 %)")
        w = d.get("warning")
        if w:
            if "lead_time_s" in w:
                lines.append(f"Warning: lead time to point of no return {_f(w['lead_time_s'], '{:.2f}')} s "
                             f"(first warning {_f(w['first_warning_t_s'], '{:.2f}')} s, PONR "
                             f"{_f(w['truth_point_of_no_return_t_s'], '{:.2f}')} s), to tip-up "
                             f"{_f(w['lead_to_tipup_s'], '{:.2f}')} s, same-side {_f(w['lead_time_matched_side_s'], '{:.2f}')} s")
            if "false_alarms" in w:
                runs = ", ".join(f"{k} {v['false_alarms']} in {v['runs']} run(s), valid "
                                 f"{100 * v['valid_fraction']:.0f} %" for k, v in w["false_alarm_runs"].items())
                lines.append(f"False alarms: {w['false_alarms']} ({runs})")
        if "snr_table" in d:
            lines.append("Table 2: |rel err| % of Ix Iy Iz at 10.25 s vs SNR (SNR = -10 log10 mean over wdot_xyz, "
                         "M_xyz of var(noise error) / var(signal), 5-10.25 s; noise error = vs the same drive on "
                         "zero-noise sensors)")
            for r in d["snr_table"]:
                ours = " ".join(_f(r["rel_err_pct"][n], "{:7.2f}") for n in INERTIA)
                pap = " ".join(_f(v, "{:6.2f}") for v in r["paper_rel_err_pct"].values()) if r["paper_rel_err_pct"] \
                    else "  (no paper row)"
                lines.append(f"  {r['label']:18s} k {_f(r['noise_scale'], '{:6.3g}')} SNR {_f(r['snr_db'], '{:5.1f}')} dB"
                             f"  ours {ours}   paper {pap}")
        if "weighting_table" in d:
            lines.append("Table 3: Q4 = diag(q,q,q), W4 = I, P(0) = I, noise-free; time to within 10 % [s], "
                         "min eigenvalue of sum A^T Q^T Q A")
            for r in d["weighting_table"]:
                ours = " ".join(_f(v, "{:6.2f}") for v in r["convergence_s"].values())
                pap = " ".join(_f(v, "{:6.2f}") for v in r["paper_convergence_s"].values())
                lines.append(f"  q {r['q']:<6g} lambda_min {_f(r['min_eigenvalue'], '{:9.3g}')}  ours {ours}   "
                             f"paper {pap}")
        lines.append("")
    if "wall_time_s" in doc:
        lines.append(f"wall time {doc['wall_time_s']:.0f} s")
    return "\n".join(lines)
