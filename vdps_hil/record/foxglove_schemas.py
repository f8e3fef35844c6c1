"""Foxglove's message schemas the recordings use (``foxglove.LocationFix``,
``foxglove.FrameTransform``, ``foxglove.PoseInFrame``) and their document builders, so that
Foxglove's Map and 3D panels show the GNSS fixes, the estimated track and the vehicle's pose.

The schemas re-state Foxglove's published JSON schemas (foxglove-sdk ``schemas/jsonschema``)
field by field with the fields Foxglove requires; ``tests/test_foxglove_schemas.py`` checks the
field names against the schemas shipped in the ``foxglove-sdk`` package. Time stamps are
Foxglove's ``time`` ({sec, nsec}); in our files they equal the message's MCAP ``log_time``
(``schemas`` module docstring). ``record.schemas`` holds these schemas in ``SCHEMAS`` and
re-exports the names.
"""

from __future__ import annotations

import math

LOCATION_FIX = "foxglove.LocationFix"
FRAME_TRANSFORM = "foxglove.FrameTransform"
POSE_IN_FRAME = "foxglove.PoseInFrame"
GNSS_FIX_TOPIC = "/gnss/fix"
EST_FIX_TOPIC = "/est/fix"
EST_TF_TOPIC = "/est/tf"
EST_POSE_TOPIC = "/est/pose"
ENU_FRAME = "enu"
"""Foxglove frame of the global ENU frame {g} (origin: ``vdps_hil.conventions``)."""
VEHICLE_FRAME = "vehicle"
"""Foxglove frame of the vehicle (ISO 8855 at the sprung-mass CG)."""

COVARIANCE_UNKNOWN = 0
COVARIANCE_APPROXIMATED = 1
COVARIANCE_DIAGONAL_KNOWN = 2
COVARIANCE_KNOWN = 3

_MAX_NS = 2**63 - 1

# Foxglove's published LocationFix schema (foxglove/schemas), re-stated field by field.
_LOCATION_FIX_SCHEMA = {
    "title": LOCATION_FIX,
    "description": "A navigation satellite fix for any Global Navigation Satellite System",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object", "title": "time", "description": "Timestamp of the message",
            "properties": {"sec": {"type": "integer", "minimum": 0},
                           "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}},
        },
        "frame_id": {"type": "string",
                     "description": "Frame for the sensor. Latitude and longitude readings "
                                    "are at the origin of the frame."},
        "latitude": {"type": "number", "description": "Latitude in degrees"},
        "longitude": {"type": "number", "description": "Longitude in degrees"},
        "altitude": {"type": "number", "description": "Altitude in meters"},
        "position_covariance": {
            "type": "array", "items": {"type": "number"}, "minItems": 9, "maxItems": 9,
            "description": "Position covariance (m^2) defined relative to a tangential plane "
                           "through the reported position. The components are East, North, "
                           "and Up (ENU), in row-major order.",
        },
        "position_covariance_type": {
            "title": "foxglove.PositionCovarianceType", "type": "integer",
            "enum": [0, 1, 2, 3],
            "description": "If position_covariance is available, position_covariance_type "
                           "must be set to indicate the type of covariance. "
                           "0 UNKNOWN, 1 APPROXIMATED, 2 DIAGONAL_KNOWN, 3 KNOWN",
        },
    },
}

# Foxglove's published FrameTransform and PoseInFrame schemas (foxglove-sdk, schemas/jsonschema),
# re-stated with the fields Foxglove requires (optional lineage fields left out).
_TIME = {"type": "object", "title": "time",
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}},
         "required": ["sec", "nsec"]}
_VECTOR3 = {"title": "foxglove.Vector3", "type": "object",
            "properties": {k: {"type": "number", "description": f"{k} coordinate length"} for k in "xyz"},
            "required": ["x", "y", "z"]}
_QUATERNION = {"title": "foxglove.Quaternion", "type": "object",
               "properties": {k: {"type": "number", "description": f"{k} value"} for k in "xyzw"},
               "required": ["x", "y", "z", "w"]}

_FRAME_TRANSFORM_SCHEMA = {
    "title": FRAME_TRANSFORM,
    "description": "A transform between two reference frames in 3D space: the position (translation) and "
                   "orientation (rotation) of the child frame in the parent frame.",
    "type": "object",
    "properties": {
        "timestamp": {**_TIME, "description": "Timestamp of transform"},
        "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
        "child_frame_id": {"type": "string", "description": "Name of the child frame"},
        "translation": {**_VECTOR3, "description": "Position of the child frame's origin in the parent frame"},
        "rotation": {**_QUATERNION, "description": "Orientation of the child frame in the parent frame"},
    },
    "required": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"],
}

_POSE_IN_FRAME_SCHEMA = {
    "title": POSE_IN_FRAME,
    "description": "A timestamped pose for an object or reference frame in 3D space",
    "type": "object",
    "properties": {
        "timestamp": {**_TIME, "description": "Timestamp of pose"},
        "frame_id": {"type": "string", "description": "Frame of reference for pose position and orientation"},
        "pose": {"title": "foxglove.Pose", "type": "object", "description": "Pose in 3D space",
                 "properties": {"position": {**_VECTOR3, "description": "Point denoting position in 3D space"},
                                "orientation": {**_QUATERNION,
                                                "description": "Quaternion denoting orientation in 3D space"}},
                 "required": ["position", "orientation"]},
    },
    "required": ["timestamp", "frame_id", "pose"],
}

