"""Identified parameters saved and loaded between drives: round trip, sanity bounds, bad files."""

import dataclasses
import json
import math

import pytest
from hypothesis import given, settings, strategies as st

from vdps_hil.identification.persistence import (SCHEMA, SCHEMA_VERSION, ParamsFileError, load_params,
                                                 parse_params, reset_params, save_params, unidentified_params,
                                                 unsettled_problems)
from vdps_hil.identification.identifier import Identifier
from vdps_hil.model.params import PARAM_NAMES, load_vehicle

MODEL = load_vehicle("sedan-model", "model")
IDENTIFIED = dataclasses.replace(MODEL.params, mass_kg=1601.234567890123, inertia_x_kgm2=551.5,
                                 cornering_stiffness_rear_nprad=170123.25)


def _doc(**changes):
    doc = {"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "vehicle": MODEL.name,
           "vehicle_sha256": MODEL.source_sha256, "params": IDENTIFIED.as_dict(), "sigmas": {}, "meta": {}}
    doc.update(changes)
    return doc


def test_round_trip_is_exact(tmp_path):
    path = tmp_path / "params.json"
    sigmas = {n: 0.01 * getattr(IDENTIFIED, n) for n in PARAM_NAMES}
    save_params(path, IDENTIFIED, MODEL, sigmas=sigmas, meta={"drive": "test", "updates": 1234})
    got = load_params(path, MODEL)
    assert got.params == IDENTIFIED  # floats survive JSON bit for bit
    assert got.sigmas == sigmas and got.meta == {"drive": "test", "updates": 1234}
    assert got.vehicle == MODEL.name and got.vehicle_sha256 == MODEL.source_sha256
    assert [p.name for p in tmp_path.iterdir()] == ["params.json"]  # no temporary file left


def test_identifier_starts_from_a_loaded_file(tmp_path):
    path = tmp_path / "p.json"
    save_params(path, IDENTIFIED, MODEL)
    ident = Identifier(MODEL, start=load_params(path, MODEL).params)
    assert ident.params == IDENTIFIED
    assert ident.prior == MODEL.params  # bounds and W still come from the model file


def test_reset_removes_the_file(tmp_path):
    path = tmp_path / "p.json"
    save_params(path, IDENTIFIED, MODEL)
    assert reset_params(path) is True
    assert not path.exists()
    assert reset_params(path) is False


@pytest.mark.parametrize("text,msg", [
    ("{not json", "not valid JSON"),
    ("[1, 2]", "expected a JSON object"),
    (json.dumps(_doc(schema="something-else")), "not a vdps-hil parameter file"),
    (json.dumps(_doc(schema_version=2)), "unsupported schema_version"),
    (json.dumps(_doc(schema_version=True)), "unsupported schema_version"),
    (json.dumps(_doc(vehicle="truck-model")), "saved for vehicle"),
    (json.dumps(_doc(params={k: v for k, v in IDENTIFIED.as_dict().items() if k != "mass_kg"})), "missing parameter"),
    (json.dumps(_doc(params={**IDENTIFIED.as_dict(), "bogus": 1.0})), "unknown parameter"),
    (json.dumps(_doc(params={**IDENTIFIED.as_dict(), "mass_kg": "heavy"})), "finite number"),
    (json.dumps(_doc(params={**IDENTIFIED.as_dict(), "mass_kg": True})), "finite number"),
    (json.dumps(_doc(params={**IDENTIFIED.as_dict(), "mass_kg": float("nan")})), "finite number"),
    (json.dumps(_doc(params={**IDENTIFIED.as_dict(), "mass_kg": 10 ** 400})), "finite number"),
    (json.dumps(_doc(sigmas={"mass_kg": 10 ** 400})), "non-negative"),
    (json.dumps(_doc(params={**IDENTIFIED.as_dict(), "mass_kg": 1e6})), "outside the sanity bounds"),
    (json.dumps(_doc(params={**IDENTIFIED.as_dict(), "inertia_z_kgm2": 100.0})), "outside the sanity bounds"),
    (json.dumps(_doc(sigmas={"mass_kg": -1.0})), "non-negative"),
    (json.dumps(_doc(sigmas=[1])), "'sigmas' must be an object"),
    (json.dumps(_doc(meta=3)), "'meta' must be an object"),
    ("[" * 100000, "not valid JSON"),
])
def test_bad_files_give_one_line_errors(tmp_path, text, msg):
    path = tmp_path / "p.json"
    path.write_text(text)
    with pytest.raises(ParamsFileError, match=msg) as e:
        load_params(path, MODEL)
    assert "\n" not in str(e.value)


