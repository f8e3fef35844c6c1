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
def drive(drive_cache):
    """The step steer of test_residuals (seed 5) and its table, as (table, None, None)."""
    path = cached_drive(drive_cache, "step-steer", (), seed=5)
    return load_drive(path, VEH), None, None


def test_simulation_errors_grow_with_the_horizon(drive):
    tab, _, _ = drive
    se = S.simulation_errors(tab, TRUE, EffectSet(), every_s=2.0)
    s = se.summary()
    assert set(s) == {"0.5", "1", "2"}
    assert s["0.5"]["position_m"] < s["2"]["position_m"]
    assert s["2"]["position_m"] < 2.0  # the true parameters predict 2 s of a step steer within 2 m
    assert all(math.isfinite(v) for v in s["2"].values())


def test_a_diverging_prediction_is_reported_not_averaged(drive):
    """A model whose yaw dynamics are absurd (yaw inertia 1 kg m^2 with the tires' full
    cornering stiffness: the explicit integrator at 10 ms is unstable) loses the car: every such
    prediction is counted as diverged with its time, left out of the RMS, and said in words."""
    tab, _, _ = drive
    bad = TRUE.with_params(inertia_z_kgm2=1.0, inertia_x_kgm2=1.0)
    se = S.simulation_errors(tab, bad, EffectSet(), every_s=2.0)
    s = se.summary()
    assert s["2"]["n_diverged"] >= 1
    assert s["2"]["n"] + s["2"]["n_diverged"] >= 1
    assert all(math.isfinite(v) or v != v for v in s["2"].values())
    notes = se.notes()
    assert notes and "diverged in" in notes[0] and "first at t = " in notes[0]
    ok = S.simulation_errors(tab, TRUE, EffectSet(), every_s=2.0)
    assert ok.summary()["2"]["n_diverged"] == 0 and ok.notes() == []


def test_without_wheel_torques_the_missing_inputs_are_named(drive):
    tab, _, _ = drive
    cols = dict(tab.columns)
    for i in range(1, 5):
        cols[f"wheel_torque_nm_{i}"] = cols[f"wheel_torque_nm_{i}"] * float("nan")
    import dataclasses

    se = S.simulation_errors(dataclasses.replace(tab, columns=cols), TRUE, EffectSet(), every_s=2.0)
    assert se.missing_inputs == tuple(f"wheel_torque_nm_{i}" for i in range(1, 5))
    assert "wheel_torque_nm_1" in se.notes()[0] and "not computed" in se.notes()[0]
