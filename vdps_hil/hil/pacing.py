"""Pacing the steppable simulator to the wall clock: the bench's time axis, absolute deadlines
and the count of late sends.

Time axis (one for the whole bench)
-----------------------------------
Everything on the bench -- the simulator, the sensor frames, the pipeline's adapters, the
warning frames, the ECU -- uses one time axis, the simulated time ``t`` [ns], tied to the host's
monotonic clock ``m`` [ns] (``time.monotonic_ns``: CLOCK_MONOTONIC, shared by every process of
the host) by the speed ``X`` (``--speed``) and the start instant ``m0``::

    t(m) = X (m - m0)                   (the bench clock, :class:`BenchClock`)
    d(t) = m0 + t / X                   (deadline of an item of simulated time t)

so a live adapter stamping "now" writes times on the simulator's axis (its recording lines up
with ``/truth``) and the pipeline, which takes time only from the samples, sees simulated time
at any speed. Wall-clock UTC in recordings is ``DEFAULT_SIM_EPOCH_NS + t`` (as a simulated
recording). Latencies are reported in wall milliseconds: ``(t_b - t_a) / X``.

Drift correction
----------------
Every item (a CAN frame, a serial read chunk) is sent when ``m >= d(t_item)``, with ``d``
computed from ``m0`` for each item: sleeps never accumulate, so the error of one sleep
(typically 50-100 us on Linux, several ms when another thread holds the GIL) delays the items
due during it and nothing after them. Items due while the sender was busy go out at once, in
time order.

Late sends
----------
``lateness = m_sent - d(t_item)`` [wall ns]. A send is *late* when its lateness exceeds
``late_tolerance_s`` (default 2 ms: two periods of the fastest stream, the 1 kHz wheel speeds
and IMU; a receiver then sees two samples at once, which its time stamps already allow for). The
pacer counts sends, late sends and keeps the lateness distribution (p50, p99, max).

Symbols: t simulated time [ns]; m monotonic host time [ns]; X speed (simulated s per wall s);
d deadline [ns, monotonic].
"""

from __future__ import annotations

import math
import threading
import time
from typing import Callable

import numpy as np

from vdps_hil.record.schemas import DEFAULT_SIM_EPOCH_NS
from vdps_hil.units import NS_PER_S

__all__ = ["BenchClock", "Pacer", "DEFAULT_LATE_TOLERANCE_S", "percentiles_ms"]

DEFAULT_LATE_TOLERANCE_S = 0.002
"""A send more than this after its deadline [wall s] is counted late (module docstring)."""


def percentiles_ms(values_ns, qs=(50, 99)) -> dict[str, float]:
    """``{"p50": .., "p99": .., "max": .., "n": ..}`` of durations given in ns, in ms (NaN for
    no values)."""
    a = np.asarray(values_ns, dtype=float)
    out: dict[str, float] = {f"p{q}": (float(np.percentile(a, q)) / 1e6 if a.size else math.nan) for q in qs}
    out["max"] = float(a.max()) / 1e6 if a.size else math.nan
    out["n"] = int(a.size)
    return out


class BenchClock:
    """The bench's time axis (module docstring), usable as an adapter clock (``now()``,
    ``wall(t_ns)``, ``replay = False``).

    ``speed``: simulated seconds per wall second (> 0). ``start(m0_ns)`` fixes the start instant
    (default: now); before ``start`` the clock reads 0. ``mono0_ns`` may be given to share one
    axis between processes (CLOCK_MONOTONIC is system-wide)."""

    replay = False

    def __init__(self, speed: float = 1.0, mono0_ns: int | None = None, epoch_ns: int = DEFAULT_SIM_EPOCH_NS,
                 monotonic_ns: Callable[[], int] = time.monotonic_ns):
        self.monotonic_ns = monotonic_ns
        speed = float(speed)
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be a positive number, got {speed!r}")
        self.speed = speed
        self.epoch_ns = int(epoch_ns)
        self.mono0_ns: int | None = None if mono0_ns is None else int(mono0_ns)

    def start(self, mono0_ns: int | None = None) -> int:
        self.mono0_ns = self.monotonic_ns() if mono0_ns is None else int(mono0_ns)
        return self.mono0_ns

    @property
    def started(self) -> bool:
        return self.mono0_ns is not None

    def t_of(self, mono_ns: int) -> int:
        """Simulated time [ns] of a monotonic instant."""
        if self.mono0_ns is None:
            return 0
        if self.speed == 1.0:  # the same integer, without the float round trip (per sample)
            return mono_ns - self.mono0_ns
        return int(round((mono_ns - self.mono0_ns) * self.speed))

    def deadline(self, t_ns: int) -> int:
        """Monotonic instant [ns] at which simulated time ``t_ns`` is due."""
        return self.mono0_ns + int(round(t_ns / self.speed))

    def now_ns(self) -> int:
        return self.t_of(self.monotonic_ns())

    def now(self) -> tuple[int, int]:
        t = self.now_ns()
        return t, self.epoch_ns + t

    def wall(self, t_ns: int) -> int:
        return self.epoch_ns + t_ns

    def wall_ms(self, dt_ns: float) -> float:
        """A simulated-time duration [ns] as wall milliseconds."""
        return dt_ns / self.speed / 1e6


