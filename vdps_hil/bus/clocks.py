"""Clocks of the bus: ``now() -> (t_ns, wall_time_ns)`` and ``wall(t_ns)``.

``t_ns`` is integer monotonic nanoseconds (orders samples across sources); the wall time is
``wall_time_ns = t_ns + (wall0 - mono0)`` with the offset taken once when the clock starts, so
the two never disagree about order (:class:`SystemClock`). Recorded input brings its own
``t_ns`` (:class:`ReplayClock`: ``wall_time_ns = t_ns``, the file's own clock). ``replay``
says which: a replay clock's ``now()`` is the last data time seen, so timeouts are judged in
data time.
"""

from __future__ import annotations

import time

__all__ = ["ReplayClock", "SystemClock", "wall_minus_monotonic_ns"]


def wall_minus_monotonic_ns(tries: int = 7) -> int:
    """``time.time_ns() - time.monotonic_ns()``, read as a pair with monotonic reads on both
    sides, keeping the pair with the tightest bracket of ``tries``. One plain pair is off by as
    long as the thread was preempted between its two reads: milliseconds on a loaded machine,
    enough to stamp a bench's first frames before its start (two such offsets, the sender's
    and the receiver's, must agree to microseconds)."""
    best = None
    for _ in range(max(1, tries)):
        a = time.monotonic_ns()
        w = time.time_ns()
        b = time.monotonic_ns()
        if best is None or b - a < best[0]:
            best = (b - a, w - (a + b) // 2)
    return best[1]


class SystemClock:
    """Host clock: ``now() -> (t_ns, wall_time_ns)``, ``t_ns`` from ``time.monotonic_ns`` and
    ``wall_time_ns = t_ns + offset`` with the wall-minus-monotonic offset fixed at creation."""

    replay = False

    def __init__(self):
        self.offset_ns = wall_minus_monotonic_ns()

    def now(self) -> tuple[int, int]:
        t = time.monotonic_ns()
        return t, t + self.offset_ns

    def wall(self, t_ns: int) -> int:
        return t_ns + self.offset_ns


class ReplayClock:
    """Recorded input: every record brings its ``t_ns`` (the file's clock) and the wall time is
    the same number (the file's clock is the only one known). ``now()`` returns the last time
    seen so timeouts are judged in data time."""

    replay = True

    def __init__(self):
        self.last_ns = 0

    def now(self) -> tuple[int, int]:
        return self.last_ns, self.last_ns

    def wall(self, t_ns: int) -> int:
        return t_ns
