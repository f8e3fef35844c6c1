"""Tests of vdps_hil.record.foxglove_schemas: our JSON schemas carry exactly the field names of
Foxglove's own schemas (checked against the schema descriptors shipped in the foxglove-sdk
package, an independent source), the document builders produce valid documents with those
fields, and time stamps are {sec, nsec} of the nanoseconds."""

from __future__ import annotations

import math

import pytest

from vdps_hil.bus.samples import Sample
from vdps_hil.record import foxglove_schemas as F
from vdps_hil.record import schemas as S

foxglove_messages = pytest.importorskip("foxglove.messages")


def _descriptor_has_field(descriptor: bytes, name: str) -> bool:
    """Whether a protobuf FileDescriptorSet (the SDK's schema data) declares a field ``name``:
    FieldDescriptorProto.name is field 1, a length-delimited string (tag 0x0a)."""
    raw = name.encode()
    return b"\x0a" + bytes([len(raw)]) + raw in descriptor


def _names(schema: dict) -> set[str]:
    """Every property name, nested ones included, except the members of a ``time`` ({sec, nsec}
    in JSON; the protobuf schema's google.protobuf.Timestamp has its own field names)."""
    out = set()
    for k, v in schema.get("properties", {}).items():
        out.add(k)
        if v.get("title") != "time":
            out |= _names(v)
    return out


@pytest.mark.parametrize("name, sdk", [(F.LOCATION_FIX, "LocationFix"), (F.FRAME_TRANSFORM, "FrameTransform"),
                                       (F.POSE_IN_FRAME, "PoseInFrame")])
def test_field_names_are_foxglove_s(name, sdk):
    ours = S.SCHEMAS[name]
    theirs = getattr(foxglove_messages, sdk).get_schema()
    assert theirs.name == name == ours["title"]
    for field in _names(ours):
        assert _descriptor_has_field(theirs.data, field), f"{name}: {field} is not a field of Foxglove's schema"
    assert not _descriptor_has_field(theirs.data, "no_such_field")


def test_required_fields_are_foxglove_s_required_ones():
    req = {n: set(S.SCHEMAS[n]["required"]) for n in (F.FRAME_TRANSFORM, F.POSE_IN_FRAME)}
    assert req[F.FRAME_TRANSFORM] == {"timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"}
    assert req[F.POSE_IN_FRAME] == {"timestamp", "frame_id", "pose"}


def test_documents_validate_and_stamp_in_sec_nsec():
    stamp = 1_533_226_488_299_000_123
    tf = F.frame_transform_doc(stamp, "enu", "vehicle", (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
    pose = F.pose_in_frame_doc(stamp, "enu", (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))
    fix = F.geodetic_fix_doc(stamp, 37.72, -122.47, 10.0, (0.5, 0.6, 1.0))
    for doc, name in ((tf, F.FRAME_TRANSFORM), (pose, F.POSE_IN_FRAME), (fix, F.LOCATION_FIX)):
        assert S.validate(doc, S.SCHEMAS[name]) == [], name
        assert doc["timestamp"] == {"sec": 1_533_226_488, "nsec": 299_000_123}
    assert fix["position_covariance"][0] == pytest.approx(0.25) and fix["position_covariance"][8] == 1.0
    assert fix["position_covariance_type"] == F.COVARIANCE_DIAGONAL_KNOWN
    unknown = F.geodetic_fix_doc(stamp, 37.72, -122.47, math.nan, (math.nan, 1.0, 1.0))
    assert unknown["position_covariance_type"] == F.COVARIANCE_UNKNOWN and unknown["altitude"] == 0.0
    assert F.geodetic_fix_doc(stamp, math.nan, 1.0, 0.0) is None
    with pytest.raises(ValueError):
        F.foxglove_time(-1)
    with pytest.raises(TypeError):
        F.foxglove_time(1.5)


def test_location_fix_of_a_gnss_sample_is_ellipsoidal():
    s = Sample(5, "gnss", "gnss_pos", {"gnss_lat_deg": 24.0, "gnss_lon_deg": 121.0, "gnss_alt_m": 100.0,
                                       "gnss_geoid_sep_m": 20.0, "gnss_pos_sigma_h_m": 0.5}, 7_000_000_001, True)
    doc = F.location_fix_doc(s)
    assert doc["altitude"] == 120.0 and doc["timestamp"] == {"sec": 7, "nsec": 1}
    assert doc["position_covariance_type"] == F.COVARIANCE_APPROXIMATED  # vertical sigma assumed 2 sigma_h
    assert S.validate(doc, S.SCHEMAS[F.LOCATION_FIX]) == []
