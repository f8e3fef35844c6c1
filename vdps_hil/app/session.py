"""The live recording session of ``vdps log``: :class:`LogSession` and :func:`open_all` (every
adapter opened, or none).

Three stages, so that nothing downstream can make a device lose data:

1. **Readers** (``Adapter.start_reader``): each device is drained by a process of its own
   (serial ports, pseudo-terminals, slcan adapters: ``adapters.fdreader``) or a thread that
   only calls the interface's blocking read (other python-can interfaces: ``adapters.reader``).
   A reader copies what it read into a bounded buffer with the time its read returned, and
   nothing else; a full buffer drops and counts (``reader_overflow``).
2. **Raw first**: the session loop takes what every reader holds and writes the raw records
   (``/raw/can/<bus>``, ``/raw/serial/<device>``) at once.
3. **Decoding after**: the same records are decoded in arrival order in the time left (50 ms per
   loop, then the readers are served again); a record read more than ``decode_lag_s`` ago (or,
   read before the loop began, that long after its start) is not decoded (``decoded_skipped``, its raw record is in the file, the decoder forgets its sequence state so the skip is not taken for data
   lost on the wire). When the disk (or the file-size limit of the process) leaves less than
   ``reserve_bytes``, decoded samples are no longer written (``decoded_skipped_disk``) and the
   rest goes to the raw records. The ``tap`` (``vdps log --pipeline``) is called in a thread of
   its own behind a bounded queue: when it falls behind by ``tap_queue`` samples it loses input
   (``tap_dropped``), never the recording (``vdps log`` passes ``app.tap_process.TapProcess``:
   the estimator itself runs in a process of its own at a lower priority).

Health: ``/health/<source>`` every ``health_s`` and at the end (with the serial driver's own
loss counters where the OS keeps them); the final health of every source also in the metadata
record ``vdps.health`` (``record.recorder``). Crash safety: the MCAP chunk in progress is closed
every ``flush_s`` (0.5 s), so a ``kill -9`` or a power cut loses at most about that much;
``vdps recover`` rescues every complete chunk. A write the file system refuses (disk full) ends
the session with the reason in ``fatal``.
"""

from __future__ import annotations

import os
import resource
import threading
import time
from collections import deque
from typing import Callable, Sequence

from vdps_hil.adapters.base import Adapter, AdapterError
from vdps_hil.record.recorder import Recorder

__all__ = ["LogSession", "open_all", "start_readers", "room_bytes", "DEFAULT_RESERVE_BYTES"]

DECODE_SLICE = 64
"""Payloads decoded between two looks at the clock (a slow decoder yields to raw writing)."""

DEFAULT_RESERVE_BYTES = 64 << 20
"""Room kept for raw records once the disk is nearly full (minutes of every device here)."""


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


def start_readers(adapters: Sequence[Adapter], max_buffer_bytes: int | None = None) -> None:
    """Start the reader of every adapter that has none yet (opening it if closed), as soon as
    the devices are open: a device's own buffer holds well under a second at high rates."""
    for a in adapters:
        if a.reader is None:
            a.start_reader(max_buffer_bytes)


def room_bytes(path: str | None) -> int | None:
    """Bytes the recording at ``path`` may still grow: the free space of its file system for
    this user, and no more than the process's file-size limit (``RLIMIT_FSIZE``) allows the
    file; None when unknown."""
    if not path:
        return None
    try:
        st = os.statvfs(os.path.dirname(os.path.abspath(path)) or ".")
    except OSError:
        return None
    room = st.f_bavail * st.f_frsize
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        try:
            size = os.path.getsize(path)
        except OSError:
            size = 0
        room = min(room, soft - size)
    return room


class _TapWorker:
    """The tap in a thread of its own, fed through a bounded queue of sample batches."""

    def __init__(self, tap, max_samples: int, errors: list):
        self.tap, self.max_samples, self.errors = tap, int(max_samples), errors
        self._q: deque = deque()
        self.waiting = 0
        self.dropped = 0
        self.failed = False
        self._wake = threading.Event()
        self._closed = False
        self._thread = threading.Thread(target=self._loop, name="tap", daemon=True)
        self._thread.start()

    def feed(self, samples: list) -> None:
        if self.failed or not samples:
            return
        if self.waiting + len(samples) > self.max_samples:
            self.dropped += len(samples)
            lost = getattr(self.tap, "input_lost", None)
            if lost is not None:
                lost(len(samples))
            return
        self.waiting += len(samples)
        self._q.append(samples)
        self._wake.set()

    def _loop(self) -> None:
        while True:
            if not self._q:
                if self._closed:
                    return
                self._wake.wait(0.1)
                self._wake.clear()
                continue
            batch = self._q.popleft()
            try:
                self.tap(batch)
            except Exception as e:  # noqa: BLE001 - the recording goes on whatever the tap does
                self.errors.append(f"tap: {type(e).__name__}: {e}")
                self.failed = True
                self._q.clear()
                self.waiting = 0
                return
            self.waiting -= len(batch)

    def close(self, timeout_s: float) -> None:
        """Let the tap finish what is queued while it gets on (``timeout_s`` without a batch
        done: the rest is dropped). A tap at a lower priority catches up slowly on a loaded
        machine, and the recording is complete meanwhile."""
        self._closed = True
        self._wake.set()
        wind_down = getattr(self.tap, "wind_down", None)  # a tap that bounds its own end
        if wind_down is not None:
            wind_down()
        seen, t_seen = self.waiting, time.monotonic()
        while self._thread.is_alive() and time.monotonic() - t_seen < timeout_s:
            self._thread.join(min(1.0, timeout_s))
            if self.waiting != seen:
                seen, t_seen = self.waiting, time.monotonic()
        if self._thread.is_alive():
            self.failed = True  # stop feeding a tap still busy: its input is lost, counted
            self.dropped += self.waiting
            self.errors.append(f"tap: still {self.waiting} samples behind after {timeout_s:g} s; "
                               "left out")