class Pacer:
    """Absolute-deadline waits and late-send accounting (module docstring).

    ``wait_until(t_ns, max_wait_s)`` sleeps until simulated time ``t_ns`` is due (or
    ``max_wait_s`` wall seconds passed) and returns True when it is due. ``sent(t_items_ns,
    m_sent_ns)`` accounts items sent at monotonic ``m_sent_ns``; ``stats()`` summarises.
    ``sleep`` and the clock's ``monotonic_ns`` can be replaced (tests)."""

    def __init__(self, clock: BenchClock, late_tolerance_s: float = DEFAULT_LATE_TOLERANCE_S,
                 keep: int = 200_000, sleep: Callable[[float], None] = time.sleep):
        self.clock = clock
        self.sleep = sleep
        self.late_tolerance_ns = int(round(late_tolerance_s * NS_PER_S))
        self._sends = 0
        self._late_sends = 0
        self._max_late_ns = 0
        self._pending: list = []  # (m_sent_ns, t_items_ns) not yet folded into the counts
        self._pending_n = 0
        self._lock = threading.Lock()
        self._keep = int(keep)
        self._lateness: list[np.ndarray] = []
        self._kept = 0

    def wait_until(self, t_ns: int, max_wait_s: float = 0.005) -> bool:
        d = self.clock.deadline(t_ns)
        mono = self.clock.monotonic_ns
        now = mono()
        if now >= d:
            return True
        self.sleep(min((d - now) / NS_PER_S, max_wait_s))
        return mono() >= d

    def sent(self, t_items_ns, m_sent_ns: int) -> None:
        """Account items sent at ``m_sent_ns``; folded into the counts in batches (``_fold``): the
        numpy of one send pass cost more than the pass's own work."""
        if not len(t_items_ns):
            return
        with self._lock:
            self._pending.append((m_sent_ns, t_items_ns))
            self._pending_n += len(t_items_ns)
            full = self._pending_n >= 512
        if full:
            self._fold()

    def _fold(self) -> None:
        """Fold the pending sends into the counts (the sending thread, or a reader's: locked)."""
        with self._lock:
            pending, self._pending, self._pending_n = self._pending, [], 0
            if not pending:
                return
            m = np.concatenate([np.full(len(t), m_s, np.int64) for m_s, t in pending])
            t = np.concatenate([np.asarray(t, dtype=np.int64) for _, t in pending])
            self._fold_arrays(m, t)

    def _fold_arrays(self, m: np.ndarray, t: np.ndarray) -> None:
        c = self.clock
        late = m - (c.mono0_ns + np.rint(t / c.speed).astype(np.int64))
        self._sends += int(t.size)
        self._late_sends += int(np.count_nonzero(late > self.late_tolerance_ns))
        mx = int(late.max())
        if mx > self._max_late_ns:
            self._max_late_ns = mx
        if self._kept < self._keep:
            self._lateness.append(np.maximum(late, 0))
            self._kept += int(t.size)

    @property
    def sends(self) -> int:
        self._fold()
        return self._sends

    @property
    def late_sends(self) -> int:
        self._fold()
        return self._late_sends

    @property
    def max_late_ns(self) -> int:
        self._fold()
        return self._max_late_ns

    def stats(self) -> dict:
        self._fold()
        lat = np.concatenate(self._lateness) if self._lateness else np.zeros(0)
        p = percentiles_ms(lat)
        return {"sends": self.sends, "late_sends": self.late_sends,
                "late_tolerance_ms": self.late_tolerance_ns / 1e6,
                "lateness_ms": {"p50": p["p50"], "p99": p["p99"], "max": self.max_late_ns / 1e6}}
