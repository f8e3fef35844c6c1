"""The paper's experiments (vdps_hil.experiments.paper_tasks, ``vdps paper``): a reduced, seeded version of the paper's experiments through
the real chain (simulated wire formats -> /raw/ decode -> VdpsSystem), asserting the issue-6
acceptance thresholds that the chain reaches, and marking the one it does not reach with the
paper's linear-tire predictor (the left turn within 3 m / 3 deg) as a strict expected failure
with the measured figures and their cause (so a fix shows up as an XPASS).

Runtime: one paper-left-turn drive (15 s, identification + left turn + warning), the SUV fishhook,
one lane change and a 12 s noise-free Table 3 drive: about a minute on one core.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vdps_hil.experiments import paper_tasks as P
from vdps_hil.experiments.scoring import FUSION_NAMES

PROFILE = "table1-susp1k"


IDENT_SEEDS = (30, 31, 32)
"""Held-out seeds of the identification experiment. It ran on seed 1 until 2026-12-06, one of the
two ``paper-left-turn`` drives the identification thresholds were chosen on
(``ident_study.TUNING_SEEDS``); on the held-out seeds 30-37 the per-seed bounds below failed on
some seeds (seed 30: I_z -13.6 %, the left turn 17.2 m; seed 34 one false alarm), so the
assertions take the acceptance's own form, the median over seeds (``tools/paper_full.py``: 20)."""


@pytest.fixture(scope="module")
def ident_runs():
    """The identification experiment on each of ``IDENT_SEEDS`` (the harness scores; the chain
    sees /raw/)."""
    from vdps_hil.experiments.seeds import check_held_out

    check_held_out(IDENT_SEEDS, __name__)
    return [P.identification_task(PROFILE, s) for s in IDENT_SEEDS]


def _median(runs, get) -> float:
    return float(np.median([get(r) for r in runs]))


# ------------------------------------------------------------------------------ pure helpers
def test_snr_is_minus_ten_log_of_the_mean_noise_to_signal_variance_ratio():
    rng = np.random.default_rng(5)
    t = list(range(1000))
    clean = rng.normal(0.0, 1.0, (1000, 6)) * np.array([1, 2, 3, 100, 200, 300])
    for ratio_db in (10.0, 30.0):
        noise = rng.normal(0.0, 1.0, (1000, 6)) * np.array([1, 2, 3, 100, 200, 300]) * 10 ** (-ratio_db / 20)
        noisy = clean + noise
        expect = -10 * math.log10(np.mean(np.var(noise, axis=0) / np.var(noisy, axis=0)))
        got = P.snr_db({"t_ns": t, "series": noisy}, {"t_ns": t, "series": clean})
        assert got == pytest.approx(expect, rel=1e-12)
        assert got == pytest.approx(ratio_db, abs=0.5)  # sampling spread of 1000 samples
    assert math.isnan(P.snr_db({"t_ns": [1, 2], "series": clean[:2]}, {"t_ns": [3, 4], "series": clean[:2]}))


def _saturating_runs(seed: int = 7):
    """A zero-noise series and the same series with a noise error e (linear in k), two channels
    so noisy at k = 1 that their noise-to-signal ratio saturates (var(e) = 4 and 9 x var(s_0))."""
    rng = np.random.default_rng(seed)
    t = list(range(2000))
    clean = rng.normal(0.0, 1.0, (2000, 6)) * np.array([1, 2, 3, 100, 200, 300])
    e = rng.normal(0.0, 1.0, (2000, 6)) * np.array([0.03, 0.45, 0.1, 200.0, 600.0, 3.0])
    return t, clean, e


def test_snr_noise_scale_gives_the_target_snr_of_the_definition():
    t, clean, e = _saturating_runs()
    ref = {"t_ns": t, "series": clean}
    run1 = {"t_ns": t, "series": clean + e}
    snr1 = P.snr_db(run1, ref)
    for target in (30.0, 20.0, 10.0):
        k = P.snr_noise_scale(run1, ref, target)
        got = P.snr_db({"t_ns": t, "series": clean + k * e}, ref)
        assert got == pytest.approx(target, abs=1e-6)  # the model is exact for an error linear in k
        # the 20 log10 rule misses because var(s_k) holds the noise too (this drive: by > 3 dB)
        k_rule = 10 ** ((snr1 - target) / 20)
        assert abs(P.snr_db({"t_ns": t, "series": clean + k_rule * e}, ref) - target) > 3.0
        # from a run at another noise scale the same k follows
        half = {"t_ns": t, "series": clean + 0.5 * e}
        assert P.snr_noise_scale(half, ref, target, run_k=0.5) == pytest.approx(k, rel=1e-9)
    # every ratio saturates at 1 as k grows: SNR >= 0 dB, a negative target is out of reach
    assert math.isnan(P.snr_noise_scale(run1, ref, -1.0))
    assert math.isnan(P.snr_noise_scale(run1, {"t_ns": [-1, -2], "series": clean[:2]}, 20.0))


