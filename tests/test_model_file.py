"""Model files: TOML and JSON round trips, data only, one-line errors."""

from __future__ import annotations

import json
import math

import pytest

from vdps_hil.model.effects import EffectSet, make_effect
from vdps_hil.model.params import PARAM_NAMES, load_vehicle
from vdps_hil.workbench.model_file import ModelFileError, load_model, read_model, save_model

VEH = load_vehicle("sedan-model")


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_round_trip(tmp_path, suffix):
    veh = VEH.with_params(mass_kg=1601.25, cornering_stiffness_front_nprad=121234.5)
    eff = EffectSet([make_effect("aero_drag", cda_m2=0.6875), make_effect("low_pressure_tire", wheel=2.0,
                                                                           radius_reduction=0.0149)])
    p = save_model(tmp_path / f"m{suffix}", veh, eff, sigmas={"mass_kg": 2.5},
                   effect_sigmas={"aero_drag": {"cda_m2": 0.004}}, source="test")
    v2, e2, mf = load_model(p, VEH)
    for n in PARAM_NAMES:
        assert getattr(v2.params, n) == getattr(veh.params, n)
    assert e2 == eff
    assert mf.sigmas == {"mass_kg": 2.5}
    assert mf.effect_sigmas["aero_drag"] == {"cda_m2": 0.004}
    assert mf.vehicle == "sedan-model" and mf.vehicle_sha256 == VEH.source_sha256


def test_linear_tire_is_not_written(tmp_path):
    p = save_model(tmp_path / "m.toml", VEH, EffectSet([make_effect("linear_tire")]))
    assert read_model(p).effects == []


@pytest.mark.parametrize("text, msg", [
    ("schema = 'other'\nschema_version = 1\n[params]\nmass_kg = 1.0\n", "not a model file"),
    ("schema = 'vdps-model'\nschema_version = 2\n[params]\nmass_kg = 1.0\n", "schema_version"),
    ("schema = 'vdps-model'\nschema_version = 1\n", "missing table"),
    ("schema = 'vdps-model'\nschema_version = 1\n[params]\nmass = 1.0\n", "unknown parameter"),
    ("schema = 'vdps-model'\nschema_version = 1\n[params]\nmass_kg = -1.0\n", "outside its physical range"),
    ("schema = 'vdps-model'\nschema_version = 1\n[params]\nmass_kg = 1e308\n", r"mass_kg = 1e\+308 is outside"),
    ("schema = 'vdps-model'\nschema_version = 1\n[params]\nmass_kg = 'x'\n", "finite number"),
    ("schema = 'vdps-model'\nschema_version = 1\nextra = 1\n[params]\n", "unknown key"),
    ("this is [not toml", "malformed TOML"),
    ("schema = 'vdps-model'\nschema_version = 1\n[params]\n[[effects]]\nname = 'warp_drive'\n", "unknown effect"),
    ("schema = 'vdps-model'\nschema_version = 1\n[params]\n[[effects]]\nname = 'aero_drag'\n"
     "params = { cda_m2 = 0.7, code = 1.0 }\n", "unknown parameter"),
])
def test_bad_files_are_one_line_errors(tmp_path, text, msg):
    p = tmp_path / "m.toml"
    p.write_text(text)
    with pytest.raises(ModelFileError, match=msg) as ei:
        load_model(p, VEH)
    assert "\n" not in str(ei.value)


def test_json_cannot_carry_code_and_truth_is_refused(tmp_path):
    p = tmp_path / "m.json"
    p.write_text(json.dumps({"schema": "vdps-model", "schema_version": 1, "params": {"mass_kg": 1500.0},
                             "effects": [{"name": "__import__('os')", "params": {}}]}))
    with pytest.raises(ModelFileError, match="unknown effect"):
        load_model(p, VEH)
    with pytest.raises(ModelFileError, match="model vehicle"):
        load_model(p, load_vehicle("sedan-truth"))
    with pytest.raises(ModelFileError, match=".toml or .json"):
        save_model(tmp_path / "m.yaml", VEH, EffectSet())


def test_missing_parameters_keep_the_vehicle_values(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text("schema = 'vdps-model'\nschema_version = 1\n[params]\nmass_kg = 1700.0\n")
    v, e, _ = load_model(p, VEH)
    assert v.params.mass_kg == 1700.0 and v.params.inertia_z_kgm2 == VEH.params.inertia_z_kgm2
    assert len(e) == 0 and math.isfinite(v.params.cornering_stiffness_rear_nprad)
