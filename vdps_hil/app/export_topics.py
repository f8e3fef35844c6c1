"""``vdps export FILE --csv DIR``: chosen topics of a recording as one CSV file per topic.

Columns: ``t_ns`` (the message's time stamp, integer nanoseconds), then every key of the
topic's JSON messages flattened to a dotted path, in the order first seen (``values.phi_v_rad``,
``translation.x``, ``fields.wheel_speed_radps_1``; a list element ``.0``, ``.1`` ...) -- the paths
``vdps plot FILE TOPIC.KEY`` takes. A key a message lacks, or JSON ``null``, is an empty cell.

A ``/raw/`` topic is exported decoded: ``/raw/can/<bus>`` as the bus samples of that bus and
``/raw/serial/<device>`` as the device's, decoded with the signal map and DBC the recording names
(``app.plot_signals.recorded_samples``, as ``vdps plot`` decodes), columns ``t_ns``, ``source``,
``kind``, ``valid`` and ``fields.<name>`` (SI, catalogue names).

Topics: ``--topic`` (repeatable) is a topic name or a shell pattern (``/est/*``); none: every
topic but the ``/raw/`` ones. The file of ``/est/state`` is ``DIR/est.state.csv``.
"""

from __future__ import annotations

import csv
import fnmatch
import os
from pathlib import Path
from typing import Iterable, Iterator

__all__ = ["ExportError", "flatten", "export_csv", "select_topics"]


class ExportError(ValueError):
    """An unreadable recording, a topic it does not have, an unwritable directory: one line."""


def flatten(doc, prefix: str = "", out: dict | None = None) -> dict:
    """{dotted path: scalar} of a JSON document (lists by index; ``None`` kept as ``None``)."""
    out = {} if out is None else out
    if isinstance(doc, dict):
        for k, v in doc.items():
            flatten(v, f"{prefix}{k}.", out)
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            flatten(v, f"{prefix}{i}.", out)
    else:
        out[prefix[:-1]] = doc
    return out


def select_topics(all_topics: Iterable[str], wanted: Iterable[str]) -> list[str]:
    """The topics to export (module docstring); ExportError naming a pattern that matches nothing."""
    all_topics = list(all_topics)
    wanted = list(wanted)
    if not wanted:
        return [t for t in all_topics if not t.startswith("/raw/")]
    out: list[str] = []
    for w in wanted:
        hit = [t for t in all_topics if fnmatch.fnmatchcase(t, w)]
        if not hit:
            shown = ", ".join(all_topics)[:300]
            raise ExportError(f"--topic {w}: no such topic in the recording (topics: {shown})")
        out.extend(t for t in hit if t not in out)
    return out


def _raw_source(topic: str) -> str:
    from vdps_hil.record import schemas as S

    if topic.startswith(S.RAW_CAN_PREFIX):
        return "can." + topic[len(S.RAW_CAN_PREFIX):]
    return topic[len(S.RAW_SERIAL_PREFIX):]


def _rows(reader, path, topic: str) -> Iterator[dict]:
    if not topic.startswith("/raw/"):
        for _, t_ns, doc in reader.iter_messages(topics=[topic]):
            yield flatten(doc, "", {"t_ns": t_ns}) if isinstance(doc, dict) else {"t_ns": t_ns, "value": doc}
        return
    from vdps_hil.app.plot_signals import PlotError, recorded_samples

    source = _raw_source(topic)
    try:
        samples = recorded_samples(reader, path)
    except PlotError as e:
        raise ExportError(str(e)) from None
    for s in samples:
        if s.source == source:
            row = {"t_ns": s.t_ns, "source": s.source, "kind": s.kind, "valid": s.valid}
            row.update((f"fields.{k}", v) for k, v in s.fields.items())
            yield row


def _cell(v):
    if v is None:
        return ""
    if isinstance(v, float) and v != v:
        return ""
    return v


def export_csv(path, out_dir, topics: Iterable[str] = ()) -> dict[str, dict]:
    """Write one CSV per chosen topic into ``out_dir`` (created); returns
    {topic: {"file", "rows", "columns"}}. Two passes per topic: the columns, then the rows."""
    from vdps_hil.record.reader import RecordingError, RecordingReader

    try:
        reader = RecordingReader(path)
    except RecordingError as e:
        raise ExportError(str(e)) from None
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        reader.close()
        raise ExportError(f"cannot create {out_dir}: {e.strerror or e}") from None
    result: dict[str, dict] = {}
    with reader:
        for topic in select_topics(reader.topics(), topics):
            columns: dict[str, None] = {}
            for row in _rows(reader, path, topic):
                columns.update(dict.fromkeys(row))
            target = out_dir / (topic.strip("/").replace("/", ".") + ".csv")
            n = 0
            try:
                with open(target, "w", newline="", encoding="utf-8") as f:
                    w = csv.writer(f)
                    w.writerow(columns)
                    for row in _rows(reader, path, topic):
                        w.writerow([_cell(row.get(c)) for c in columns])
                        n += 1
            except OSError as e:
                raise ExportError(f"cannot write {target}: {e.strerror or e}") from None
            result[topic] = {"file": os.fspath(target), "rows": n, "columns": list(columns)}
    return result
