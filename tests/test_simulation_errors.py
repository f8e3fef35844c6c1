"""The input-driven simulation error over fixed horizons."""

from __future__ import annotations

import math

import pytest

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import simulation_errors as S
from vdps_hil.workbench.dataset import load_drive
from vdps_hil.experiments.workbench_study import cached_drive

VEH = load_vehicle("sedan-model")
TRUE = VEH.with_params(**load_vehicle("sedan-truth").params.as_dict())  # tests only: a correct model


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """The step steer of test_residuals (seed 5) and its table, as (table, None, None)."""
    path = cached_drive(tmp_path_factory.getbasetemp() / "wb_drives", "step-steer", (), seed=5)
    return load_drive(path, VEH), None, None


def test_simulation_errors_grow_with_the_horizon(drive):
    tab, _, _ = drive
    se = S.simulation_errors(tab, TRUE, EffectSet(), every_s=2.0)
    s = se.summary()
    assert set(s) == {"0.5", "1", "2"}
    assert s["0.5"]["position_m"] < s["2"]["position_m"]
    assert s["2"]["position_m"] < 2.0  # the true parameters predict 2 s of a step steer within 2 m
    assert all(math.isfinite(v) for v in s["2"].values())
