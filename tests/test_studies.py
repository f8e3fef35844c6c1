"""Tests of vdps_hil.batch.studies: the statistics (against numpy and textbook values), a small
weighting study through the engine (resumable, the noise-free row deterministic, the table
filled from the trials), option checks, and the effects study failing clearly without a
workbench entry point."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.batch.engine import EngineConfig
from vdps_hil.batch.studies import (STUDY_FILE, TRIALS_DIR, StudyOptions, format_study, run_study,
                                    summary, wilson)


@settings(max_examples=80, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=30))
def test_summary_matches_numpy(xs):
    s = summary(xs)
    a = np.array(xs)
    assert s["n"] == len(xs) and s["n_missing"] == 0
    assert s["mean"] == pytest.approx(a.mean(), rel=1e-9, abs=1e-6)
    assert s["std"] == pytest.approx(a.std(ddof=1) if len(xs) > 1 else 0.0, rel=1e-7, abs=1e-6)
    for p in (10, 50, 90):
        key = {10: "p10", 50: "median", 90: "p90"}[p]
        assert s[key] == pytest.approx(np.percentile(a, p), rel=1e-9, abs=1e-6)
    assert s["min"] == a.min() and s["max"] == a.max()


def test_summary_counts_missing_values():
    s = summary([1.0, None, float("nan"), 3.0, float("inf")])
    assert (s["n"], s["n_missing"], s["mean"]) == (2, 3, 2.0)
    assert summary([None, None])["mean"] is None and summary([None])["n_missing"] == 1


def test_wilson_interval_textbook_values():
    w = wilson(8, 10)
    # Wilson 95 % for 8/10: [0.490, 0.943] (e.g. Newcombe 1998, method 3)
    assert w["rate"] == 0.8
    assert w["lo"] == pytest.approx(0.490, abs=1e-3) and w["hi"] == pytest.approx(0.943, abs=1e-3)
    w0 = wilson(0, 20)
    assert w0["lo"] == 0.0 and w0["hi"] == pytest.approx(0.161, abs=1e-3)
    assert wilson(0, 0)["rate"] is None


def test_options_are_checked():
    with pytest.raises(ValueError, match="at least 1"):
        StudyOptions(seeds=0)
    with pytest.raises(ValueError, match="10.25"):
        StudyOptions(duration_s=10.0)
    with pytest.raises(ValueError, match=">= 0"):
        StudyOptions(noise_scales=(-1.0,))
    with pytest.raises(ValueError, match="unknown study"):
        run_study("astrology", StudyOptions(), out_dir="/nonexistent")


def test_weighting_study_runs_resumes_and_reports(tmp_path):
    # two noise-free seeds would be identical: the study runs the k = 0 row once
    opt = StudyOptions(seeds=2, noise_scales=(0.0,), duration_s=11.0, qs=(0.625, 0.005))
    cfg = EngineConfig(backend="inline")
    doc = run_study("weighting", opt, cfg, out_dir=tmp_path)
    assert [p.name for p in (tmp_path / TRIALS_DIR).iterdir()] == ["weighting-k0-seed1.json"]
    assert json.loads((tmp_path / STUDY_FILE).read_text()) == doc
    rows = {r["q"]: r for r in doc["table"]}
    assert set(rows) == {0.625, 0.005} and all(r["deterministic"] and r["ok"] == 1 for r in rows.values())
    trial = json.loads((tmp_path / TRIALS_DIR / "weighting-k0-seed1.json").read_text())["result"]
    # the table is the trial's numbers (one trial: mean = the value, sd 0)
    for q, r in rows.items():
        t = trial["rows"][f"{q:g}"]
        assert r["min_eigenvalue"]["mean"] == t["min_eigenvalue"] and r["min_eigenvalue"]["std"] == 0.0
    # Table 3's ordering: a larger q gives a larger minimum eigenvalue (better observability)
    assert rows[0.625]["min_eigenvalue"]["mean"] > 100 * rows[0.005]["min_eigenvalue"]["mean"]
    # q = 0.005 does not converge within 11 s for any inertia (the paper's "Nan" row)
    assert all(s["n"] == 0 and s["n_missing"] == 1 for s in rows[0.005]["convergence_s"].values())
    text = format_study(doc)
    assert "q 0.005" in text and "never (0/1)" in text and "paper NaN NaN NaN" in text
    # rerun: the trial is reused (same key), same table
    doc2 = run_study("weighting", opt, cfg, out_dir=tmp_path)
    assert doc2["stages"][0]["run"]["reused"] == 1 and doc2["table"] == doc["table"]


def test_effects_table_counts_hits_found_confusions_and_false_alarms(monkeypatch):
    # the aggregation on trial outcomes of known content (the trials themselves: next test)
    from vdps_hil.batch import studies
    from vdps_hil.batch.worker import Outcome

    recs = {("aero_drag", 1): ["aero_drag"], ("aero_drag", 2): ["rolling_resistance", "aero_drag"],
            ("aero_drag", 3): [], ("crosswind", 1): ["crosswind"], ("crosswind", 2): ["crosswind"],
            ("crosswind", 3): None}  # None: the trial failed

    def stage(label, tasks):
        out = {}
        for t in tasks:
            kw = t.kwargs
            if kw["effect"] is None:
                res = {"recommended": ["aero_drag"] if kw["seed"] == 1 else [], "false_alarm": kw["seed"] == 1}
                out[t.id] = Outcome(t.id, "ok", res, None, {})
                continue
            rec = recs[(kw["effect"], kw["seed"])]
            if rec is None:
                out[t.id] = Outcome(t.id, "failed", None, {"type": "X", "message": "y"}, {})
            else:
                out[t.id] = Outcome(t.id, "ok", {"recommended": rec, "hit": bool(rec) and rec[0] == kw["effect"],
                                                 "found": kw["effect"] in rec}, None, {})
        return out

    opt = StudyOptions(seeds=3, effects=("aero_drag", "crosswind"), null_maneuvers=("straight",))
    doc = studies._effects(opt, stage)
    rows = {r["effect"]: r for r in doc["table"]}
    assert (rows["aero_drag"]["hit_rate"]["hits"], rows["aero_drag"]["hit_rate"]["n"]) == (1, 3)
    assert rows["aero_drag"]["found_rate"]["hits"] == 2
    assert rows["aero_drag"]["first_recommended_instead"] == {"rolling_resistance": 1}
    assert (rows["crosswind"]["ok"], rows["crosswind"]["hit_rate"]["rate"]) == (2, 1.0)
    assert doc["null"]["false_alarm_rate"]["hits"] == 1 and doc["null"]["trials"] == 3


@pytest.mark.slow
def test_one_hidden_effect_trial_through_the_workbench(tmp_path):
    opt = StudyOptions(seeds=1, effects=("aero_drag",))
    doc = run_study("effects", opt, EngineConfig(backend="inline"), out_dir=tmp_path)
    assert doc["stages"][0]["failed"] == []
    (row,) = doc["table"]
    trial = json.loads((tmp_path / TRIALS_DIR / "effect-aero_drag-seed1.json").read_text())["result"]
    assert row["ok"] == 1 and row["hit_rate"]["hits"] == int(trial["hit"])
    assert trial["hit"] == (trial["recommended"][:1] == ["aero_drag"])
    assert "aero_drag" in format_study(doc)
