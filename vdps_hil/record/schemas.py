"""Recording layout: topics, JSON schemas and the message documents written to MCAP.

Layout version 1 (``LAYOUT_VERSION``). Every channel uses message encoding ``json`` and a
schema of encoding ``jsonschema`` whose name carries its version (``vdps.RawCan.v1``); a
change of meaning gets a new name (``...v2``), never an edit of an existing one.

=============================  =====================  ==========================================
topic                          schema                 one message per
=============================  =====================  ==========================================
``/raw/can/<bus>``             ``vdps.RawCan.v1``     CAN frame (``<bus>`` a logical bus name)
``/raw/serial/<device>``       ``vdps.RawSerial.v1``  read chunk of a serial device
``/decoded/<source>/<kind>``   ``vdps.Sample.v1``     bus sample (``vdps_hil.bus.samples``)
``/gnss/fix`` (any topic)      ``foxglove.LocationFix``  GNSS position sample, for Foxglove maps
``/est/fix``                   ``foxglove.LocationFix``  estimated CG position (replay, live pipeline)
``/est/tf``                    ``foxglove.FrameTransform``  estimated pose: frame ``vehicle`` in ``enu``
``/est/pose``                  ``foxglove.PoseInFrame``  the same pose, for the 3D panel's path
``/truth/...``                 ``vdps.Truth.v1``      simulation epoch (100 Hz), simulation only
``/est/...``                   ``vdps.Estimate.v1``   estimator output epoch
=============================  =====================  ==========================================

Time (integer nanoseconds everywhere):

* ``t_ns`` (in every document and as the MCAP ``publish_time``): the monotonic time the
  quantity was measured; recordings are ordered by it. Within one topic it never decreases.
* MCAP ``log_time``: wall-clock UTC nanoseconds (``wall_time_ns``), for tools such as
  Foxglove. In simulation there is no wall clock: ``log_time = sim_epoch_ns + t_ns`` with a
  fixed epoch (``DEFAULT_SIM_EPOCH_NS``), so a simulated file is bit-for-bit reproducible.

Raw serial channels carry the device's baud rate and format (``nmea``, ``vn-binary`` ...) in
their channel metadata (``baud``, ``format``). Non-finite floats are written as JSON ``null``
(JSON has no NaN) and read back as NaN.

The file's metadata record ``vdps.recording`` holds the layout version, the tool and its
version, the time convention, content hashes (``hash.<role>`` = ``sha256:<hex>``) and the
caller's free-form string metadata.
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import os
import re
from typing import Any, Mapping

from vdps_hil.record.foxglove_schemas import (  # noqa: F401 - re-exported: the layout's Foxglove part
    COVARIANCE_APPROXIMATED, COVARIANCE_DIAGONAL_KNOWN, COVARIANCE_KNOWN, COVARIANCE_UNKNOWN, ENU_FRAME,
    EST_FIX_TOPIC, EST_POSE_TOPIC, EST_TF_TOPIC, FOXGLOVE_SCHEMAS, FRAME_TRANSFORM, GNSS_FIX_TOPIC, LOCATION_FIX,
    POSE_IN_FRAME, VEHICLE_FRAME, foxglove_time, frame_transform_doc, geodetic_fix_doc, location_fix_doc,
    pose_in_frame_doc)

LAYOUT_VERSION = "1"
"""Recording layout version written to the ``vdps.recording`` metadata record."""

METADATA_NAME = "vdps.recording"
"""Name of the MCAP metadata record holding the recording's provenance."""

MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"

RAW_PREFIX = "/raw/"
RAW_CAN_PREFIX = "/raw/can/"
RAW_SERIAL_PREFIX = "/raw/serial/"
DECODED_PREFIX = "/decoded/"
TRUTH_PREFIX = "/truth/"
EST_PREFIX = "/est/"

RAW_CAN = "vdps.RawCan.v1"
RAW_SERIAL = "vdps.RawSerial.v1"
SAMPLE = "vdps.Sample.v1"
TRUTH = "vdps.Truth.v1"
ESTIMATE = "vdps.Estimate.v1"

DEFAULT_SIM_EPOCH_NS = 1_352_419_200_000_000_000
"""Fixed wall-clock epoch of simulated recordings: 2012-11-09T00:00:00Z (the paper's
publication month). ``log_time = DEFAULT_SIM_EPOCH_NS + t_ns``."""

MAX_TIME_NS = 2**63 - 1
"""Largest time stamp accepted (MCAP times are uint64; we keep them inside int64)."""

_NAME_RE = re.compile(r"[A-Za-z0-9_.:\-]+")

# --- JSON schemas (draft 2020-12 subset: type, properties, required, enum, bounds, items) -------

_UINT_NS = {"type": "integer", "minimum": 0, "maximum": MAX_TIME_NS}
_NUM_OR_NULL = {"type": ["number", "null"]}

