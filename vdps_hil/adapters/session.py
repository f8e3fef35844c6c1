"""Recording adapter events into MCAP: the :class:`Recorder` (events -> writer calls) and the
live :class:`LogSession` (one reader thread per device, one writer loop).

Events go to the recording as

====================  ==================================================================
event                 topic
====================  ==================================================================
``RawCan``            ``/raw/can/<bus>`` (every frame, rx and tx, always)
``RawSerial``         ``/raw/serial/<device>`` (every read chunk, always)
``Sample``            ``/decoded/<source>/<kind>``; ``gnss_pos`` samples also as
                      ``foxglove.LocationFix`` on ``/gnss/fix`` (Foxglove's map)
health                ``/health/<source>`` (``vdps.Health.v1``) every ``health_s`` and at
                      the end: counters, learned rates, drops, outages
====================  ==================================================================

and the final health of every source also goes into the metadata record ``vdps.health``
(source -> JSON), so ``vdps info`` reads it without scanning the file.

Crash safety: the writer loop closes the MCAP chunk in progress every ``flush_s`` (0.5 s by
default), so a ``kill -9`` or a power cut loses at most the last ``flush_s`` plus the time to
write one chunk; ``vdps recover`` rescues every complete chunk.

Loss accounting: a reader never blocks on the writer; if the writer falls behind by more than
``queue_size`` events, new events are dropped and counted (``queue_overflow`` per source).
"""

from __future__ import annotations

import json
import threading
import time
from typing import Callable, Iterable, Sequence

from vdps_hil.adapters.base import Adapter, AdapterError, RawCan, RawSerial, Subscription
from vdps_hil.bus.samples import Sample
from vdps_hil.record import schemas as S

__all__ = ["Recorder", "LogSession", "HEALTH_SCHEMA", "HEALTH_PREFIX", "HEALTH_METADATA"]

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


def open_all(adapters: Sequence[Adapter], errors: tuple = (AdapterError,)) -> None:
    """Open every adapter, or none: on one of ``errors`` the ones already open are closed
    again and the error is raised."""
    opened = []
    try:
        for a in adapters:
            a.open()
            opened.append(a)
    except errors:
        for a in opened:
            a.close()
        raise


class LogSession:
    """Record live adapters until stopped.

    ``adapters`` are opened by :meth:`open` (a person's mistake -> AdapterError naming the
    device, every adapter opened so far closed again). :meth:`run` starts one reader thread per
    adapter and writes in the calling thread until ``stop`` is set or ``duration_s`` passed;
    ``status`` (if given) receives the one-line status of every source every ``status_s``.
    """

    def __init__(self, adapters: Sequence[Adapter], writer, *, queue_size: int = 1_000_000,
                 flush_s: float = 0.5, health_s: float = 1.0, status_s: float = 1.0,
                 status: Callable[[list[str]], None] | None = None, poll_s: float = 0.02,
                 tap: Callable[[list], None] | None = None):
        names = [a.name for a in adapters]
        if len(set(names)) != len(names):
            raise AdapterError(f"two sources share a name: {names}")
        self.adapters = list(adapters)
        self.writer = writer
        self.recorder = Recorder(writer)
        self.sub = Subscription("recorder", queue_size)
        for a in self.adapters:
            a.subscribe(self.sub)
        self.flush_s, self.health_s, self.status_s = flush_s, health_s, status_s
        self.status = status
        self.poll_s = poll_s
        self.tap = tap  # called with the events of every drained batch the recording took
        self._threads: list[threading.Thread] = []
        self._adapter_stop = threading.Event()
        self.errors: list[str] = []

    def open(self) -> None:
        open_all(self.adapters)

    def _reader(self, a: Adapter) -> None:
        try:
            a.run(self._adapter_stop, self.poll_s)
        except Exception as e:  # noqa: BLE001 - a reader must not die silently
            self.errors.append(f"{a.name}: {type(e).__name__}: {e}")

    def status_lines(self) -> list[str]:
        lines = [a.status_line() for a in self.adapters]
        if self.tap is not None and hasattr(self.tap, "status_line"):
            lines.append(self.tap.status_line())
        return lines

    def _write(self, events: list) -> None:
        if self.tap is None:
            self.recorder.write_many(events)
            return
        write = self.recorder.write
        events = [ev for ev in events if write(ev)]  # the tap sees what the file holds
        if events:
            try:
                self.tap(events)
            except Exception as e:  # noqa: BLE001 - the recording must go on whatever the tap does
                self.errors.append(f"tap: {type(e).__name__}: {e}")
                self.tap = None

    def run(self, stop: threading.Event, duration_s: float | None = None) -> dict:
        """Record until ``stop`` is set or ``duration_s`` elapsed; returns a summary dict."""
        for a in self.adapters:
            if not a.is_open and a.health.state == "closed":
                a.open()
        t_start = time.monotonic()
        for a in self.adapters:
            th = threading.Thread(target=self._reader, args=(a,), name=f"reader-{a.name}",
                                  daemon=True)
            th.start()
            self._threads.append(th)
        rec = self.recorder
        sub = self.sub
        next_flush = next_health = next_status = time.monotonic()
        try:
            while not stop.is_set():
                now = time.monotonic()
                if duration_s is not None and now - t_start >= duration_s:
                    break
                if sub.wait(0.02):
                    self._write(sub.drain(20_000))
                now = time.monotonic()
                if now >= next_flush:
                    self.writer.flush()
                    next_flush = now + self.flush_s
                if now >= next_health:
                    rec.write_health(self.adapters)
                    next_health = now + self.health_s
                if self.status is not None and now >= next_status:
                    self.status(self.status_lines())
                    next_status = now + self.status_s
                if self._threads and not any(t.is_alive() for t in self._threads):
                    break
        finally:
            self._adapter_stop.set()
            for th in self._threads:
                th.join(timeout=5.0)
            while len(sub):
                self._write(sub.drain(100_000))
            rec.write_health(self.adapters)
            rec.write_final_health(self.adapters, {"reader_errors": self.errors,
                                                   "queue_high_water": sub.high_water})
        return {"duration_s": time.monotonic() - t_start, "written": rec.written,
                "write_errors": rec.write_errors, "queue_overflow": sub.overflows,
                "sources": {a.name: a.status() for a in self.adapters},
                "reader_errors": list(self.errors)}
