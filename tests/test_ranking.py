"""Acceptance of the ranking on drives with a hidden effect (issue 9), two seeds per effect.

Each drive is simulated with one effect hidden in the truth (maneuver and magnitude per effect:
``vdps_hil.experiments.workbench_study``; refinements against the issue's wording are stated there:
12-20 s drives, a weaving crosswind drive, a 0.2-0.6 Hz sine sweep of 0.9 rad for the load-dependent
stiffness, the IMU bias on one straight-then-circle drive; Table 1 sensors with the suspension
at 100 Hz). The workbench reads only the recording's /raw/ topics and the model vehicle file.

A *hit* is the hidden effect recommended, named by the recommendation as equivalent, or in the
top equivalence group together with the recommendation (``study.is_hit``; a top group with
nothing recommended, "no missing effect found", is not a hit). The goals of the issue (>= 90 % hits per effect, null in
>= 95 %) are measured on >= 20 seeds by ``tools/workbench_study.py``; here every hidden drive of
the two seeds must be a hit and every nothing-hidden drive must recommend nothing. Effects that
miss on a test seed are marked ``xfail(strict=True)`` with the measured figure, so an improvement
shows up as XPASS and fails the suite until the mark is removed. Effects below the goal in the
study that still hit on both test seeds (tire saturation 12/20, load-dependent stiffness 16/20 in
the 2026-12-02 study) stay plain tests: the study, not this module, measures the rate.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor

import pytest

from vdps_hil.experiments.workbench_study import HIDDEN, SHIPPED, STUDY_SEEDS, TUNING_SEEDS, TWO_HIDDEN, run_job

SEEDS = (21, 22)
"""Test seeds: neither the ranking's tuning seeds nor the study's (``test_seeds_are_disjoint``)."""
NULL_MANEUVERS = ("accel-coast", "coast-down", "step-steer", "lane-change", "sine-sweep")
KNOWN_WEAK: dict[str, str] = {
    "steering_compliance": (
        "measured with the hit rule tightened (2026-12-02): on seeds 21 and 22 the workbench recommends "
        "nothing ('no candidate explains enough of the held-out residual with plausible values'); the "
        "hidden compliance is only in the top equivalence group {front cornering stiffness, tire "
        "saturation, steering compliance}, with a K&C measurement or a circle to the limit named as what "
        "would separate them. The old rule counted the group without a recommendation as a hit"),
}
"""Effect -> reason (measured, see the module docstring)."""


def _jobs(cache: str) -> list[dict]:
    jobs = []
    for eff, (man, spec) in HIDDEN.items():
        for s in SEEDS:
            jobs.append({"key": ("hidden", eff, s), "maneuver": man, "specs": [spec], "seed": s, "effect": eff,
                         "cache": cache})
    for man in NULL_MANEUVERS:
        jobs.append({"key": ("null", man, SEEDS[0]), "maneuver": man, "specs": [], "seed": SEEDS[0], "cache": cache})
    for pair, man in TWO_HIDDEN.items():
        jobs.append({"key": ("two", pair, SEEDS[0]), "maneuver": man, "specs": [HIDDEN[e][1] for e in pair],
                     "seed": SEEDS[0], "cache": cache})
    return jobs


@pytest.fixture(scope="module")
def runs(drive_cache):
    cache = str(drive_cache)
    jobs = _jobs(cache)
    with ProcessPoolExecutor(max_workers=min(2, os.cpu_count() or 1)) as ex:
        out = list(ex.map(run_job, jobs))
    return {r["key"]: r for r in out}


def _mark(eff):
    return pytest.param(eff, marks=pytest.mark.xfail(strict=True, reason=KNOWN_WEAK[eff])) if eff in KNOWN_WEAK else eff


@pytest.mark.parametrize("effect", [_mark(e) for e in HIDDEN])
def test_hidden_effect_is_found_on_both_seeds(runs, effect):
    for s in SEEDS:
        r = runs[("hidden", effect, s)]
        assert "error" not in r, r.get("error")
        assert r["hit"], (effect, s, r["recommendation"], r["groups"], r["messages"])


def test_nothing_hidden_recommends_nothing(runs):
    false = {m: runs[("null", m, SEEDS[0])]["recommendation"] for m in NULL_MANEUVERS}
    assert all(v is None for v in false.values()), false


@pytest.mark.parametrize("pair", list(TWO_HIDDEN))
def test_two_hidden_effects_are_found_one_after_the_other(runs, pair):
    r = runs[("two", pair, SEEDS[0])]
    assert set(pair) <= set(r["selected"]), (pair, r["selected"], r["messages"])
    assert r["recommendation"] in pair


def test_fitted_magnitudes_are_the_hidden_ones(runs):
    """Tolerances: 10 % of the hidden magnitude; the lever arm 30 % (measured bias +0.10 to +0.13 m on
    these seeds: the lateral force balance also carries the reduced model's own roll-coupling
    mismatch, which the lever arm's z and x components partly take up)."""
    checks = [("aero_drag", "cda_m2", 0.7, 0.07), ("rolling_resistance", "coefficient", 0.012, 0.0015),
              ("low_pressure_tire", "radius_reduction", 0.015, 0.0015), ("imu_lever_arm", "lever_x_m", 0.5, 0.15)]
    for eff, p, truth, tol in checks:
        for s in SEEDS:
            r = runs[("hidden", eff, s)]
            if r["recommendation"] != eff:
                continue  # judged by the hit test
            v = r["entries"][eff]["parameters"][p]
            assert abs(v - truth) <= tol, (eff, s, v)
    r = runs[("hidden", "low_pressure_tire", SEEDS[0])]
    assert r["entries"]["low_pressure_tire"]["parameters"]["wheel"] == 4.0


def test_known_group_compliance_and_front_cornering_stiffness(runs):
    """Steering compliance and the front cornering stiffness cannot be told apart on a step steer
    in the linear range: they come out as one group."""
    for s in SEEDS:
        groups = runs[("hidden", "steering_compliance", s)]["groups"]
        assert any({"steering_compliance", "cornering_stiffness_front"} <= set(g) for g in groups), groups


def test_known_group_rolling_resistance_and_accelerometer_bias_or_grade(runs):
    """Rolling resistance and an accelerometer x bias act alike on the longitudinal force balance
    of a coast-down; the issue asks for them as a group (or with the grade). The GNSS/IMU
    innovations can separate the bias (it makes the integrated IMU drift from the GNSS velocity),
    so the group holds only while the drive is too short for that drift to show."""
    for s in SEEDS:
        r = runs[("hidden", "rolling_resistance", s)]
        groups = r["groups"] + [[r["recommendation"], *r["equivalent_to"]]]
        assert any("rolling_resistance" in g and ("imu_bias" in g or "road_grade" in g) for g in groups), groups


def test_known_group_load_dependent_stiffness_and_tire_saturation(runs):
    """On the sine sweep (about 5 m/s^2) each of the two explains the residual on its own and one
    reproduces the other's fit: they come out as a group (the separating maneuver, a circle
    ramped to the limit, is named); which one leads depends on the seed."""
    for s in SEEDS:
        r = runs[("hidden", "load_dependent_cornering_stiffness", s)]
        groups = r["groups"] + [[r["recommendation"], *r["equivalent_to"]]]
        assert any({"load_dependent_cornering_stiffness", "magic_formula_tire"} <= set(g) for g in groups), groups


def test_saturation_is_told_apart_from_load_dependent_stiffness_on_the_circle_ramp(runs):
    """On the circle ramped to 7 m/s^2 the load-dependent stiffness reproduces the saturation only
    with implausible values (a negative load slope) and a significantly worse fit: saturation is
    recommended, not grouped with it."""
    for s in SEEDS:
        r = runs[("hidden", "magic_formula_tire", s)]
        assert r["recommendation"] == "magic_formula_tire", (s, r["recommendation"], r["messages"])
        assert "load_dependent_cornering_stiffness" not in r["equivalent_to"], (s, r["equivalent_to"])


LANE_CHANGE = SHIPPED + "lane-change-iso3888"
LANE_CHANGE_EFFECTS = ("imu_bias", "crosswind", "low_pressure_tire")
TRUTH_TIRE = {"magic_formula_tire", "load_dependent_cornering_stiffness"}
"""The shipped lane change's own truth tire (Magic Formula) against the model's linear one, and the
effect the workbench groups with it: the only recommendation a nothing-hidden drive may make."""


def test_seeds_are_disjoint():
    from vdps_hil.experiments.seeds import check_held_out

    check_held_out(SEEDS, __name__)  # no tuning seed of any threshold (experiments.seeds)
    assert not set(STUDY_SEEDS) & set(TUNING_SEEDS)
    assert not set(SEEDS) & set(STUDY_SEEDS)


@pytest.fixture(scope="module")
def lane_change_runs(drive_cache):
    """Issue 18 on the shipped ISO 3888 lane change (Magic Formula truth tire): each effect hidden
    on the test seeds, and the nothing-hidden drives of the same seeds."""
    cache = str(drive_cache)
    jobs = [{"key": (eff, s), "maneuver": LANE_CHANGE, "specs": [HIDDEN[eff][1]], "seed": s, "effect": eff,
             "cache": cache} for eff in LANE_CHANGE_EFFECTS for s in SEEDS]
    jobs += [{"key": (None, s), "maneuver": LANE_CHANGE, "specs": [], "seed": s, "cache": cache} for s in SEEDS]
    with ProcessPoolExecutor(max_workers=min(2, os.cpu_count() or 1)) as ex:
        out = list(ex.map(run_job, jobs))
    return {r["key"]: r for r in out}


@pytest.mark.parametrize("effect", LANE_CHANGE_EFFECTS)
def test_lane_change_hidden_effect_is_recommended_beside_the_truth_tire(lane_change_runs, effect):
    """The truth misses two effects against the model here (its Magic Formula tire and the hidden
    one): the hidden one must be found (selected) and recommended first -- its unique contribution
    in the final model is the larger (``ranking.ordering``), whichever the greedy first round took."""
    for s in SEEDS:
        r = lane_change_runs[(effect, s)]
        assert "error" not in r, r.get("error")
        assert effect in r["selected"], (effect, s, r["selected"], r["messages"])
        assert r["hit"], (effect, s, r["recommendation"], r["selected"], r["messages"])


def test_lane_change_with_nothing_hidden_recommends_only_the_truth_tire(lane_change_runs):
    """No sensor, wind or tire-radius effect is selected on the nothing-hidden lane change; what is
    recommended, if anything, is the truth's own tire law (or its group)."""
    for s in SEEDS:
        r = lane_change_runs[(None, s)]
        assert set(r["selected"]) <= TRUTH_TIRE, (s, r["selected"], r["messages"])
