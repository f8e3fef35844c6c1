"""Recording layout: schema definitions, document builders and their validation."""

import base64
import hashlib
import json
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.bus.samples import Sample
from vdps_hil.record import schemas as S

FAST = settings(max_examples=80, deadline=None)


def test_every_schema_is_versioned_json_and_titled_by_its_name():
    assert set(S.SCHEMAS) >= {S.RAW_CAN, S.RAW_SERIAL, S.SAMPLE, S.TRUTH, S.ESTIMATE,
                              S.LOCATION_FIX}
    for name, schema in S.SCHEMAS.items():
        assert schema["title"] == name
        assert json.loads(S.schema_bytes(name)) == schema
        if name.startswith("vdps."):
            assert re.fullmatch(r"vdps\.[A-Za-z]+\.v\d+", name), name


def test_location_fix_schema_has_foxglove_fields():
    props = S.SCHEMAS[S.LOCATION_FIX]["properties"]
    assert set(props) == {"timestamp", "frame_id", "latitude", "longitude", "altitude",
                          "position_covariance", "position_covariance_type"}
    assert set(props["timestamp"]["properties"]) == {"sec", "nsec"}
    assert props["position_covariance"]["minItems"] == props["position_covariance"]["maxItems"] == 9


@st.composite
def can_fields(draw):
    ext = draw(st.booleans())
    fd = draw(st.booleans())
    return dict(arbitration_id=draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF)),
                data=draw(st.binary(max_size=64 if fd else 8)), is_extended_id=ext, is_fd=fd,
                is_remote_frame=draw(st.booleans()), is_error_frame=draw(st.booleans()),
                dlc=draw(st.integers(0, 64)), direction=draw(st.sampled_from(["rx", "tx"])),
                bitrate_switch=draw(st.booleans()), error_state_indicator=draw(st.booleans()))


@FAST
@given(t_ns=st.integers(0, S.MAX_TIME_NS), f=can_fields())
def test_raw_can_doc_matches_its_schema_and_keeps_every_field(t_ns, f):
    doc = S.raw_can_doc(t_ns, **f)
    assert S.validate(doc, S.SCHEMAS[S.RAW_CAN]) == []
    assert bytes.fromhex(doc["data_hex"]) == f["data"]
    for k in ("arbitration_id", "is_extended_id", "is_fd", "is_remote_frame", "is_error_frame",
              "dlc", "direction"):
        assert doc[k] == f[k]
    assert ("bitrate_switch" in doc) == f["is_fd"]


@pytest.mark.parametrize("kwargs", [
    dict(arbitration_id=0x800),  # standard id above 11 bits
    dict(arbitration_id=0x20000000, is_extended_id=True),
    dict(arbitration_id=-1),
    dict(arbitration_id=1, dlc=65),
    dict(arbitration_id=1, data=bytes(65)),
    dict(arbitration_id=1, direction="both"),
])
def test_raw_can_doc_rejects_impossible_frames(kwargs):
    kwargs.setdefault("data", b"")
    with pytest.raises(ValueError):
        S.raw_can_doc(0, **kwargs)


@FAST
@given(t_ns=st.integers(0, S.MAX_TIME_NS), data=st.binary(max_size=600))
def test_raw_serial_doc_is_base64_of_the_bytes(t_ns, data):
    doc = S.raw_serial_doc(t_ns, data)
    assert S.validate(doc, S.SCHEMAS[S.RAW_SERIAL]) == []
    assert base64.b64decode(doc["data_b64"], validate=True) == data


@pytest.mark.parametrize("t", [-1, 2**63, 1.5, True])
def test_time_stamps_must_be_int_ns_in_range(t):
    with pytest.raises((TypeError, ValueError)):
        S.raw_serial_doc(t, b"")


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@FAST
@given(values=st.dictionaries(st.sampled_from(["x_m", "roll_rad", "v_mps", "ltr_1"]),
                              st.one_of(finite, st.just(math.nan), st.just(math.inf))),
       sigmas=st.none() | st.dictionaries(st.sampled_from(["x_m", "roll_rad"]), finite))
def test_truth_and_estimate_docs_are_strict_json_with_nulls_for_nan(values, sigmas):
    for doc, name in ((S.truth_doc(5, values), S.TRUTH),
                      (S.estimate_doc(5, values, sigmas), S.ESTIMATE)):
        text = json.dumps(doc, allow_nan=False)  # raises if a NaN slipped through
        assert S.validate(json.loads(text), S.SCHEMAS[name]) == []
        for k, v in values.items():
            assert doc["values"][k] == (v if math.isfinite(v) else None)


def test_sample_json_validates_against_sample_schema():
    s = Sample(7, "imu", "imu", {"angular_rate_radps_x": 0.1, "specific_force_mps2_z": math.nan})
    assert S.validate(s.to_json(), S.SCHEMAS[S.SAMPLE]) == []


