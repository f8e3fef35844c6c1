"""The live recording session of ``vdps log`` and the bench: :class:`LogSession` (one reader
thread per device, one writer loop writing through a :class:`~vdps_hil.record.recorder.Recorder`)
and :func:`open_all` (every adapter opened, or none).

Health: ``/health/<source>`` every ``health_s`` and at the end; the final health of every
source also in the metadata record ``vdps.health`` (``record.recorder``).

Crash safety: the writer loop closes the MCAP chunk in progress every ``flush_s`` (0.5 s by
default), so a ``kill -9`` or a power cut loses at most the last ``flush_s`` plus the time to
write one chunk; ``vdps recover`` rescues every complete chunk.

Loss accounting: a reader never blocks on the writer; if the writer falls behind by more than
``queue_size`` events, new events are dropped and counted (``queue_overflow`` per source).
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Sequence

from vdps_hil.adapters.base import Adapter, AdapterError
from vdps_hil.bus.subscription import Subscription
from vdps_hil.record.recorder import Recorder

__all__ = ["LogSession", "open_all"]


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
