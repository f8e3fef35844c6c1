"""The JSON bytes of recording messages, encoded apart from the writer.

``json_payload`` is what :meth:`~vdps_hil.record.writer.RecordingWriter.write_json` writes,
``estimate_payload`` what ``write_estimate`` writes (directly when every value is a plain float);
``sample_payload`` what ``write_sample`` writes; ``vdps replay --jobs 2`` encodes with them in
one process and writes the bytes in the other (``RecordingWriter.write_encoded``).
``raw_can_rows`` is what ``write_can`` writes for many received classic frames at once (numpy, the
simulator's CAN recording: thousands of frames per simulated second).
"""

from __future__ import annotations

import base64
import json
import math
import operator
from typing import Any, Mapping

import numpy as np

from vdps_hil.record import schemas as S

__all__ = ["check_run", "estimate_payload", "estimate_topic", "json_payload", "raw_can_payload", "raw_can_rows",
           "raw_serial_payload", "sample_payload", "truth_payload"]

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


_TRUTH_HEADS: dict[tuple, list[str]] = {}


def truth_payload(topic: str, t_ns: int, values: Mapping[str, Any]) -> bytes:
    """The bytes ``RecordingWriter.write_truth`` writes (= ``json_payload`` of
    ``schemas.truth_doc``). The simulator's snapshot (a flat dict of str keys to finite floats
    and ints, 100 per simulated second) is written directly: each value as ``repr`` (what json
    writes for an int and a finite float) after its key's cached ``"key":``; a non-finite value
    (the sum is not finite), another type or a non-str key takes the general path."""
    if type(values) is dict and type(t_ns) is int and 0 <= t_ns <= S.MAX_TIME_NS:
        vals = values.values()
        try:
            plain = set(map(type, vals)) <= {float, int} and math.isfinite(sum(vals))
        except OverflowError:  # an int too large for a float
            plain = False
        keys = tuple(values) if plain else ()
        heads = _TRUTH_HEADS.get(keys)
        if plain and heads is None and all(type(k) is str for k in keys):
            if len(_TRUTH_HEADS) > 64:
                _TRUTH_HEADS.clear()
            heads = _TRUTH_HEADS[keys] = [("," if i else "") + json.dumps(k) + ":" for i, k in enumerate(keys)]
        if plain and heads is not None:
            return ('{"t_ns":%d,"values":{%s}}' % (t_ns, "".join(map(operator.add, heads, map(repr, vals))))).encode()
    return json_payload(topic, S.TRUTH, t_ns, S.truth_doc(t_ns, values))


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


def raw_can_payload(t_ns: int, msg_or_fields: Any, direction: str | None = None) -> bytes:
    """The bytes ``RecordingWriter.write_can`` writes for one frame (``t_ns`` checked by the caller)."""
    m = msg_or_fields
    if isinstance(m, Mapping):
        data = m.get("data")
        data = bytes.fromhex(m.get("data_hex", "")) if data is None else data
        direction = m.get("direction", "rx") if direction is None else direction
        flags = ("is_extended_id", "is_fd", "is_remote_frame", "is_error_frame", "bitrate_switch",
                 "error_state_indicator")
        doc = S.raw_can_doc(t_ns, m["arbitration_id"], data, dlc=m.get("dlc"), direction=direction,
                            **{k: m.get(k, False) for k in flags})
        payload = json.dumps(doc, separators=(",", ":")).encode()
    else:  # can.Message (duck-typed): fast path, same document as raw_can_doc
        if direction is None:
            direction = "rx" if getattr(m, "is_rx", True) else "tx"
        elif direction not in ("rx", "tx"):
            raise ValueError(f"direction must be 'rx' or 'tx', got {direction!r}")
        aid, ext, dlc, data = m.arbitration_id, m.is_extended_id, m.dlc, m.data or b""
        if not 0 <= aid <= (0x1FFFFFFF if ext else 0x7FF) or not 0 <= dlc <= 64 \
                or len(data) > 64:
            raise ValueError(f"bad CAN frame: id 0x{aid:X} extended={ext} dlc={dlc} "
                             f"len={len(data)}")
        fd = m.is_fd
        tail = (f',"bitrate_switch":{"true" if m.bitrate_switch else "false"},'
                f'"error_state_indicator":{"true" if m.error_state_indicator else "false"}'
                if fd else "")
        payload = (f'{{"t_ns":{t_ns},"arbitration_id":{aid},'
                   f'"is_extended_id":{"true" if ext else "false"},'
                   f'"is_fd":{"true" if fd else "false"},'
                   f'"is_remote_frame":{"true" if m.is_remote_frame else "false"},'
                   f'"is_error_frame":{"true" if m.is_error_frame else "false"},'
                   f'"dlc":{dlc},"data_hex":"{bytes(data).hex()}",'
                   f'"direction":"{direction}"{tail}}}').encode()
    return payload