def _fix(**fields):
    base = {"gnss_lat_deg": 48.1, "gnss_lon_deg": 11.5, "gnss_alt_m": 520.0}
    base.update(fields)
    return Sample(1_500_000_000, "gnss", "gnss_pos", base, wall_time_ns=1_700_000_000_123_456_789)


def test_location_fix_from_sample_diagonal_covariance_and_ellipsoidal_altitude():
    doc = S.location_fix_doc(_fix(gnss_pos_sigma_h_m=0.02, gnss_pos_sigma_v_m=0.05,
                                  gnss_geoid_sep_m=47.5), frame_id="antenna1")
    assert S.validate(doc, S.SCHEMAS[S.LOCATION_FIX]) == []
    assert doc["timestamp"] == {"sec": 1_700_000_000, "nsec": 123_456_789}
    assert doc["frame_id"] == "antenna1"
    assert doc["altitude"] == pytest.approx(520.0 + 47.5, abs=1e-9)
    cov = np.array(doc["position_covariance"]).reshape(3, 3)
    np.testing.assert_allclose(cov, np.diag([0.02**2, 0.02**2, 0.05**2]), rtol=1e-12)
    assert doc["position_covariance_type"] == S.COVARIANCE_DIAGONAL_KNOWN


def test_location_fix_without_sigmas_or_position():
    doc = S.location_fix_doc(_fix(), stamp_ns=2_000_000_001)
    assert doc["position_covariance_type"] == S.COVARIANCE_UNKNOWN
    assert doc["position_covariance"] == [0.0] * 9
    assert doc["timestamp"] == {"sec": 2, "nsec": 1}
    assert doc["altitude"] == 520.0
    approx = S.location_fix_doc(_fix(gnss_pos_sigma_h_m=1.0))
    assert approx["position_covariance_type"] == S.COVARIANCE_APPROXIMATED
    assert approx["position_covariance"][8] == pytest.approx(4.0)
    assert S.location_fix_doc(_fix(gnss_lat_deg=math.nan)) is None


def test_validator_reports_what_is_wrong():
    schema = S.SCHEMAS[S.RAW_CAN]
    good = S.raw_can_doc(1, 0x10, b"\x01")
    assert S.validate(good, schema) == []
    assert any("missing 'dlc'" in e for e in S.validate({k: v for k, v in good.items()
                                                         if k != "dlc"}, schema))
    assert any("unexpected" in e for e in S.validate({**good, "extra": 1}, schema))
    assert S.validate({**good, "data_hex": "0G"}, schema)
    assert S.validate({**good, "direction": "up"}, schema)
    assert S.validate({**good, "dlc": True}, schema)  # a bool is not an integer


def test_register_schema_refuses_to_change_a_name():
    S.register_schema("vdps.TestOnly.v1", {"title": "vdps.TestOnly.v1", "type": "object"})
    S.register_schema("vdps.TestOnly.v1", {"title": "vdps.TestOnly.v1", "type": "object"})
    with pytest.raises(ValueError):
        S.register_schema("vdps.TestOnly.v1", {"title": "vdps.TestOnly.v1", "type": "array"})
    with pytest.raises(KeyError):
        S.schema_bytes("vdps.Nope.v1")


@pytest.mark.parametrize("name", ["", "a/b", "a b", "can0\n", None])
def test_bad_logical_names_are_refused(name):
    with pytest.raises(ValueError):
        S.can_topic(name)


@pytest.mark.parametrize("topic", ["truth/state", "/truth/", "/a//b", "/a b", ""])
def test_bad_topics_are_refused(topic):
    with pytest.raises(ValueError):
        S.check_topic(topic)


def test_topic_builders():
    assert S.can_topic("chassis") == "/raw/can/chassis"
    assert S.serial_topic("imu") == "/raw/serial/imu"
    assert S.sample_topic("can.vdps", "wheel_speed") == "/decoded/can.vdps/wheel_speed"


def test_content_hash_of_bytes_and_file_agree(tmp_path):
    blob = b"BO_ 256 WHEEL: 8 VDPS\n"
    p = tmp_path / "x.dbc"
    p.write_bytes(blob)
    assert S.content_hash(blob) == "sha256:" + hashlib.sha256(blob).hexdigest()
    assert S.content_hash(p) == S.content_hash(blob)
    assert S.content_hash(str(p)) != S.content_hash(b"other")


def test_clean_json_handles_numpy_and_nonfinite():
    out = S.clean_json({"a": np.float64(1.5), "b": [np.nan, np.int64(3)], "c": {"d": -math.inf}})
    assert out == {"a": 1.5, "b": [None, 3], "c": {"d": None}}
    assert S.nan_from_null({"a": None, "b": 2.0})["b"] == 2.0
    assert math.isnan(S.nan_from_null({"a": None})["a"])
