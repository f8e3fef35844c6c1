"""Progress of long commands on a terminal: one bar with a percentage, elapsed time and an ETA
(tqdm), and nothing at all when standard error is not a terminal or with ``--quiet``.

:class:`ProgressBar` is the one door for every long command (``vdps replay``, ``diagnose``,
``sim``, ``paper``, ``import``, ``batch``): ``ProgressBar(total, desc, unit=...)``, then
``update_to(position)`` (absolute, e.g. seconds of the recording done) or ``advance(n)``,
``note(text)`` for a line above the bar (a stage starts), ``close()`` (also as a context
manager). The work itself never imports this module: it takes a callback (``progress(done,
total)`` or ``progress(text)``) that the command line connects to a bar (``callback``,
``stage_callback``), so the library layers stay free of terminal code.

The ETA is tqdm's: the remaining amount at the rate observed so far (smoothed), so a command
whose pace is uneven (a diagnosis's stages, a batch's long drives first) shows a rough figure
early that improves as it runs.

:class:`Progress` is the batch's task counter on top of a bar: counts of finished, failed and
reused tasks, the engine line, and failures as lines above the bar; off a terminal only those
lines (no per-task progress lines).
"""

from __future__ import annotations

import os
import sys
import time
from typing import IO, Callable

__all__ = ["Progress", "ProgressBar", "format_duration", "is_live"]


def format_duration(s: float | None) -> str:
    """``h:mm:ss`` or ``m:ss``; ``--:--`` when unknown."""
    if s is None or s != s or s < 0 or s == float("inf"):
        return "--:--"
    s = int(round(s))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"