class LogSession:
    """Record live adapters until stopped (stages: module docstring).

    ``adapters`` are opened by :meth:`open` (a person's mistake -> AdapterError naming the
    device, every adapter opened so far closed again). :meth:`run` starts the readers and
    records in the calling thread until ``stop`` is set or ``duration_s`` passed; ``status`` (if
    given) receives the one-line status of every source every ``status_s``.
    """

    def __init__(self, adapters: Sequence[Adapter], writer, *, flush_s: float = 0.5,
                 health_s: float = 1.0, status_s: float = 1.0,
                 status: Callable[[list[str]], None] | None = None, poll_s: float = 0.01,
                 tap: Callable[[list], None] | None = None, decode_lag_s: float = 2.0,
                 reserve_bytes: int = DEFAULT_RESERVE_BYTES, tap_queue: int = 300_000,
                 tap_drain_s: float = 60.0, reader_buffer_bytes: int | None = None):
        names = [a.name for a in adapters]
        if len(set(names)) != len(names):
            raise AdapterError(f"two sources share a name: {names}")
        self.adapters = list(adapters)
        self.writer = writer
        self.recorder = Recorder(writer)
        self.flush_s, self.health_s, self.status_s = flush_s, health_s, status_s
        self.status = status
        self.poll_s = poll_s
        self.tap = tap  # called (in its own thread) with the samples the recording took
        self.decode_lag_s = float(decode_lag_s)
        self.reserve_bytes = int(reserve_bytes)
        self.tap_queue, self.tap_drain_s = tap_queue, tap_drain_s
        self.reader_buffer_bytes = reader_buffer_bytes
        self.errors: list[str] = []
        self.fatal: str | None = None
        self.decoded_ok = True  # False once the disk reserve is reached
        self._backlog: deque = deque()  # (adapter, stamped payloads, index of the next to decode)
        self._tap_worker: _TapWorker | None = None
        self.raw_written = 0
        self.decode_backlog_max = 0
        self._t_run_ns = 0  # monotonic time :meth:`run` began

    def open(self) -> None:
        open_all(self.adapters)

    def status_lines(self) -> list[str]:
        lines = [a.status_line() for a in self.adapters]
        if self.tap is not None and hasattr(self.tap, "status_line"):
            w = self._tap_worker
            extra = "" if w is None or not (w.waiting or w.dropped) else \
                f" [{w.waiting} samples queued, {w.dropped} dropped]"
            lines.append(self.tap.status_line() + extra)
        if not self.decoded_ok:
            lines.append("disk: reserve reached, decoded topics stopped, raw topics go on")
        return lines

    # -- the stages ----------------------------------------------------------------------------

    def _write_raw(self, a: Adapter, stamped: list) -> None:
        write = self.recorder.write
        bad = 0
        for ev in a.raw_events(stamped):
            if not write(ev):
                bad += 1
        self.raw_written += len(stamped) - bad
        if bad:
            a.health.count("raw_write_errors", bad)

    def _take_raw(self, final: bool = False) -> int:
        """Stage 2 for every adapter; returns the number of payloads taken."""
        n = 0
        for a in self.adapters:
            stamped = a.stop_reader() if final else a.collect()
            if stamped:
                self._write_raw(a, stamped)
                self._backlog.append((a, stamped, 0))
                n += len(stamped)
        self.decode_backlog_max = max(self.decode_backlog_max, len(self._backlog))
        return n

    def _decode(self, budget_s: float) -> None:
        """Stage 3 for up to ``budget_s`` of time, in slices of ``DECODE_SLICE`` payloads;
        payloads whose read time is more than ``decode_lag_s`` ago are not decoded -- counted
        from the start of :meth:`run` for what the readers took before it (the logger's own
        start-up, tens of seconds on a loaded machine, is not the decoder falling behind)."""
        t_end = time.monotonic() + budget_s
        backlog = self._backlog
        lag_ns = int(self.decode_lag_s * 1e9)
        while backlog:
            a, stamped, i = backlog[0]
            j, n = i, len(stamped)
            old = time.monotonic_ns() - lag_ns
            if not a.clock.replay and old > self._t_run_ns:
                while j < n and stamped[j][0] < old:
                    j += 1
                if j > i:
                    a.skip_decoding(stamped[i:j])
            k = min(n, j + DECODE_SLICE)
            samples = a.decode_stamped(stamped[j:k])
            if samples:
                self._write_samples(a, samples)
            if k >= n:
                backlog.popleft()
            else:
                backlog[0] = (a, stamped, k)
            if time.monotonic() >= t_end:
                break

    def _write_samples(self, a: Adapter, samples: list) -> None:
        if not self.decoded_ok:
            a.health.count("decoded_skipped_disk", len(samples))
            return
        write = self.recorder.write
        kept = [s for s in samples if write(s)]
        if len(kept) != len(samples):
            a.health.count("decoded_write_errors", len(samples) - len(kept))
        if self._tap_worker is not None and kept:
            self._tap_worker.feed(kept)

    def _check_room(self) -> None:
        room = room_bytes(getattr(self.writer, "path", None))
        ok = room is None or room >= self.reserve_bytes
        if ok != self.decoded_ok:
            self.decoded_ok = ok
            if not ok:
                self.errors.append(f"disk: {room} bytes left (< reserve {self.reserve_bytes}): "
                                   "decoded topics stopped")

    def _wait(self, until: float) -> None:
        """Sleep to the next tick (one loop per ``poll_s``, not one per read: the readers
        buffer, and a loop per read costs more CPU than the reading)."""
        dt = until - time.monotonic()
        if dt > 0:
            time.sleep(dt)

    def _periodic(self, now: float, due: dict) -> None:
        if now >= due["flush"]:
            self.writer.flush()
            due["flush"] = now + self.flush_s
        if now >= due["health"]:
            for a in self.adapters:
                a.check_os_counters()
            self._check_room()
            self.recorder.write_health(self.adapters)
            due["health"] = now + self.health_s
        if self.status is not None and now >= due["status"]:
            self.status(self.status_lines())
            due["status"] = now + self.status_s

    # -- the loop ------------------------------------------------------------------------------

    def run(self, stop: threading.Event, duration_s: float | None = None) -> dict:
        """Record until ``stop`` is set or ``duration_s`` elapsed; returns a summary dict."""
        start_readers(self.adapters, self.reader_buffer_bytes)
        if self.tap is not None:
            self._tap_worker = _TapWorker(self.tap, self.tap_queue, self.errors)
        t_start = time.monotonic()
        self._t_run_ns = time.monotonic_ns()
        due = {"flush": t_start, "health": t_start, "status": t_start}
        self._check_room()  # before the first decoded write, not at the first health tick
        try:
            while not stop.is_set():
                now = time.monotonic()
                if duration_s is not None and now - t_start >= duration_s:
                    break
                n = self._take_raw()
                self._decode(0.05)
                self._periodic(time.monotonic(), due)
                if not n and not self._backlog and \
                        all(a.reader is not None and not a.reader.alive for a in self.adapters):
                    break  # every input ended
                if not self._backlog:  # the readers hold what comes meanwhile
                    self._wait(now + self.poll_s)
        except OSError as e:  # the file system refused a write (disk full ...)
            self.fatal = f"recording stopped: {e.strerror or e}"
            self.errors.append(self.fatal)
        finally:
            self._finish()
        return self._summary(t_start)

    def _finish(self) -> None:
        try:
            if self.fatal is None:
                self._take_raw(final=True)
                self._decode(10.0)
            else:
                for a in self.adapters:
                    a.stop_reader()
            for a, stamped, i in self._backlog:
                a.skip_decoding(stamped[i:])
            self._backlog.clear()
            if self._tap_worker is not None:
                self._tap_worker.close(self.tap_drain_s)
                if self._tap_worker.failed:
                    self.tap = None
            for a in self.adapters:
                a.close()
            self.recorder.write_health(self.adapters)
            self.recorder.write_final_health(self.adapters, self._recorder_extra())
        except OSError as e:
            self.fatal = self.fatal or f"recording stopped: {e.strerror or e}"
            self.errors.append(f"final health not written: {e.strerror or e}")

    def _recorder_extra(self) -> dict:
        w = self._tap_worker
        return {"reader_errors": self.errors, "decode_backlog_max": self.decode_backlog_max,
                "decoded_topics_stopped_for_disk": not self.decoded_ok,
                "tap_dropped": 0 if w is None else w.dropped}

    def _summary(self, t_start: float) -> dict:
        w = self._tap_worker
        return {"duration_s": time.monotonic() - t_start, "written": self.recorder.written,
                "write_errors": self.recorder.write_errors, "raw_records": self.raw_written,
                "queue_overflow": sum(a.health.counters.get("reader_overflow", 0)
                                      for a in self.adapters),
                "loss": {a.name: a.health.loss() for a in self.adapters},
                "tap_dropped": 0 if w is None else w.dropped, "fatal": self.fatal,
                "sources": {a.name: a.status() for a in self.adapters},
                "reader_errors": list(self.errors)}