_RAW_CAN_SCHEMA = {
    "title": RAW_CAN,
    "description": "One CAN or CAN FD frame as seen on a bus (the raw truth of a recording).",
    "type": "object",
    "properties": {
        "t_ns": {**_UINT_NS, "description": "Monotonic receive/transmit time [ns]"},
        "arbitration_id": {"type": "integer", "minimum": 0, "maximum": 0x1FFFFFFF,
                           "description": "11-bit or 29-bit identifier"},
        "is_extended_id": {"type": "boolean"},
        "is_fd": {"type": "boolean"},
        "is_remote_frame": {"type": "boolean"},
        "is_error_frame": {"type": "boolean"},
        "dlc": {"type": "integer", "minimum": 0, "maximum": 64,
                "description": "Data length as python-can reports it (bytes; remote frames: "
                               "requested length)"},
        "data_hex": {"type": "string", "pattern": "^([0-9a-f]{2})*$",
                     "description": "Payload, lower-case hex, two digits per byte"},
        "direction": {"type": "string", "enum": ["rx", "tx"]},
        "bitrate_switch": {"type": "boolean", "description": "CAN FD BRS (written only for FD)"},
        "error_state_indicator": {"type": "boolean",
                                  "description": "CAN FD ESI (written only for FD)"},
    },
    "required": ["t_ns", "arbitration_id", "is_extended_id", "is_fd", "is_remote_frame",
                 "is_error_frame", "dlc", "data_hex", "direction"],
    "additionalProperties": False,
}

_RAW_SERIAL_SCHEMA = {
    "title": RAW_SERIAL,
    "description": "One chunk of bytes read from a serial device. Channel metadata: baud, "
                   "format. Lines are framed at decode time.",
    "type": "object",
    "properties": {
        "t_ns": {**_UINT_NS, "description": "Monotonic time the chunk was read [ns]"},
        "data_b64": {"type": "string", "contentEncoding": "base64",
                     "description": "The bytes, standard base64"},
    },
    "required": ["t_ns", "data_b64"],
    "additionalProperties": False,
}

_SAMPLE_SCHEMA = {
    "title": SAMPLE,
    "description": "vdps_hil.bus.samples.Sample: catalogue field name -> SI value (null = NaN).",
    "type": "object",
    "properties": {
        "t_ns": _UINT_NS,
        "wall_time_ns": {"type": "integer", "minimum": 0},
        "source": {"type": "string"},
        "kind": {"type": "string"},
        "valid": {"type": "boolean"},
        "fields": {"type": "object", "additionalProperties": _NUM_OR_NULL},
    },
    "required": ["t_ns", "source", "kind", "fields"],
}

_TRUTH_SCHEMA = {
    "title": TRUTH,
    "description": "Simulator ground truth at one epoch: free-form named SI values (names "
                   "carry units). Simulation only; estimators never read it.",
    "type": "object",
    "properties": {
        "t_ns": _UINT_NS,
        "values": {"type": "object"},
    },
    "required": ["t_ns", "values"],
}

_ESTIMATE_SCHEMA = {
    "title": ESTIMATE,
    "description": "Estimator output at one epoch: named SI values and optional 1-sigma "
                   "standard deviations under the same names (null = NaN).",
    "type": "object",
    "properties": {
        "t_ns": _UINT_NS,
        "values": {"type": "object", "additionalProperties": _NUM_OR_NULL},
        "sigmas": {"type": "object", "additionalProperties": _NUM_OR_NULL},
    },
    "required": ["t_ns", "values"],
}

SCHEMAS: dict[str, dict] = {
    RAW_CAN: _RAW_CAN_SCHEMA,
    RAW_SERIAL: _RAW_SERIAL_SCHEMA,
    SAMPLE: _SAMPLE_SCHEMA,
    TRUTH: _TRUTH_SCHEMA,
    ESTIMATE: _ESTIMATE_SCHEMA,
    **FOXGLOVE_SCHEMAS,
}
"""Schema name -> JSON schema. Extend with :func:`register_schema`, never by editing one."""



def register_schema(name: str, schema: Mapping[str, Any]) -> None:
    """Add a JSON schema under a new versioned name (e.g. ``vdps.Warning.v1``).

    Re-registering the same name with the same schema is a no-op; a different schema under an
    existing name raises ValueError (a changed meaning needs a new version in the name).
    """
    if not name or any(c.isspace() for c in name):
        raise ValueError(f"bad schema name {name!r}")
    schema = dict(schema)
    json.dumps(schema, allow_nan=False)  # must itself be JSON
    old = SCHEMAS.get(name)
    if old is not None and old != schema:
        raise ValueError(f"schema {name!r} already registered with a different definition; "
                         "give the new one a new version in its name")
    SCHEMAS[name] = schema


