"""Tests of ``tools/workbench_study_cr.py``'s ``add`` figures: the prediction error attributable
to saturation (the saturation drive's minus the linear-tire drive's, both of the base model) and
the fraction of it that ``--add magic_formula_tire`` removes. The study itself runs minutes per
seed (``tools/``); its refusal of tuning seeds is tested in ``tests/test_seeds.py``."""

from __future__ import annotations

import math
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))

import workbench_study_cr as wsc  # noqa: E402


def _run(kind, seed, before, after, rec=None):
    return {"kind": kind, "set": 1, "seed": seed, "recommendation": rec,
            "add_before": {"2": {"position_m": before[0], "yaw_deg": before[1]}},
            "add_after": {"2": {"position_m": after[0], "yaw_deg": after[1]}}}


def test_attributable_error_and_the_fraction_removed():
    add = _run("add", 5, (0.9, 2.0), (0.75, 1.5), "magic_formula_tire")
    null = _run("add-null", 5, (0.7, 1.6), (0.7, 1.7))
    f = wsc.add_figures(add, null)
    assert f["position_m"]["attributable"] == pytest.approx(0.2)
    assert f["position_m"]["removed"] == pytest.approx(0.75)  # 0.15 of 0.2
    assert f["yaw_deg"]["removed"] == pytest.approx(1.25)  # better than the drive without saturation
    # nothing attributable (the linear drive predicts worse): no fraction, never counted as met
    f = wsc.add_figures(add, _run("add-null", 5, (1.0, 2.5), (1.0, 2.5)))
    assert math.isnan(f["position_m"]["removed"]) and not f["position_m"]["removed"] >= 0.5


def test_the_summary_counts_seeds_meeting_half_and_saturation_named_without_it():
    runs = [_run("add", 1, (0.9, 2.0), (0.75, 1.5), "magic_formula_tire"), _run("add-null", 1, (0.7, 1.6), (0.7, 1.6)),
            _run("add", 2, (0.9, 2.0), (0.85, 1.9), "magic_formula_tire"),
            _run("add-null", 2, (0.7, 1.6), (0.7, 1.6), "magic_formula_tire")]
    text = "\n".join(wsc.summary(runs))
    assert "cr1: --add takes >= 50 % off the position" in text and "  1/2" in text.split("off the position")[1][:12]
    assert "pooled over the 2 seeds with an attributable part: 0.2 of 0.4 removed (50 %)" in text
    assert "cr1: no saturation recommended without it" in text and "  1/2" in text.split("without it")[1][:12]
    assert "of the 2 seeds with an attributable part: 1 with >= 50 % removed" in text
    assert "--add's fitted parameters at a bound of their range (not identified) on 0 of 2 seeds" in text
    # a peak friction on its upper bound, recorded before the status existed (value and sigma only)
    mf = {"peak_friction": {"value": 1.6, "sigma": 0.0027}, "shape_lateral": {"value": 1.3, "sigma": None}}
    runs[2]["add_parameters"] = {"magic_formula_tire": mf, "identified": {"mass_kg": {"before": 1.0, "after": 1.0}}}
    assert wsc._at_bound(runs[2]) == [("magic_formula_tire", "peak_friction")]
    assert "at a bound of their range (not identified) on 1 of 2 seeds: 2" in "\n".join(wsc.summary(runs))
    mf["peak_friction"]["value"] = 1.05
    assert wsc._at_bound(runs[2]) == []
    jobs = wsc.jobs_for(3, 1000)
    kinds = {j["kind"]: j for j in jobs}
    assert kinds["add"]["truth"] == "commonroad-mb:3" and kinds["add-null"]["truth"] == "commonroad-mb:3:linear-lateral"
    assert kinds["add"]["add"] == kinds["add-null"]["add"] == "magic_formula_tire"


def test_a_model_effect_keys_its_runs_apart_and_a_bad_one_is_one_line(capsys):
    """``--model-effect``: a run with a model effect is another run in a ``--runs`` file (the key of
    a run without one is unchanged, so older files still resume); an unknown effect or parameter
    refuses the study in one line (exit 2) before anything is simulated."""
    job = wsc.jobs_for(1, 1000)[0]
    spec = "load_dependent_cornering_stiffness:load_slope=1,load_degression=0"
    assert wsc._key(job) == '["saturation", "magic_formula_tire", "shipped:cr-circle-ramp", "commonroad-mb:1", 1000]'
    assert wsc._key(dict(job, model_effects=[spec])) != wsc._key(job)
    eff = wsc.model_effect_set([spec])["load_dependent_cornering_stiffness"]
    assert (eff.load_slope, eff.load_degression) == (1.0, 0.0)
    for bad in ("no_such_effect", "load_dependent_cornering_stiffness:slope=1", "aero_drag:cda_m2=x"):
        assert wsc.main(["--model-effect", bad, "--seeds", "1"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("workbench_study_cr: model effect") and "\n" not in err and "Traceback" not in err
