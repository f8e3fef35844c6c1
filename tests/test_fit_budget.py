"""The row budget (``workbench.fit_budget``): a drive longer than ``max_fit_s`` is fitted on
evenly spread segments joined end to end, the diagnosis says so (text and JSON), and the fits'
rows are the segments' only. A short drive with a small budget stands in for a long one."""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.experiments.workbench_study import HIDDEN, cached_drive
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench.dataset import load_drive
from vdps_hil.workbench.diagnosis import diagnose
from vdps_hil.workbench.fit_budget import add_window, fit_subset
from vdps_hil.workbench.ranking.config import RankingConfig


@pytest.fixture(scope="module")
def drive(drive_cache):
    man, spec = HIDDEN["aero_drag"]
    return cached_drive(drive_cache, man, [spec], seed=21)


@pytest.fixture(scope="module")
def table(drive):
    return load_drive(drive, load_vehicle("sedan-model", "model"))


def test_a_drive_within_the_budget_is_used_whole(table):
    assert fit_subset(table, table.duration_s + 1.0, 5.0) is None


def test_segments_are_evenly_spread_joined_and_map_back(table):
    sub = fit_subset(table, 12.0, 4.0)
    assert sub is not None and len(sub.segments_s) == 3
    starts = np.array([a for a, _ in sub.segments_s])
    assert starts[0] == pytest.approx(table.t_s[0])
    assert np.ptp(np.diff(starts)) < 2 * table.period_s  # evenly spread
    assert sub.segments_s[-1][1] == pytest.approx(table.t_s[-1] + table.period_s, abs=4 * table.period_s)
    j = sub.table
    assert np.all(np.diff(j.t_s) > 0) and j.duration_s < 12.0 + 3 * table.period_s
    sep = sub.rows < 0
    assert sep.sum() == 2 and len(sub.rows) == len(j.t_s)
    for name in ("vel_b_mps_x", "rate_b_radps_z", "steer_wheel_angle_rad"):
        assert np.all(np.isnan(j.columns[name][sep]))
        np.testing.assert_array_equal(j.columns[name][~sep], table.columns[name][sub.rows[~sep]])
    np.testing.assert_allclose(sub.drive_times(np.flatnonzero(~sep)), table.t_s[sub.rows[~sep]])
    # GNSS records follow their segment with its shift: each lies within its segment's joined span
    for kind, tab in j.gnss.items():
        assert len(tab["t_s"]) and tab["t_s"].min() >= j.t_s[0] - 1e-9 and tab["t_s"].max() <= j.t_s[-1] + 1e-9


def test_diagnosis_fits_the_segments_and_says_so(drive):
    cfg = RankingConfig(max_fit_s=14.0, fit_segment_s=7.0)
    d = diagnose(drive, load_vehicle("sedan-model", "model"), ranking_config=cfg, with_simulation=False)
    js = d.to_json()["workbench"]
    fs = js["fit_subset"]
    assert fs["n_segments"] == 2 and fs["fitted_s"] <= 14.0 + 1e-6
    assert fs["drive_s"] == pytest.approx(d.table.duration_s)
    assert any(m.startswith("row budget:") for m in js["messages"])
    t_c, _, vals = d.cleaned
    assert len(t_c) <= fs["rows"] < len(d.table.t_s)  # the fitted rows are the segments' only
    inside = np.zeros(len(t_c), bool)
    for a, b in fs["segments_s"]:
        inside |= (t_c >= a - 1e-9) & (t_c <= b + 1e-9)
    assert inside.all()
    assert len(d.residuals.t_s) > fs["rows"]  # the residual traces stay on the whole drive


def test_add_window_is_the_contiguous_middle_of_a_long_drive(table):
    assert add_window(table, table.duration_s + 1.0) is None
    w = add_window(table, 8.0)
    cut = w.cut(table)
    assert cut.duration_s == pytest.approx(8.0, abs=2 * table.period_s)
    assert np.all(np.diff(cut.t_s) < 1.5 * table.period_s)  # contiguous: no junction to predict across
    mid = 0.5 * (table.t_s[0] + table.t_s[-1])
    assert 0.5 * (cut.t_s[0] + cut.t_s[-1]) == pytest.approx(mid, abs=2 * table.period_s)
    np.testing.assert_array_equal(cut.columns["vel_b_mps_x"], table.columns["vel_b_mps_x"][(table.t_s >= cut.t_s[0])
                                                                                          & (table.t_s <= cut.t_s[-1])])


def test_diagnosis_with_add_on_a_long_drive_uses_the_window_and_says_so(drive):
    """--add beyond the budget: the ranking on the segments, the before/after on the middle window
    (both stated); the added drag is fitted there and lowers the longitudinal residual."""
    cfg = RankingConfig(max_fit_s=10.0, fit_segment_s=5.0)
    d = diagnose(drive, load_vehicle("sedan-model", "model"), ranking_config=cfg, with_simulation=False,
                 add=("aero_drag",))
    msgs = d.to_json()["workbench"]["messages"]
    assert any("--add is fitted" in m and "middle 10 s" in m for m in msgs)
    assert d.to_json()["workbench"]["fit_subset"]["n_segments"] == 2
    rb, ra = d.add.before["residual_rms"], d.add.after["residual_rms"]
    assert ra["long"] < rb["long"]