def test_unreadable_oversized_and_binary_files(tmp_path):
    with pytest.raises(ParamsFileError, match="cannot read"):
        load_params(tmp_path / "missing.json", MODEL)
    big = tmp_path / "big.json"
    big.write_bytes(b" " * 1_000_001)
    with pytest.raises(ParamsFileError, match="too large"):
        load_params(big, MODEL)
    binary = tmp_path / "bin.json"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ParamsFileError, match="UTF-8"):
        load_params(binary, MODEL)


def test_sanity_bounds_are_relative_to_the_prior(tmp_path):
    path = tmp_path / "p.json"
    ok = dataclasses.replace(MODEL.params, mass_kg=2.9 * MODEL.params.mass_kg)
    save_params(path, ok, MODEL)
    assert load_params(path, MODEL).params == ok
    with pytest.raises(ParamsFileError, match="outside"):
        load_params(path, MODEL, bounds_factor=(0.5, 2.0))
    with pytest.raises(ParamsFileError, match="refusing to save"):
        save_params(path, dataclasses.replace(ok, mass_kg=0.2 * MODEL.params.mass_kg), MODEL)
    assert load_params(path, MODEL).params == ok  # the refused save left the old file intact


def test_save_refuses_truth_files_and_non_json_meta(tmp_path):
    with pytest.raises(ParamsFileError, match="model vehicle"):
        save_params(tmp_path / "p.json", IDENTIFIED, dataclasses.replace(MODEL, kind="truth"))
    with pytest.raises(ParamsFileError, match="plain JSON"):
        save_params(tmp_path / "p.json", IDENTIFIED, MODEL, meta={"x": object()})
    with pytest.raises(ParamsFileError, match="cannot write"):
        save_params(tmp_path / "no-such-dir" / "p.json", IDENTIFIED, MODEL)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.integers(min_value=10 ** 308) | st.floats(allow_nan=True)
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=20)


@settings(max_examples=200, deadline=None)
@given(st.one_of(
    st.text(max_size=200),
    json_values.map(json.dumps),
    st.dictionaries(st.sampled_from(["schema", "schema_version", "vehicle", "params", "sigmas", "meta"]),
                    json_values).map(lambda d: json.dumps({**_doc(), **d})),
    st.dictionaries(st.sampled_from(list(PARAM_NAMES)), json_values).map(
        lambda p: json.dumps(_doc(params={**IDENTIFIED.as_dict(), **p}))),
))
def test_any_text_loads_or_fails_with_one_line(text):
    try:
        got = parse_params(text, MODEL, "fuzz.json")
    except ParamsFileError as e:
        assert "\n" not in str(e)
    else:
        for n in PARAM_NAMES:
            v, p = getattr(got.params, n), getattr(MODEL.params, n)
            assert math.isfinite(v) and 0.3 * p <= v <= 3.0 * p


def test_a_file_says_which_problems_were_not_identified_when_saved(tmp_path):
    path = tmp_path / "p.json"
    status = {"mass": "converged", "tracking": "at bound", "cornering": "model mismatch", "inertia": "converged"}
    save_params(path, IDENTIFIED, MODEL, meta={"status": status})
    assert unsettled_problems(load_params(path, MODEL)) == {"tracking": "at bound", "cornering": "model mismatch"}
    save_params(path, IDENTIFIED, MODEL)  # a file that does not say: nothing is taken as identified
    assert unsettled_problems(load_params(path, MODEL)) == {n: "unknown" for n in status}



def test_a_file_says_which_parameters_were_not_identified_when_saved(tmp_path):
    path = tmp_path / "p.json"
    ps = {n: "identified" for n in PARAM_NAMES}
    save_params(path, IDENTIFIED, MODEL, meta={"param_status": {**ps, "inertia_x_kgm2": "at bound",
                                                                "cornering_stiffness_rear_nprad": "model mismatch"}})
    assert unidentified_params(load_params(path, MODEL)) == {"inertia_x_kgm2": "at bound",
                                                             "cornering_stiffness_rear_nprad": "model mismatch"}
    # a parameter it does not name is not taken as identified; a file that does not say, or says
    # nonsense there, gives None (the problems' statuses then speak for it)
    del ps["mass_kg"]
    save_params(path, IDENTIFIED, MODEL, meta={"param_status": ps})
    assert unidentified_params(load_params(path, MODEL)) == {"mass_kg": "unknown"}
    for meta in ({}, {"param_status": [1, 2]}, {"param_status": "identified"}):
        save_params(path, IDENTIFIED, MODEL, meta=meta)
        assert unidentified_params(load_params(path, MODEL)) is None
