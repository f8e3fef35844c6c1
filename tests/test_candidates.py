"""Candidates: the right adapter per effect and the candidates a ranking considers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vdps_hil.model.effects import REGISTRY, DynamicsEffect, EffectSet, ParamSpec
from vdps_hil.workbench import candidate_base as CB
from vdps_hil.workbench import candidates as C


def test_adapters_per_built_in_effect():
    kinds = {n: type(C.candidate_for(cls)).__name__ for n, cls in REGISTRY.items() if n != "linear_tire"}
    assert kinds == {"magic_formula_tire": "MagicFormulaCandidate", "aero_drag": "RegressorCandidate",
                     "rolling_resistance": "RegressorCandidate",
                     "load_dependent_cornering_stiffness": "NumericCandidate",
                     "low_pressure_tire": "LowPressureCandidate", "crosswind": "CrosswindCandidate",
                     "steering_compliance": "NumericCandidate", "roll_stiffness": "RegressorCandidate",
                     "imu_bias": "MeasurementCandidate",
                     "imu_lever_arm": "MeasurementCandidate", "steering_offset": "SteeringOffsetCandidate"}
    # a sensor effect whose evidence is the balance rows: fitted and judged as a dynamics effect
    so = C.candidate_for(REGISTRY["steering_offset"])
    assert so.family == "dynamics" and REGISTRY["steering_offset"].family == "measurement"


def test_default_candidates_skip_the_models_effects_and_the_linear_tire():
    names = [c.name for c in C.default_candidates(EffectSet([REGISTRY["aero_drag"]()]))]
    assert "aero_drag" not in names and "linear_tire" not in names and len(names) == 10


def test_the_steering_offset_is_ranked_only_over_half_a_turn():
    """``TURN_NEEDED_RAD``: on a drive whose heading spans less than pi the steering offset is not
    offered (a crosswind's side force is not told apart from it there); over half a turn it is."""
    names = lambda span: {c.name for c in C.default_candidates(EffectSet(), heading_span=span)}  # noqa: E731
    assert "steering_offset" not in names(math.radians(179.0)) and "steering_offset" in names(math.pi)
    assert names(0.0) - {"steering_offset"} == names(math.pi) - {"steering_offset"}


@pytest.mark.parametrize("headings_deg, span_deg", [
    ([10.0, 20.0, 15.0], 10.0),
    ([350.0, 10.0, 5.0], 20.0),  # across north
    ([0.0, 90.0, 180.0, 270.0], 270.0),  # the largest gap (90 deg) left out
    (list(range(0, 360, 5)), 355.0),  # a full circle at 5 deg steps
    ([-170.0, 170.0], 20.0),  # -170 is 190
    ([42.0], 0.0),
])
def test_heading_span_is_the_smallest_arc_holding_every_heading(headings_deg, span_deg):
    assert math.degrees(C.heading_span_rad(np.radians(headings_deg + [math.nan]))) == pytest.approx(span_deg, abs=1e-9)


def test_user_effect_without_regressors_is_numeric():
    class Push(DynamicsEffect):
        name = "push"
        HOOKS = ("body_wrench",)
        PARAMS = (ParamSpec("force_n", "N", 100.0, "x force", 0.0, 1000.0),)

        def body_wrench(self, vel_b, omega_b, air_b):
            return (self.force_n, 0.0, 0.0, 0.0, 0.0, 0.0)

    c = C.candidate_for(Push)
    assert isinstance(c, CB.NumericCandidate) and c.params == ("force_n",) and c.linear
    assert C.default_candidates(EffectSet(), [Push])[-1].name == "push"


def test_drive_candidates_say_what_they_leave_out_and_why():
    straight = np.radians([80.0, 85.0, 90.0])
    cands, left = C.drive_candidates(EffectSet(), (), straight)
    assert "steering_offset" not in {c.name for c in cands}
    assert left == {"steering_offset": "the heading spans 10 deg, less than the half turn that tells its side force "
                                       "apart from a crosswind's"}
    circle = np.radians(np.arange(0.0, 360.0, 10.0))
    cands, left = C.drive_candidates(EffectSet(), (), circle)
    assert "steering_offset" in {c.name for c in cands} and left == {}
    # a full circle without a straight: the offset is not told apart from what grows with the turn
    cands, left = C.drive_candidates(EffectSet(), (), circle, straight_s=1.2)
    assert "steering_offset" not in {c.name for c in cands}
    assert left["steering_offset"].startswith("1.2 s of straight driving, less than the 2 s")
    cands, left = C.drive_candidates(EffectSet(), (), circle, straight_s=2.0)
    assert "steering_offset" in {c.name for c in cands} and left == {}
    named = [C.candidate_for(REGISTRY["aero_drag"])]  # the caller's own list: as it is, nothing said
    assert C.drive_candidates(EffectSet(), (), straight, named) == (named, {})
    model = EffectSet([REGISTRY["steering_offset"]()])  # already in the model: neither offered nor said
    cands, left = C.drive_candidates(model, (), straight)
    assert left == {} and "steering_offset" not in {c.name for c in cands}


def test_straight_time_counts_rows_whose_path_radius_exceeds_500_m():
    """``straight_time_s``: rows at 50 Hz; |r| < v / 500 m is straight (at 14 m/s: 0.028 rad/s)."""
    t = np.arange(0.0, 10.0, 0.02)
    v = np.full_like(t, 14.0)
    r = np.where(t < 5.0, 0.0, 14.0 / 40.0)  # 5 s straight, then a 40 m circle
    r[10] = 0.99 * 14.0 / C.STRAIGHT_RADIUS_M  # a 505 m radius: straight
    r[11] = 1.01 * 14.0 / C.STRAIGHT_RADIUS_M  # a 495 m radius: not
    r[12], v[13] = np.nan, np.nan  # not counted
    assert C.straight_time_s(t, r, v) == pytest.approx((250 - 3) * 0.02)
    assert C.straight_time_s(t, -r, v) == pytest.approx((250 - 3) * 0.02)  # either turn direction
    assert C.straight_time_s(t[:1], r[:1], v[:1]) == 0.0


def test_table_candidates_read_the_usable_rows_heading_and_straight():
    """``table_candidates``: 5 s straight then a full 40 m circle at 14 m/s (rows at 50 Hz) ranks the
    offset; the circle's rows alone do not (no straight); a table without the yaw rate column
    counts no straight."""
    from types import SimpleNamespace

    t = np.arange(0.0, 15.0, 0.02)
    r = np.where(t < 5.0, 0.0, 14.0 / 40.0)
    yaw = np.cumsum(r) * 0.02
    tab = SimpleNamespace(t_s=t, columns={"yaw_g_rad": yaw, "rate_b_radps_z": r, "vel_b_mps_x": np.full_like(t, 14.0)})
    names = lambda idx: {c.name for c in C.table_candidates(tab, idx, EffectSet(), ())[0]}  # noqa: E731
    everything = np.arange(len(t))
    assert "steering_offset" in names(everything)
    assert "steering_offset" not in names(everything[t >= 5.0])  # the circle alone: heading, no straight
    del tab.columns["rate_b_radps_z"]
    assert "steering_offset" not in names(everything)