# ----------------------------------------------------------------- through the real chain
def test_every_parameter_moves_from_prior_toward_truth_and_mass_and_inertias_within_bounds(ident_runs):
    """Acceptance (table1-susp1k), as medians over the held-out seeds (the acceptance's form; 20
    seeds in tools/paper_full.py): error at 10.25 s below a fifth of the prior error; mass <= 0.5 %,
    I_x, I_y, I_z <= 10 % (the tracking stiffnesses' fifth: the expected failure below). Measured (seeds 30 / 31 / 32): mass +0.03 / +0.03 / +0.01 %, I_x +4.4 /
    +4.1 / +4.5 %, I_y -5.6 / -1.5 / -5.5 %, I_z -13.6 / -0.1 / -2.5 %, cornering rear -19.2 / -4.6 /
    -6.5 % (secant slopes of the Magic Formula truth). On every seed the report is at 10.25 s and the
    mass and inertias are within 2 sigma of the identifier's own sigma (largest ratio 1.35)."""
    prior = ident_runs[0]["prior_rel_err"]  # the same priors on every seed
    med = {k: _median(ident_runs, lambda r, k=k: abs(r["rel_err"][k])) for k in prior}
    assert med["mass_kg"] <= 0.005, med
    for k in P.INERTIA:
        assert med[k] <= 0.10, (k, med[k])
    for k in prior:
        if k not in TRACKING:  # below: not met on held-out seeds
            assert med[k] < abs(prior[k]) / 5.0, (k, med[k], prior[k])
    for r in ident_runs:
        assert P.T0_S - 0.01 <= r["t_ident_s"] <= P.T0_S + 0.01  # the report at 10.25 s (filter clock)
        sr = r["sigma_ratio"]
        assert all(sr[k] <= 2.0 for k in ("mass_kg", *P.INERTIA)), (r["seed"], sr)


TRACKING = tuple(f"tracking_stiffness_{i}_n" for i in range(1, 5))


@pytest.mark.xfail(strict=True, reason="measured on held-out seeds (2026-12-06): wheel 3's tracking stiffness "
                   "-9.3 / -6.3 / -13.3 % on seeds 30 / 31 / 32 (median 9.3 %; over seeds 30-37 median 8.3 %) "
                   "against 8 %, a fifth of its -40 % prior error (wheels 1, 2, 4: medians 5.1-5.6 %, their bars "
                   "8-10 %); on seed 1, a tuning seed, -3.9..-6.6 %. Cause (2026-12-07, from the truth, harness only): the "
                   "truth's Magic Formula tire with combined slip is softer than its small-slip slope over this drive; "
                   "its own least-squares secant sum(F_x kappa)/sum(kappa^2) over 0-10.25 s is -3.9 / -4.3 / -6.2 / "
                   "-3.4 % (wheels 1-4; the same on seeds 30-32, the truth does not depend on the seed), so 6.2 of "
                   "wheel 3's 8 % are the tire law the linear model cannot hold, and the sensor noise spreads the rest "
                   "(tools/tire_secant.py)")
def test_tracking_stiffnesses_below_a_fifth_of_their_prior_error(ident_runs):
    prior = ident_runs[0]["prior_rel_err"]
    for k in TRACKING:
        med = _median(ident_runs, lambda r, k=k: abs(r["rel_err"][k]))
        assert med < abs(prior[k]) / 5.0, (k, med, prior[k])


@pytest.mark.xfail(strict=True, reason="linear-tire predictor (eq 15) vs Magic Formula truth: 4.8-7.0 m / "
                   "4.9-7.0 deg at +4.75 s (seed 1: 6.95 m / 7.00 deg; held-out seeds 30-32: 17.2 / 3.8 / 7.0 m, median "
                   "7.0 m); TRUE parameters and TRUE initial state give "
                   "6.0 m / 5.9 deg, the predictor with the truth's Magic Formula 0.13 m / 0.15 deg (chain init: "
                   "1.05 m / 0.78 deg). The held turn's slips (front 3.0 deg, a_y 6.3 m/s^2) exceed the sine's "
                   "(1.8 deg): stiffnesses fitted to the truth's own forces over the sine leave 5.5-5.7 m / 5.5-5.7 "
                   "deg, the turn's own secant 0.69 m (tools/left_turn_budget.py)")
