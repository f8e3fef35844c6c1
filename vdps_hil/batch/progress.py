"""Progress of a batch: counts, a bar and an ETA on one terminal line (or one log line per
finished task when the output is not a terminal, e.g. a cluster job's log file).

ETA. Tasks reused from a previous run (resume) cost nothing; the others are assumed to take
as long on average as the ones finished so far, and to run ``W`` at a time::

    rate  = n_done / (t_now - t_first_submit)         [tasks/s]   (over computed tasks only)
    ETA   = (n_todo - n_done) / rate                  [s]

This is the observed throughput, so it includes the parallelism, the cluster start-up and the
mix of long and short drives seen so far (long drives are submitted first, see ``engine``, so
the estimate tends to be pessimistic early and converges as the batch runs).
"""

from __future__ import annotations

import sys
import time
from typing import IO

__all__ = ["Progress", "format_duration"]


def format_duration(s: float | None) -> str:
    """``h:mm:ss`` or ``m:ss``; ``--:--`` when unknown."""
    if s is None or s != s or s < 0 or s == float("inf"):
        return "--:--"
    s = int(round(s))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"


class Progress:
    """Counts and ETA of a running batch (module docstring).

    ``start(total, reused)``, ``engine(info)``, ``update(outcome)`` per finished task,
    ``close()``. ``stream`` (default stderr); ``live`` (redraw one line; default: the stream
    is a terminal); ``enabled=False`` prints nothing but still counts. ``label`` prefixes
    every line. ``clock`` is injectable for tests.
    """

    def __init__(self, label: str = "vdps batch", *, stream: IO[str] | None = None,
                 live: bool | None = None, enabled: bool = True, width: int = 24, clock=time.monotonic):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        isatty = getattr(self.stream, "isatty", lambda: False)
        self.live = bool(isatty()) if live is None else live
        self.enabled = enabled
        self.width = width
        self.clock = clock
        self.total = self.reused = self.ok = self.failed = 0
        self.t0 = None
        self._drawn = False

    # -- counts
    @property
    def done(self) -> int:
        """Finished tasks, reused ones included."""
        return self.reused + self.ok + self.failed

    @property
    def computed(self) -> int:
        return self.ok + self.failed

    def eta_s(self) -> float | None:
        todo = self.total - self.reused
        if self.computed == 0 or self.t0 is None:
            return None if todo > 0 else 0.0
        elapsed = self.clock() - self.t0
        if elapsed <= 0:
            return None
        return (todo - self.computed) * elapsed / self.computed

    def line(self) -> str:
        frac = self.done / self.total if self.total else 1.0
        filled = int(round(frac * self.width))
        bar = "#" * filled + "-" * (self.width - filled)
        elapsed = 0.0 if self.t0 is None else self.clock() - self.t0
        parts = [f"{self.label} [{bar}] {self.done}/{self.total}", f"ok {self.ok}",
                 f"failed {self.failed}"]
        if self.reused:
            parts.append(f"reused {self.reused}")
        return ", ".join(parts) + f" | {format_duration(elapsed)} elapsed, ETA {format_duration(self.eta_s())}"

    # -- events
    def start(self, total: int, reused: int = 0) -> None:
        self.total, self.reused = int(total), int(reused)
        self.t0 = self.clock()
        if self.reused:
            self._say(f"{self.label}: {self.reused} of {self.total} results reused (unchanged key)")
        self._draw()

    def engine(self, info: dict) -> None:
        where = info.get("scheduler") or info.get("backend")
        text = f"{self.label}: {info.get('backend')} with {info.get('workers')} worker(s)"
        if info.get("backend") == "dask":
            text += f" at {where}"
            if info.get("dashboard"):
                text += f", dashboard {info['dashboard']}"
            text += f", allowed-failures {info.get('allowed_failures')}"
        self._say(text)
        for w in info.get("warnings") or []:
            self._say(f"{self.label}: warning: {w}")

    def update(self, outcome) -> None:
        if outcome.ok:
            self.ok += 1
        else:
            self.failed += 1
            err = outcome.error or {}
            self._say(f"{self.label}: FAILED {outcome.id}: {err.get('type', '')}: {err.get('message', '')}")
        if not self.live:
            self._say(f"{self.line()}  <- {outcome.id} {outcome.status}")
        else:
            self._draw()

    def close(self) -> None:
        if self.enabled and self.live and self._drawn:
            self._draw()
            self.stream.write("\n")
            self.stream.flush()
            self._drawn = False

    # -- output
    def _say(self, text: str) -> None:
        if not self.enabled:
            return
        if self.live and self._drawn:
            self.stream.write("\r\x1b[2K")
            self._drawn = False
        self.stream.write(text + "\n")
        self.stream.flush()
        if self.live:
            self._draw()

    def _draw(self) -> None:
        if not (self.enabled and self.live):
            return
        self.stream.write("\r\x1b[2K" + self.line())
        self.stream.flush()
        self._drawn = True
