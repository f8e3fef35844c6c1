"""Tests of hil.bench_config: the model file paired with a truth file, the bench's system."""

from __future__ import annotations

import pytest

from vdps_hil.hil.bench_config import BenchError, make_system, model_for
from vdps_hil.sim.profiles import load_profile


def test_the_model_file_is_the_truth_files_pair():
    assert model_for("configs/vehicles/suv-truth.toml") == "suv-model" and model_for("sedan-truth") == "sedan-model"
    with pytest.raises(BenchError, match="give --model"):
        model_for("my-car")


def test_bench_model_may_be_a_saved_workbench_model(tmp_path):
    """``vdps bench --model`` also takes a ``vdps diagnose --save-model`` file (as ``vdps replay
    --model``): the vehicle file it names, its parameters as the identifier's start, its
    dynamics effects in the predictor (linear tire kept); a vehicle name still works."""
    from vdps_hil.model.effects import REGISTRY, EffectSet
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.workbench.model_file import save_model

    p = load_profile("table1-susp1k")
    veh = load_vehicle("suv-model", "model")
    m = save_model(tmp_path / "suv-drag.toml", veh.with_params(mass_kg=veh.params.mass_kg + 300.0),
                   EffectSet([REGISTRY["aero_drag"](cda_m2=1.1)]))
    system = make_system(str(m), p.suspension.rate_hz, p.suspension.sigma_m)
    assert system.vehicle.name == "suv-model"
    assert system.config.start_params.mass_kg == pytest.approx(veh.params.mass_kg + 300.0)
    names = sorted(e.name for e in system.predictor.effects)
    assert names == ["aero_drag", "linear_tire"]
    assert system.predictor.effects["aero_drag"].cda_m2 == pytest.approx(1.1)
    plain = make_system("suv-model", p.suspension.rate_hz, p.suspension.sigma_m)
    assert plain.config.start_params is None and "aero_drag" not in plain.predictor.effects
