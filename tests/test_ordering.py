"""Order of the selected effects (``workbench.ranking.ordering``): by unique contribution, ties
and effects without a figure in selection order. The figures themselves are checked on drives
in tests/test_ranking.py (the shipped lane change with two missing effects)."""

from __future__ import annotations

from vdps_hil.workbench.ranking.ordering import order_selected, unique_contributions


def test_the_larger_unique_contribution_leads():
    # the crosswind drive of the module docstring: saturation first in round 1, the wind's U larger
    assert order_selected(["magic_formula_tire", "crosswind"], {"magic_formula_tire": 0.57, "crosswind": 0.88}) == \
        ["crosswind", "magic_formula_tire"]
    assert order_selected(["a", "b", "c"], {"a": 0.1, "b": 0.3, "c": 0.2}) == ["b", "c", "a"]


def test_ties_and_missing_figures_keep_the_selection_order():
    assert order_selected(["a", "b"], {"a": 0.2, "b": 0.2}) == ["a", "b"]
    assert order_selected(["a", "b", "c"], {"b": 0.5, "c": 0.1}) == ["b", "c", "a"]
    assert order_selected(["b", "a"], {}) == ["b", "a"]


def test_one_selected_effect_needs_no_figure():
    # with fewer than two selected effects nothing is refitted (the arguments are never touched)
    assert unique_contributions(None, None, None, None, None, None, {"crosswind": object()}, None) == {}
    assert unique_contributions(None, None, None, None, None, None, {}, None) == {}


def test_sensor_effects_lead_then_each_part_by_unique_contribution():
    # a lever arm's U is a share of the innovations, an anti-roll stiffness's a share of the
    # force balance: not comparable, and the sensor is corrected before the model is judged
    order = order_selected(["roll_stiffness", "imu_lever_arm"], {"roll_stiffness": 0.16, "imu_lever_arm": -0.14},
                           sensors={"imu_lever_arm"})
    assert order == ["imu_lever_arm", "roll_stiffness"]
    assert order_selected(["a", "s1", "b", "s2"], {"a": 0.1, "b": 0.5, "s1": 0.2, "s2": 0.3}, sensors=("s1", "s2")) == \
        ["s2", "s1", "b", "a"]
