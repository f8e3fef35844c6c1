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