def raw_serial_payload(t_ns: int, data: bytes) -> bytes:
    """The bytes ``RecordingWriter.write_serial`` writes for one read chunk (= ``json.dumps`` of
    ``schemas.raw_serial_doc``: base64 needs no escaping; ``t_ns`` checked by the caller)."""
    return b'{"t_ns":%d,"data_b64":"%s"}' % (t_ns, base64.b64encode(bytes(data)))


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


_HEX_PAIRS = np.frombuffer(b"".join(b"%02x" % b for b in range(256)), dtype=np.uint8).reshape(256, 2)
_POW10 = 10 ** np.arange(18, -1, -1, dtype=np.int64)  # 10^18 .. 10^0: the 19 digits of an int64


def _ascii(text: str) -> np.ndarray:
    return np.frombuffer(text.encode(), dtype=np.uint8)


def _can_middle(arbitration_id: int, dlc: int) -> np.ndarray:
    """The text of a raw CAN payload between ``t_ns`` and the data's hex (``write_can``)."""
    return _ascii(f',"arbitration_id":{arbitration_id},"is_extended_id":false,"is_fd":false,'
                  f'"is_remote_frame":false,"is_error_frame":false,"dlc":{dlc},"data_hex":"')


def raw_can_rows(t_ns: np.ndarray, arbitration_ids: np.ndarray, dlcs: np.ndarray, data: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The payloads ``RecordingWriter.write_can`` writes for N received (``rx``) classic frames
    with standard IDs (not remote, not error frames): ``(rows, lengths)``, rows (N, W) uint8 with
    payload k in ``rows[k, :lengths[k]]`` (zero padding after it). ``t_ns`` int64 >= 0,
    ``arbitration_ids`` 0..0x7FF, ``dlcs`` 0..8, ``data`` (N, >= max DLC) uint8 (the first DLC
    bytes of row k are frame k's); ValueError when one is out of range.

    A payload is fixed text around three fields: the decimal ``t_ns``, the ID and DLC (fixed per
    (ID, DLC)) and the data's hex; the rows are filled per (ID, DLC, number of digits of
    ``t_ns``) group, each group's columns with one slice assignment."""
    t = np.asarray(t_ns, dtype=np.int64)
    n = t.size
    aid = np.asarray(arbitration_ids, dtype=np.int64)
    dlc = np.asarray(dlcs, dtype=np.int64)
    data = np.asarray(data, dtype=np.uint8).reshape(n, -1) if n else np.zeros((0, 8), np.uint8)
    if n and (t.min() < 0 or aid.min() < 0 or aid.max() > 0x7FF or dlc.min() < 0 or dlc.max() > min(8, data.shape[1])
              or aid.shape != t.shape or dlc.shape != t.shape):
        raise ValueError("bad CAN frames: times must be >= 0, standard IDs 0..0x7FF, DLC 0..8 within the data")
    digits = np.maximum(np.searchsorted(_POW10[::-1], t, side="right"), 1)  # decimal digits of t
    key = (aid * 16 + dlc) * 32 + digits
    head, tail = _ascii('{"t_ns":'), _ascii('","direction":"rx"}')
    width = len(head) + 19 + len(_can_middle(0x7FF, 8)) + 16 + len(tail)
    rows = np.zeros((n, width), dtype=np.uint8)
    lengths = np.zeros(n, dtype=np.int64)
    if n == 0:
        return rows, lengths
    chars = (t[:, None] // _POW10[None, :]) % 10 + 48  # (N, 19) decimal digits, leading zeros
    for k in np.unique(key).tolist():
        sel = np.flatnonzero(key == k)
        a, d, nd = k // 512, (k // 32) % 16, k % 32
        mid = _can_middle(a, d)
        c = len(head)
        block = np.empty((sel.size, c + nd + len(mid) + 2 * d + len(tail)), dtype=np.uint8)
        block[:, :c] = head
        block[:, c:c + nd] = chars[sel, 19 - nd:]
        c += nd
        block[:, c:c + len(mid)] = mid
        c += len(mid)
        block[:, c:c + 2 * d] = _HEX_PAIRS[data[sel, :d]].reshape(sel.size, 2 * d)
        block[:, c + 2 * d:] = tail
        rows[sel, :block.shape[1]] = block
        lengths[sel] = block.shape[1]
    return rows, lengths
