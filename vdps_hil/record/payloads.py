"""The JSON bytes of recording messages, encoded apart from the writer.

``json_payload`` is what :meth:`~vdps_hil.record.writer.RecordingWriter.write_json` writes,
``estimate_payload`` what ``write_estimate`` writes (directly when every value is a plain float);
``sample_payload`` what ``write_sample`` writes; ``vdps replay --jobs 2`` encodes with them in
one process and writes the bytes in the other (``RecordingWriter.write_encoded``).
"""

from __future__ import annotations

import json
from typing import Any, Mapping

from vdps_hil.record import schemas as S

__all__ = ["check_run", "estimate_payload", "estimate_topic", "json_payload", "sample_payload"]

_JSON_KEYS: dict[str, str] = {}
_SAMPLE_HEADS: dict[tuple[str, str], str] = {}


def _float_object(d: Mapping[str, Any]) -> str | None:
    """The compact JSON object ``json.dumps(clean_json(dict(d)), separators=(",", ":"))`` of a
    flat mapping of str keys to plain floats (non-finite -> null; json writes a float with
    ``float.__repr__``), or None when some key or value is of another type (the caller then
    takes the general path)."""
    parts = []
    keys = _JSON_KEYS
    rep = float.__repr__
    for k, v in d.items():
        if type(v) is not float or type(k) is not str:
            return None
        q = keys.get(k)
        if q is None:
            if len(keys) > 4096:
                keys.clear()
            q = keys[k] = json.dumps(k) + ":"
        parts.append(q + (rep(v) if v - v == 0.0 else "null"))
    return "{" + ",".join(parts) + "}"


def _clean_flat(d: Mapping[str, Any]) -> dict:
    """``schemas.clean_json(dict(d))`` for a flat mapping, without recursion for plain floats."""
    out = {}
    for k, v in d.items():
        out[str(k)] = (v if v - v == 0.0 else None) if type(v) is float else S.clean_json(v)
    return out


def json_payload(topic: str, schema_name: str, t_ns: int, doc: Mapping[str, Any]) -> bytes:
    """The bytes ``RecordingWriter.write_json`` writes for ``doc`` (topic, time and schema
    checked; ``t_ns`` added when the schema has it; non-finite floats -> null)."""
    S.check_topic(topic)
    S.check_time_ns("t_ns", t_ns)
    if schema_name not in S.SCHEMAS:
        raise KeyError(f"unknown schema {schema_name!r}; register it with "
                       "vdps_hil.record.schemas.register_schema()")
    doc = S.clean_json(dict(doc))
    if "t_ns" in S.SCHEMAS[schema_name].get("properties", {}):
        if doc.setdefault("t_ns", t_ns) != t_ns:
            raise ValueError(f"doc t_ns {doc['t_ns']} differs from t_ns {t_ns}")
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()


def estimate_topic(topic: str) -> str:
    """The absolute, checked topic of an estimate (``"ekf"`` -> ``/est/ekf``)."""
    if not topic.startswith("/"):
        topic = S.EST_PREFIX + topic
    if not S.check_topic(topic).startswith(S.EST_PREFIX):
        raise ValueError(f"estimate topic must be under {S.EST_PREFIX}: {topic}")
    return topic


def estimate_payload(t_ns: int, values: Mapping[str, float], sigmas: Mapping[str, float] | None = None) -> bytes:
    """The bytes of an estimate message (schema ``ESTIMATE``): = ``json_payload`` of
    ``{"t_ns", "values", "sigmas"}``, written directly when every value is a plain float (a
    replay writes thousands of these per second)."""
    S.check_time_ns("t_ns", t_ns)
    v = _float_object(values)
    sg = "" if sigmas is None else _float_object(sigmas)
    if v is not None and sg is not None:
        return (f'{{"t_ns":{int(t_ns)},"values":{v}' + (f',"sigmas":{sg}}}' if sigmas is not None else "}")
                ).encode()
    doc = {"t_ns": t_ns, "values": _clean_flat(values)}
    if sigmas is not None:
        doc["sigmas"] = _clean_flat(sigmas)
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()


def sample_payload(s) -> bytes:
    """The bytes ``RecordingWriter.write_sample`` writes for a bus ``Sample`` (``json.dumps`` of
    ``Sample.to_json``, compact, non-finite values as null): written directly when the times are
    ints, ``valid`` a bool and every field a plain float (every decoded sample), else by
    ``json.dumps``."""
    t, w, valid = s.t_ns, s.wall_time_ns, s.valid
    fields = _float_object(s.fields) if type(t) is int and type(w) is int and type(valid) is bool else None
    if fields is None:
        return json.dumps(s.to_json(), separators=(",", ":"), allow_nan=False).encode()
    key = (s.source, s.kind)
    head = _SAMPLE_HEADS.get(key)
    if head is None:
        if len(_SAMPLE_HEADS) > 4096:
            _SAMPLE_HEADS.clear()
        head = _SAMPLE_HEADS[key] = f',"source":{json.dumps(key[0])},"kind":{json.dumps(key[1])},"valid":'
    return (f'{{"t_ns":{t},"wall_time_ns":{w}{head}{"true" if valid else "false"},"fields":{fields}}}').encode()


def check_run(topic: str, schema_name: str, t_ns, payloads, wall_time_ns) -> tuple[tuple, tuple, tuple]:
    """The checks ``write_encoded`` makes of each message, of a run of one topic (times at once,
    each one's own error where one fails): (t_ns, payloads, log times) as tuples; a log time
    0 or None stays for the writer's rule."""
    S.check_topic(topic)
    if schema_name not in S.SCHEMAS:
        raise KeyError(f"unknown schema {schema_name!r}")
    t_ns, payloads, walls = tuple(t_ns), tuple(payloads), tuple(wall_time_ns)
    if not len(t_ns) == len(payloads) == len(walls):
        raise ValueError("t_ns, payloads and wall_time_ns differ in length")
    if not t_ns:
        return t_ns, payloads, walls
    for what, ts in (("t_ns", t_ns), ("wall_time_ns", [w for w in walls if w])):
        if ts and not (all(type(t) is int for t in ts) and 0 <= min(ts) and max(ts) <= S.MAX_TIME_NS):
            for t in ts:  # raises the one-by-one error
                S.check_time_ns(what, t)
    if not all(type(p) is bytes for p in payloads):
        bad = next(p for p in payloads if not isinstance(p, bytes))
        raise TypeError(f"payload must be bytes, got {type(bad).__name__}")
    return t_ns, payloads, walls