def test_left_turn_prediction_within_three_metres_and_degrees(ident_runs):
    assert _median(ident_runs, lambda r: r["left_turn"]["position_err_m"]) <= 3.0
    assert _median(ident_runs, lambda r: abs(r["left_turn"]["yaw_err_deg"])) <= 3.0


def test_left_turn_prediction_is_bounded_and_no_false_alarm_on_the_left_turn(ident_runs):
    """Measured (seeds 30 / 31 / 32): 17.2 / 3.8 / 7.0 m, 17.3 / 3.8 / 6.9 deg at 15 s; bound 10 m /
    10 deg on the median. No warning episode on any seed (seed 34, outside this set, had one). The
    warnings become valid once the cornering stiffnesses have stayed converged 1 s
    (``converged_hold_s``): on seeds 30 and 31 never within the 15 s (valid fraction 0.0), on 32
    0.70 (0.80 without the hold), so over the seeds at least a fifth of the frames are valid (the
    check is not vacuous)."""
    for r in ident_runs:
        lt = r["left_turn"]
        assert P.T0_S <= lt["t0_s"] <= P.T0_S + 0.01  # the first estimate at or after 10.25 s
        assert lt["t_end_s"] == pytest.approx(P.LEFT_TURN_END_S, abs=0.011)
        assert r["warning"]["false_alarms"] == 0 and r["warning"]["episodes"] == [], r["seed"]
        assert r["warning"]["frames_rejected"] == 0
    assert _median(ident_runs, lambda r: r["left_turn"]["position_err_m"]) <= 10.0
    assert _median(ident_runs, lambda r: abs(r["left_turn"]["yaw_err_deg"])) <= 10.0
    assert np.mean([r["warning"]["valid_fraction"] for r in ident_runs]) >= 0.2


def test_a_convergence_flicker_sends_no_false_alarm_on_the_left_turn():
    """Held-out seed 34 (found 2026-12-06, not a tuning drive): without the validity hold the
    cornering problem's status said converged for 40 ms at ~1.4 s with the front stiffness 13.6 %
    high, the frames were valid, and the chain, predicting from the identifier's current values,
    sent a false alarm (level 2; no truth event). Either guard alone removes it: the shipped
    ``converged_hold_s`` (1 s, chosen on ``prediction.warning.TUNING_SEEDS``), and predicting from
    the values identified (``predict_from``, ``identification.trusted``, added 2026-12-07). With
    both (the shipped system) the frames are valid later in the drive (measured: from 4.67 s, 69 %
    of the frames)."""
    from dataclasses import replace

    from vdps_hil.experiments.paper_chain import chain_run
    from vdps_hil.experiments.scoring import evaluate_warning_frames
    from vdps_hil.prediction.warning import load_warning_config

    pol, node = load_warning_config()
    got = {}
    for hold, source in ((pol.converged_hold_s, "identified"), (0.0, "identified"), (0.0, "current")):
        kw = {"warning_policy": replace(pol, converged_hold_s=hold), "warning_node": node, "predict_from": source}
        r = chain_run("paper-left-turn", P.profile_of(PROFILE), 34, system_kw=kw)
        got[hold, source] = evaluate_warning_frames(r["frames"], r["events"])
    shipped, neither = got[pol.converged_hold_s, "identified"], got[0.0, "current"]
    assert math.isnan(shipped.truth_point_of_no_return_t_s) and shipped.false_alarms == 0
    assert shipped.frames_invalid_status < shipped.frames_accepted and shipped.frames_rejected == 0  # some valid
    assert got[0.0, "identified"].false_alarms == 0
    assert neither.false_alarms >= 1  # the drive still holds the flicker the test is about


def test_fusion_errors_are_reported_for_every_state(ident_runs):
    for r in ident_runs:
        fs = r["fusion_std"]
        assert set(fs) == set(FUSION_NAMES)
        assert all(math.isfinite(v) and v >= 0 for v in fs.values())
        assert fs["psi_g_deg"] < 0.4  # below the GNSS attitude sigma of Table 1 (0.4 deg)


