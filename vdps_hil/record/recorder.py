"""Recording adapter events into MCAP: the :class:`Recorder` turns events into
:class:`~vdps_hil.record.writer.RecordingWriter` calls (``vdps log``'s session, ``vdps import``,
the bench).

Events go to the recording as

====================  ==================================================================
event                 topic
====================  ==================================================================
``RawCan``            ``/raw/can/<bus>`` (every frame, rx and tx, always)
``RawSerial``         ``/raw/serial/<device>`` (every read chunk, always)
``Sample``            ``/decoded/<source>/<kind>``; ``gnss_pos`` samples also as
                      ``foxglove.LocationFix`` on ``/gnss/fix`` (Foxglove's map)
health                ``/health/<source>`` (``vdps.Health.v1``, ``write_health``): counters,
                      learned rates, drops, outages
====================  ==================================================================

and the final health of every source also goes into the metadata record ``vdps.health``
(source -> JSON), so ``vdps info`` reads it without scanning the file.
"""

from __future__ import annotations

import json
from typing import Iterable, Sequence

from vdps_hil.adapters.base import Adapter
from vdps_hil.bus.raw import RawCan, RawSerial
from vdps_hil.bus.samples import Sample
from vdps_hil.record import schemas as S

__all__ = ["Recorder", "HEALTH_SCHEMA", "HEALTH_PREFIX", "HEALTH_METADATA"]

HEALTH_SCHEMA = "vdps.Health.v1"
HEALTH_PREFIX = "/health/"
HEALTH_METADATA = "vdps.health"

S.register_schema(HEALTH_SCHEMA, {
    "title": HEALTH_SCHEMA,
    "description": "Health of one source (adapter): counters, learned rates per sample kind, "
                   "drops and outages, as seen at t_ns.",
    "type": "object",
    "properties": {
        "t_ns": {"type": "integer", "minimum": 0},
        "source": {"type": "string"},
        "transport": {"type": "string"},
        "device": {"type": "string"},
        "state": {"type": "string"},
        "records": {"type": "integer"},
        "bytes": {"type": "integer"},
        "samples": {"type": "integer"},
        "drops": {"type": "integer"},
        "outage_s": {"type": "number"},
        "last_error": {"type": "string"},
        "counters": {"type": "object"},
        "kinds": {"type": "object"},
    },
    "required": ["t_ns", "source", "counters"],
})


def _bus_of(source: str) -> str:
    return source[4:] if source.startswith("can.") else source


class Recorder:
    """Turn adapter events into :class:`~vdps_hil.record.writer.RecordingWriter` calls.

    Never raises on an event: a write the writer refuses (a frame it cannot represent, a time
    out of range) is counted in ``write_errors`` with the first reasons kept in ``problems``.
    """

    def __init__(self, writer, *, location_fix: bool = True):
        self.writer = writer
        self.location_fix = location_fix
        self.written = 0
        self.write_errors = 0
        self.problems: list[str] = []

    def _fail(self, what: str, e: BaseException) -> None:
        self.write_errors += 1
        if len(self.problems) < 20:
            first = str(e).splitlines()[0] if str(e) else ""
            self.problems.append(f"{what}: {type(e).__name__}: {first}")

    def write(self, ev) -> bool:
        """Write one event; True when it is in the recording (for a sample: its ``/decoded/``
        record, even if its ``/gnss/fix`` copy was refused)."""
        w = self.writer
        try:
            if isinstance(ev, RawCan):
                w.write_can(_bus_of(ev.source), ev.t_ns, ev.msg, ev.direction,
                            ev.wall_time_ns or None)
            elif isinstance(ev, RawSerial):
                w.write_serial(ev.source, ev.t_ns, ev.data, ev.wall_time_ns or None, ev.baud,
                               ev.fmt)
            elif isinstance(ev, Sample):
                w.write_sample(ev)
                if self.location_fix and ev.kind == "gnss_pos":
                    try:
                        w.write_location_fix(ev)
                    except (ValueError, TypeError, KeyError, OverflowError) as e:
                        self._fail(ev.source, e)  # counted; the sample itself is written
            else:
                raise TypeError(f"not an adapter event: {type(ev).__name__}")
        except (ValueError, TypeError, KeyError, OverflowError) as e:
            self._fail(getattr(ev, "source", "?"), e)
            return False
        self.written += 1
        return True

    def write_many(self, events: Iterable) -> None:
        for ev in events:
            self.write(ev)

    def write_health(self, adapters: Sequence[Adapter], t_ns: int | None = None) -> None:
        """One ``/health/<source>`` message per adapter at ``t_ns`` (default: its clock)."""
        for a in adapters:
            snap = a.status()
            t = t_ns if t_ns is not None else max(0, a.clock.now()[0])
            wall = a.clock.wall(t) if t_ns is None else None
            snap["t_ns"] = t
            try:
                self.writer.write_json(HEALTH_PREFIX + a.name, HEALTH_SCHEMA, t, snap,
                                       wall_time_ns=wall or None)
            except (ValueError, TypeError) as e:
                self._fail(a.name, e)

    def write_final_health(self, adapters: Sequence[Adapter], extra: dict | None = None) -> None:
        """The metadata record ``vdps.health``: source -> final health JSON."""
        md = {a.name: json.dumps(S.clean_json(a.status()), sort_keys=True) for a in adapters}
        md["recorder"] = json.dumps({"written": self.written, "write_errors": self.write_errors,
                                     "problems": self.problems, **(extra or {})},
                                    sort_keys=True)
        try:
            self.writer.add_metadata(HEALTH_METADATA, md)
        except ValueError as e:
            self._fail("metadata", e)