def schema_bytes(name: str) -> bytes:
    """The schema as stored in the MCAP Schema record (canonical JSON, sorted keys)."""
    try:
        schema = SCHEMAS[name]
    except KeyError:
        raise KeyError(f"unknown schema {name!r}; register it with register_schema()") from None
    return json.dumps(schema, sort_keys=True, separators=(",", ":")).encode()


# --- names and topics -------------------------------------------------------------------------

def check_name(kind: str, name: str) -> str:
    """A logical bus/device/source/kind name: letters, digits and ``_ . : -`` only."""
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise ValueError(f"bad {kind} name {name!r}: use letters, digits and _ . : - only")
    return name


_CHECKED_TOPICS: set[str] = set()
"""Topics ``check_topic`` accepted (at most ``_CHECKED_TOPICS_MAX``): a writer checks every
message's topic, and scanning it character by character was ~7 % of a replay."""
_CHECKED_TOPICS_MAX = 4096


def check_topic(topic: str) -> str:
    """A topic: absolute (``/...``), no empty components, no whitespace."""
    if type(topic) is str and topic in _CHECKED_TOPICS:
        return topic
    if (not isinstance(topic, str) or not topic.startswith("/") or topic.endswith("/")
            or "//" in topic or any(c.isspace() for c in topic)):
        raise ValueError(f"bad topic {topic!r}: expected an absolute path like /truth/state")
    if type(topic) is str and len(_CHECKED_TOPICS) < _CHECKED_TOPICS_MAX:
        _CHECKED_TOPICS.add(topic)
    return topic


def can_topic(bus: str) -> str:
    return RAW_CAN_PREFIX + check_name("bus", bus)


def serial_topic(device: str) -> str:
    return RAW_SERIAL_PREFIX + check_name("device", device)


def sample_topic(source: str, kind: str) -> str:
    return f"{DECODED_PREFIX}{check_name('source', source)}/{check_name('kind', kind)}"


def check_time_ns(what: str, t_ns: int) -> int:
    if isinstance(t_ns, bool) or not isinstance(t_ns, int):
        raise TypeError(f"{what} must be int nanoseconds, got {type(t_ns).__name__}")
    if not 0 <= t_ns <= MAX_TIME_NS:
        raise ValueError(f"{what} out of range: {t_ns}")
    return t_ns


# --- documents --------------------------------------------------------------------------------