FOXGLOVE_SCHEMAS: dict[str, dict] = {
    LOCATION_FIX: _LOCATION_FIX_SCHEMA,
    FRAME_TRANSFORM: _FRAME_TRANSFORM_SCHEMA,
    POSE_IN_FRAME: _POSE_IN_FRAME_SCHEMA,
}


def foxglove_time(stamp_ns: int) -> dict:
    """Foxglove's ``time`` ({sec, nsec}) of integer nanoseconds (0 <= stamp < 2^63)."""
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, int):
        raise TypeError(f"stamp_ns must be int nanoseconds, got {type(stamp_ns).__name__}")
    if not 0 <= stamp_ns <= _MAX_NS:
        raise ValueError(f"stamp_ns out of range: {stamp_ns}")
    return {"sec": stamp_ns // 1_000_000_000, "nsec": stamp_ns % 1_000_000_000}


def location_fix_doc(sample, *, frame_id: str = "gnss", stamp_ns: int | None = None,
                     ellipsoidal: bool = True) -> dict | None:
    """A ``foxglove.LocationFix`` document from a ``gnss_pos`` Sample, or None without a fix.

    ``timestamp`` = ``stamp_ns`` (default: the sample's wall time, else its ``t_ns``).
    ``altitude`` = ``gnss_alt_m + gnss_geoid_sep_m`` (height above the WGS-84 ellipsoid, as
    Foxglove/ROS expect) when ``ellipsoidal`` and the separation is known, else ``gnss_alt_m``
    (0 when unknown). Covariance: diagonal ENU ``(sigma_h^2, sigma_h^2, sigma_v^2)`` with type
    DIAGONAL_KNOWN when ``gnss_pos_sigma_h_m`` is known (sigma_v defaults to 2 sigma_h, type
    APPROXIMATED), else zeros with type UNKNOWN. Returns None when latitude or longitude is not
    finite (nothing to show on a map).
    """
    lat, lon = sample.get("gnss_lat_deg"), sample.get("gnss_lon_deg")
    if not (math.isfinite(lat) and math.isfinite(lon)):
        return None
    alt = sample.get("gnss_alt_m")
    alt = alt if math.isfinite(alt) else 0.0
    sep = sample.get("gnss_geoid_sep_m")
    if ellipsoidal and math.isfinite(sep):
        alt += sep
    sh, sv = sample.get("gnss_pos_sigma_h_m"), sample.get("gnss_pos_sigma_v_m")
    cov = [0.0] * 9
    cov_type = COVARIANCE_UNKNOWN
    if math.isfinite(sh) and sh >= 0:
        cov_type = COVARIANCE_DIAGONAL_KNOWN
        if not (math.isfinite(sv) and sv >= 0):
            sv, cov_type = 2.0 * sh, COVARIANCE_APPROXIMATED
        cov[0] = cov[4] = sh * sh
        cov[8] = sv * sv
    if stamp_ns is None:
        stamp_ns = sample.wall_time_ns or sample.t_ns
    return {"timestamp": foxglove_time(stamp_ns),
            "frame_id": frame_id, "latitude": float(lat), "longitude": float(lon),
            "altitude": float(alt), "position_covariance": cov,
            "position_covariance_type": cov_type}


def geodetic_fix_doc(stamp_ns: int, lat_deg: float, lon_deg: float, h_m: float,
                     sigma_enu_m: tuple[float, float, float] | None = None, *,
                     frame_id: str = VEHICLE_FRAME) -> dict | None:
    """A ``foxglove.LocationFix`` document of a position (ellipsoidal height ``h_m``) with an
    optional 1-sigma per ENU axis (covariance DIAGONAL_KNOWN, else UNKNOWN); None when the
    latitude or longitude is not finite."""
    if not (math.isfinite(lat_deg) and math.isfinite(lon_deg)):
        return None
    cov, cov_type = [0.0] * 9, COVARIANCE_UNKNOWN
    if sigma_enu_m is not None and all(math.isfinite(v) and v >= 0 for v in sigma_enu_m):
        cov[0], cov[4], cov[8] = (float(v) * float(v) for v in sigma_enu_m)
        cov_type = COVARIANCE_DIAGONAL_KNOWN
    return {"timestamp": foxglove_time(stamp_ns), "frame_id": frame_id, "latitude": float(lat_deg),
            "longitude": float(lon_deg), "altitude": float(h_m) if math.isfinite(h_m) else 0.0,
            "position_covariance": cov, "position_covariance_type": cov_type}


def frame_transform_doc(stamp_ns: int, parent: str, child: str, xyz_m, quat_xyzw) -> dict:
    """A ``foxglove.FrameTransform`` document: frame ``child`` at ``xyz_m`` in ``parent``,
    oriented by the unit quaternion ``quat_xyzw`` (child -> parent coordinates)."""
    x, y, z = (float(v) for v in xyz_m)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    return {"timestamp": foxglove_time(stamp_ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": {"x": x, "y": y, "z": z}, "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}}


def pose_in_frame_doc(stamp_ns: int, frame_id: str, xyz_m, quat_xyzw) -> dict:
    """A ``foxglove.PoseInFrame`` document: position ``xyz_m`` and orientation ``quat_xyzw`` in
    frame ``frame_id``."""
    x, y, z = (float(v) for v in xyz_m)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    return {"timestamp": foxglove_time(stamp_ns), "frame_id": frame_id,
            "pose": {"position": {"x": x, "y": y, "z": z}, "orientation": {"x": qx, "y": qy, "z": qz, "w": qw}}}