def test_rollover_predicted_and_warned_at_least_one_second_ahead():
    """fishhook-suv through the chain (suv-model, identifier running, started from the parameters
    identified on the paper's manoeuvre driven with the SUV): measured lead 2.49 s to the point of
    no return, 0.97 s to tip-up; acceptance lead >= 1.0 s, zero false alarms, valid warnings."""
    r = P.rollover_task(PROFILE, 1)
    assert abs(r["calibration"]["rel_err"]["mass_kg"]) <= 0.005
    assert r["valid_fraction"] >= 0.95
    assert r["predicted"] is True
    assert r["lead_time_s"] >= 1.0
    assert r["false_alarms"] == 0 and r["frames_rejected"] == 0
    assert math.isfinite(r["inaccuracy_pct"])
    # the paper's Fig 9 situation: the first prediction after the fishhook's last steering
    # change (the reversal ends at about 1.89 s) holds the true inputs; measured 28.2 % from
    # t0 1.905 s (paper 27.3 %) against 67.8 % for the first forecast at 1.215 s, made before
    # the reversal. Bounds: t0 within 0.3 s after the reversal, inaccuracy <= 35 %.
    h = r["held_inputs"]
    assert 1.85 <= h["prediction_t0_s"] <= 2.2
    assert h["inaccuracy_pct"] <= 35.0 and h["inaccuracy_pct"] < r["inaccuracy_pct"]


def test_no_false_alarm_on_the_lane_change():
    """From calibrated parameters (valid warnings for the whole run): no episode, level "none".
    Before the predictor took only the values identified (``identification.trusted``, 2026-12-07)
    seed 1 reached level 1 (caution) for a moment (an expected failure since the identification
    status merge of issue 17)."""
    r = P.false_alarm_task("lane-change-iso3888", PROFILE, 1)
    assert r["truth_events"] == 0 and r["valid_fraction"] >= 0.95 and r["max_level"] == 0
    assert r["false_alarms"] == 0 and r["episodes"] == []
    assert r["frames_accepted"] > 45 * r["duration_s"]  # 50 Hz, a few frames at the start excepted


def test_no_false_alarm_on_the_table1_sine_sweep_while_the_identifier_wanders():
    """Found 2026-12-07 by ``vdps paper --quick`` (seed 1; profile ``table1``, the suspension at
    1 Hz): started from a calibration drive's parameters, the identifier left them during the sine
    sweep (cornering on its bounds, then "not converged" with the rear stiffness at a third of the
    calibrated value) and a prediction from those current values foresaw a point of no return:
    a warning (level >= 2 at 4.31-5.01 s) while the truth's |LTR| stayed below 0.21. Predicting
    from the values identified (``identification.trusted``), none, the frames valid after the EKF's start.
    (Seed 1 is where it was found; no threshold was chosen on it.)"""
    from vdps_hil.experiments.paper_chain import chain_run
    from vdps_hil.experiments.scoring import evaluate_warning_frames

    kw, _ = P._start_kw("table1", 1, "sedan-model", None, P.ROLLOVER_CALIBRATION)
    got = {}
    for source in ("identified", "current"):
        r = chain_run("sine-sweep", "table1", 1, duration_s=6.0, system_kw={**kw, "predict_from": source})
        got[source] = evaluate_warning_frames(r["frames"], r["events"])
    shipped, current = got["identified"], got["current"]
    assert math.isnan(shipped.truth_point_of_no_return_t_s)
    assert shipped.false_alarms == 0 and shipped.frames_rejected == 0
    assert shipped.frames_invalid_status <= 0.02 * shipped.frames_accepted  # the EKF's start-up only
    assert current.false_alarms >= 1  # the drive still holds the wandering the test is about


def test_table3_minimum_eigenvalue_scales_with_q_squared_and_larger_q_converges_no_slower():
    """Table 3 on a 12 s noise-free drive: the identifiability of Q4 = qI is q^2 times that of
    I (same rows; to 1e-6 relative), and the paper's ordering holds: a larger q converges no later."""
    qs = (0.625, 0.125, 0.025)
    t3 = P.table3_task(PROFILE, 12.0, qs=qs)
    lam = [t3["rows"][q]["min_eigenvalue"] for q in qs]
    for q, lm in zip(qs[1:], lam[1:]):
        assert lm / lam[0] == pytest.approx((q / qs[0]) ** 2, rel=1e-6)
    conv = [t3["rows"][q]["convergence_s"] for q in qs]
    for j in range(3):
        times = [c[j] if math.isfinite(c[j]) else math.inf for c in conv]
        assert times == sorted(times)
