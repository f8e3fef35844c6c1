"""The order in which a live system received its samples, kept in the recording so a replay can
feed the recorded ``/decoded/`` samples in exactly that order (``vdps replay --input-order
recorded``) and reproduce the live outputs.

Format: the MCAP metadata record ``hil.input_order`` (written by ``vdps bench -o`` and
``vdps log --pipeline -o``)::

    topics          JSON list of the /decoded/ topics, index k -> topic
    count           number of samples fed, as a decimal string
    index_bytes     "1" (one byte per sample) or "2" (little-endian uint16, more than 256
                    topics); absent: "1"
    order_zlib_b64  base64(zlib(the topic index of each sample fed, in order)))

Sample j of the input is the next not yet used record of topic ``topics[order[j]]``, in the
file's order of that topic (the writer's order; ``RecordingReader`` keeps it per topic). Every
sample noted must therefore be a record of its topic in the same file, noted in the order it
was written: note a sample only after the writer accepted it. Other keys (the settings of the
live system, ``vdps log --pipeline``) are JSON values, returned by :func:`read_input_order`.
"""

from __future__ import annotations

import base64
import json
import sys
import zlib
from array import array
from typing import Any, Mapping

from vdps_hil.bus.samples import Sample
from vdps_hil.record import schemas as S

__all__ = ["INPUT_ORDER_METADATA", "InputOrder", "read_input_order", "input_order_samples", "recorded_drops"]

INPUT_ORDER_METADATA = "hil.input_order"
_FORMAT_KEYS = ("topics", "count", "index_bytes", "order_zlib_b64")


class InputOrder:
    """Collects the input order, one :meth:`note` per sample fed; :meth:`metadata` is the
    record to write (``writer.add_metadata(INPUT_ORDER_METADATA, order.metadata())``)."""

    def __init__(self):
        self._topics: dict[tuple[str, str], int] = {}
        self._order: bytearray | array = bytearray()

    def __len__(self) -> int:
        return len(self._order)

    def note(self, s: Sample) -> None:
        key = (s.source, s.kind)
        k = self._topics.get(key)
        if k is None:
            k = self._topics[key] = len(self._topics)
            if k == 256:  # one byte per sample no longer does
                self._order = array("H", iter(self._order))  # (a bytearray would be taken as raw bytes)
        self._order.append(k)

    def metadata(self, **settings: Any) -> dict[str, str]:
        """The metadata record; ``settings`` are added as JSON values."""
        topics = [S.sample_topic(src, kind) for src, kind in sorted(self._topics, key=self._topics.get)]
        if isinstance(self._order, array):
            a = array("H", self._order)
            if sys.byteorder != "little":
                a.byteswap()
            raw, width = a.tobytes(), "2"
        else:
            raw, width = bytes(self._order), "1"
        md = {"topics": json.dumps(topics), "count": str(len(self._order)), "index_bytes": width,
              "order_zlib_b64": base64.b64encode(zlib.compress(raw, 9)).decode("ascii")}
        for k, v in settings.items():
            md[k] = json.dumps(S.clean_json(v), sort_keys=True)
        return md


def read_input_order(reader) -> tuple[list[Sample], dict[str, Any]]:
    """(the ``/decoded/`` samples in the recorded input order, the settings recorded with it).
    Raises ValueError (also KeyError, IndexError, TypeError for a damaged record)."""
    md: Mapping[str, str] | None = reader.metadata().get(INPUT_ORDER_METADATA)
    if md is None:
        raise ValueError(f"no {INPUT_ORDER_METADATA} metadata in this recording (written by vdps bench -o "
                         "and vdps log --pipeline -o)")
    topics = json.loads(md["topics"])
    if not isinstance(topics, list) or not all(isinstance(t, str) and t.startswith(S.DECODED_PREFIX)
                                               for t in topics):
        raise ValueError("topics must be a list of /decoded/ topics")
    raw = zlib.decompress(base64.b64decode(md["order_zlib_b64"]))
    width = md.get("index_bytes", "1")
    if width == "1":
        order: bytes | array = raw
    elif width == "2":
        order = array("H")
        order.frombytes(raw)
        if sys.byteorder != "little":
            order.byteswap()
    else:
        raise ValueError(f"index_bytes must be 1 or 2, got {width!r}")
    if len(order) != int(md["count"]):
        raise ValueError(f"{len(order)} samples in the order, count says {md['count']}")
    per_topic: dict[str, list] = {t: [] for t in topics}
    for rec in reader.iter_records(topics=topics):
        per_topic[rec.topic].append(rec.data)
    lists = [per_topic[t] for t in topics]
    pos = [0] * len(topics)
    out = []
    for k in order:
        data = lists[k][pos[k]]  # IndexError: more samples noted than the file holds
        pos[k] += 1
        out.append(Sample.from_json(json.loads(data)))
    settings = {k: json.loads(v) for k, v in md.items() if k not in _FORMAT_KEYS}
    return out, settings


def input_order_samples(reader) -> list[Sample]:
    """The ``/decoded/`` samples of a recording in the order the live system received them
    (metadata ``hil.input_order``): what ``VdpsSystem.replay`` needs to reproduce the live run."""
    return read_input_order(reader)[0]


def recorded_drops(settings: Mapping[str, Any]) -> tuple[int, ...]:
    """The t0 [ns] of the predictions the live system dropped at their deadline (setting
    ``prediction``, ``VdpsSystem.status()["prediction"]``; none recorded: ()): a replay drops
    them again (``SystemConfig.prediction_drops_t0_ns``) to reproduce the live run."""
    drops = (settings.get("prediction") or {}).get("dropped_t0_ns", [])
    if not isinstance(drops, list) or not all(isinstance(t, int) and not isinstance(t, bool) for t in drops):
        raise ValueError("prediction.dropped_t0_ns must be a list of integer times")
    return tuple(drops)