def clean_json(o: Any) -> Any:
    """Replace non-finite floats by None (recursively); numpy scalars become Python numbers."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): clean_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean_json(v) for v in o]
    if hasattr(o, "item") and callable(o.item) and not isinstance(o, (str, bytes)):
        return clean_json(o.item())
    return o


def nan_from_null(d: Mapping[str, Any]) -> dict[str, Any]:
    """Inverse of :func:`clean_json` for a flat dict of numbers: None -> NaN."""
    return {k: (math.nan if v is None else v) for k, v in d.items()}


def raw_can_doc(t_ns: int, arbitration_id: int, data: bytes, *, is_extended_id: bool = False,
                is_fd: bool = False, is_remote_frame: bool = False,
                is_error_frame: bool = False, dlc: int | None = None, direction: str = "rx",
                bitrate_switch: bool = False, error_state_indicator: bool = False) -> dict:
    """The ``vdps.RawCan.v1`` document of one frame (validated)."""
    data = bytes(data)
    if dlc is None:
        dlc = len(data)
    if direction not in ("rx", "tx"):
        raise ValueError(f"direction must be 'rx' or 'tx', got {direction!r}")
    id_max = 0x1FFFFFFF if is_extended_id else 0x7FF
    if isinstance(arbitration_id, bool) or not 0 <= int(arbitration_id) <= id_max:
        raise ValueError(f"arbitration_id {arbitration_id!r} out of range for "
                         f"{'extended' if is_extended_id else 'standard'} id")
    if not 0 <= int(dlc) <= 64 or len(data) > 64:
        raise ValueError(f"dlc {dlc} / data length {len(data)} out of range 0..64")
    doc = {"t_ns": check_time_ns("t_ns", t_ns), "arbitration_id": int(arbitration_id),
           "is_extended_id": bool(is_extended_id), "is_fd": bool(is_fd),
           "is_remote_frame": bool(is_remote_frame), "is_error_frame": bool(is_error_frame),
           "dlc": int(dlc), "data_hex": data.hex(), "direction": direction}
    if is_fd:
        doc["bitrate_switch"] = bool(bitrate_switch)
        doc["error_state_indicator"] = bool(error_state_indicator)
    return doc


def raw_serial_doc(t_ns: int, data: bytes) -> dict:
    """The ``vdps.RawSerial.v1`` document of one read chunk."""
    return {"t_ns": check_time_ns("t_ns", t_ns),
            "data_b64": base64.b64encode(bytes(data)).decode("ascii")}


def truth_doc(t_ns: int, values: Mapping[str, Any]) -> dict:
    return {"t_ns": check_time_ns("t_ns", t_ns), "values": clean_json(dict(values))}


def estimate_doc(t_ns: int, values: Mapping[str, float],
                 sigmas: Mapping[str, float] | None = None) -> dict:
    doc = {"t_ns": check_time_ns("t_ns", t_ns), "values": clean_json(dict(values))}
    if sigmas is not None:
        doc["sigmas"] = clean_json(dict(sigmas))
    return doc


# --- provenance -------------------------------------------------------------------------------

_RESERVED_KEYS = ("layout_version", "tool", "tool_version", "mcap_library", "log_time",
                  "publish_time", "sim_epoch_ns", "message_encoding")


def provenance_record(metadata: Mapping[str, Any], hashes: Mapping[str, bytes | os.PathLike | str],
                      sim_epoch_ns: int | None, tool_version: str, mcap_library: str) -> dict[str, str]:
    """The ``vdps.recording`` metadata record of a recording (``record.writer``): the layout's
    keys, then ``metadata`` (reserved keys refused; non-str values as JSON), then
    ``hash.<role>`` of each content."""
    md = {"layout_version": LAYOUT_VERSION, "tool": "vdps-hil",
          "tool_version": tool_version, "mcap_library": mcap_library,
          "message_encoding": MESSAGE_ENCODING, "publish_time": "t_ns",
          "log_time": "sim_epoch_ns+t_ns" if sim_epoch_ns is not None else "wall_time_ns",
          "sim_epoch_ns": "" if sim_epoch_ns is None else str(sim_epoch_ns)}
    for k, v in metadata.items():
        if k in _RESERVED_KEYS:
            raise ValueError(f"metadata key {k!r} is reserved by the recording layout")
        md[str(k)] = v if isinstance(v, str) else json.dumps(clean_json(v), sort_keys=True)
    for role, content in hashes.items():
        md[f"hash.{role}"] = content_hash(content)
    return md


def content_hash(content: bytes | os.PathLike | str) -> str:
    """``sha256:<hex>`` of bytes, or of a file's content when given a path."""
    if isinstance(content, (bytes, bytearray, memoryview)):
        return "sha256:" + hashlib.sha256(bytes(content)).hexdigest()
    h = hashlib.sha256()
    with open(content, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return "sha256:" + h.hexdigest()


# --- a small JSON-schema checker (the subset the schemas above use) ---------------------------

_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}


def _is_type(v: Any, t: str) -> bool:
    if t == "integer":
        return isinstance(v, int) and not isinstance(v, bool)
    if t == "number":
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    return isinstance(v, _TYPES[t])


def validate(doc: Any, schema: Mapping[str, Any], path: str = "$") -> list[str]:
    """Errors of ``doc`` against ``schema`` (keywords: type, properties, required,
    additionalProperties, enum, minimum, maximum, pattern, items, minItems, maxItems).
    Empty list = valid. Used by tests and by tools that check recordings."""
    errs: list[str] = []
    t = schema.get("type")
    if t is not None:
        types = t if isinstance(t, list) else [t]
        if not any(_is_type(doc, x) for x in types):
            return [f"{path}: expected {t}, got {type(doc).__name__} {doc!r:.40}"]
    if "enum" in schema and doc not in schema["enum"]:
        errs.append(f"{path}: {doc!r} not in {schema['enum']}")
    if isinstance(doc, (int, float)) and not isinstance(doc, bool):
        if "minimum" in schema and doc < schema["minimum"]:
            errs.append(f"{path}: {doc} < {schema['minimum']}")
        if "maximum" in schema and doc > schema["maximum"]:
            errs.append(f"{path}: {doc} > {schema['maximum']}")
    if isinstance(doc, str) and "pattern" in schema and not re.search(schema["pattern"], doc):
        errs.append(f"{path}: {doc!r:.40} does not match {schema['pattern']}")
    if isinstance(doc, list):
        if len(doc) < schema.get("minItems", 0) or len(doc) > schema.get("maxItems", len(doc)):
            errs.append(f"{path}: {len(doc)} items out of bounds")
        if "items" in schema:
            for i, v in enumerate(doc):
                errs += validate(v, schema["items"], f"{path}[{i}]")
    if isinstance(doc, dict):
        props = schema.get("properties", {})
        for k in schema.get("required", []):
            if k not in doc:
                errs.append(f"{path}: missing {k!r}")
        extra = schema.get("additionalProperties", True)
        for k, v in doc.items():
            if k in props:
                errs += validate(v, props[k], f"{path}.{k}")
            elif extra is False:
                errs.append(f"{path}: unexpected {k!r}")
            elif isinstance(extra, dict):
                errs += validate(v, extra, f"{path}.{k}")
    return errs