def is_live(stream: IO[str] | None = None, quiet: bool = False) -> bool:
    """Whether a bar is drawn: not ``quiet`` and ``stream`` (default stderr) is a terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return not quiet and bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


_FLOAT_BAR = "{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} {unit} [{elapsed}<{remaining}, {rate_fmt}]"
_OPEN_BAR = "{desc}: {n:.1f} {unit} [{elapsed}, {rate_fmt}]"


def _format(total, unit: str) -> str | None:
    """tqdm's bar format: its default for whole counts, one decimal for amounts (seconds of a
    recording), no percentage without a total."""
    if not total:
        return _OPEN_BAR
    return None if float(total).is_integer() and unit != "s" else _FLOAT_BAR


def _size(stream) -> tuple[int, int]:
    """(columns, rows) of the terminal ``stream`` writes to, 0 where it does not say (tqdm
    hides a bar below row 0)."""
    try:
        size = os.get_terminal_size(stream.fileno())
    except (AttributeError, ValueError, OSError):
        return 0, 0
    return size.columns, size.lines


class ProgressBar:
    """A tqdm bar on ``stream`` (default stderr) when it is a terminal and not ``quiet``; else
    every call does nothing (module docstring). ``total`` None: no percentage, only the amount
    done and the rate. ``unit``: what ``total`` counts (``"s"`` of a recording, ``"run"``...)."""

    def __init__(self, total: float | None, desc: str, *, unit: str = "it", quiet: bool = False,
                 stream: IO[str] | None = None, live: bool | None = None):
        self.stream = sys.stderr if stream is None else stream
        self.live = is_live(self.stream, quiet) if live is None else bool(live)
        self.desc = desc
        self._bar = None
        if self.live:
            from tqdm import tqdm

            cols, rows = _size(self.stream)  # a terminal that does not say its size: 80 x 24
            self._bar = tqdm(total=total, desc=desc, unit=unit, file=self.stream, ncols=cols or 80,
                             nrows=rows or 24, mininterval=0.2, leave=True, bar_format=_format(total, unit))

    @property
    def n(self) -> float:
        return 0.0 if self._bar is None else self._bar.n

    def update_to(self, position: float) -> None:
        """Move the bar to ``position`` (never backwards)."""
        bar = self._bar
        if bar is not None and position > bar.n:
            if bar.total is not None:
                position = min(position, bar.total)
            bar.update(position - bar.n)

    def advance(self, n: float = 1) -> None:
        if self._bar is not None:
            self._bar.update(n)

    def note(self, text: str) -> None:
        """A line above the bar (on a terminal only)."""
        if self._bar is not None:
            self._bar.write(text, file=self.stream)

    def close(self, done: bool = True) -> None:
        """End the bar; ``done``: the work finished (the bar shows 100 %), else it stays where it was."""
        if self._bar is not None:
            if done and self._bar.total is not None and self._bar.n < self._bar.total:
                self._bar.update(self._bar.total - self._bar.n)  # the work is done: 100 %
            self._bar.close()
            self._bar = None

    def callback(self) -> Callable[[float, float], None]:
        """``progress(done, total)`` for the work's own loop; a new ``total`` starts the bar
        again (the next phase of the work)."""
        def progress(done: float, total: float | None = None) -> None:
            bar = self._bar
            if total is not None and bar is not None and bar.total != total:
                bar.reset(total=total)
                bar.bar_format = _format(total, bar.unit)
            self.update_to(done)
        return progress

    def stage_callback(self) -> Callable[[str], None]:
        """``progress(text)`` for work that reports stages by name: each a step of the bar,
        its name shown after the bar."""
        def stage(text: str) -> None:
            if self._bar is not None:
                if self._bar.n or getattr(self, "_staged", False):
                    self.advance(1)
                self._staged = True
                self._bar.set_postfix_str(text)
        return stage

    def __enter__(self) -> "ProgressBar":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        self.close(done=exc_type is None)


class Progress:
    """Counts and the bar of a running batch (module docstring).

    ``start(total, reused)``, ``engine(info)``, ``update(outcome)`` per finished task,
    ``close()``. ``stream`` (default stderr); ``live`` (draw the bar; default: the stream is a
    terminal); ``enabled=False`` prints nothing but still counts. ``label`` prefixes every line.
    ``clock`` is injectable for tests (the counts' ETA, :meth:`eta_s`).
    """

    def __init__(self, label: str = "vdps batch", *, stream: IO[str] | None = None,
                 live: bool | None = None, enabled: bool = True, clock=time.monotonic):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.live = is_live(self.stream) if live is None else live
        self.enabled = enabled
        self.clock = clock
        self.total = self.reused = self.ok = self.failed = 0
        self.t0 = None
        self._bar: ProgressBar | None = None

    @property
    def done(self) -> int:
        """Finished tasks, reused ones included."""
        return self.reused + self.ok + self.failed

    @property
    def computed(self) -> int:
        return self.ok + self.failed

    def eta_s(self) -> float | None:
        """Remaining tasks at the throughput observed over the computed ones (reused ones cost
        nothing)."""
        todo = self.total - self.reused
        if self.computed == 0 or self.t0 is None:
            return None if todo > 0 else 0.0
        elapsed = self.clock() - self.t0
        if elapsed <= 0:
            return None
        return (todo - self.computed) * elapsed / self.computed

    def line(self) -> str:
        parts = [f"{self.label}: {self.done}/{self.total}", f"ok {self.ok}", f"failed {self.failed}"]
        if self.reused:
            parts.append(f"reused {self.reused}")
        return ", ".join(parts) + f", ETA {format_duration(self.eta_s())}"

    def start(self, total: int, reused: int = 0) -> None:
        self.total, self.reused = int(total), int(reused)
        self.t0 = self.clock()
        if self.enabled and self.live:
            self._bar = ProgressBar(self.total, self.label, unit="task", stream=self.stream, live=True)
            self._bar.advance(self.reused)
        if self.reused:
            self._say(f"{self.label}: {self.reused} of {self.total} results reused (unchanged key)")

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
        if self._bar is not None:
            self._bar.advance(1)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def _say(self, text: str) -> None:
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.note(text)
        else:
            self.stream.write(text + "\n")
            self.stream.flush()
