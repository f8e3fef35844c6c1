"""Deadline misses of the bench's pipeline: a pipeline short of CPU skips its own work, counted,
instead of accumulating lag (``hil.node`` asks :meth:`DeadlineGuard.skip` for every sample before
it handles it).

Rule (``deadline_s``, default 0.1 s wall): when a sample stamped at its time on the wire -- the
IMU (device clock aligned to reception) and everything decoded from CAN (the interface's time
stamp) -- reaches the pipeline loop more than ``deadline_s`` after its own time on the bench
clock, every sample is skipped -- not handed to the system, not recorded under ``/decoded/``,
no outputs -- until an IMU sample is within ``deadline_s / 2`` again *and* at least
``deadline_s / 2`` of IMU input (by the samples' times) has been skipped. GNSS samples are not
judged: they carry the fix time, which a receiver reports tens of milliseconds later by design.
Judging the CAN samples too matters when input arrives in a burst: thousands of late CAN samples
queued ahead of the next IMU packet were otherwise all handled, each later than the last (at 8x
on the bench, p99 latency 350-570 ms against a 100 ms deadline). The deadline in bench time is
``deadline_s * X`` (speed ``X``), never less than twice the input sequencer's hold (a held
measurement is not late).

The skipped span of IMU input, at least ``deadline_s / 2``, is longer than the IMU monitor's gap
timeout (20 ms), so the estimator sees an IMU outage and the warning frames say "sensor missing"
(status 2) until ``ImuChecks.settle_s`` after the IMU is back (``pipeline.node``): a pipeline
that fell behind says so on the bus, also when it was a burst of CAN input that made it late
and the IMU packets in between were on time.

Counts (``counts()``): samples skipped, episodes (times the pipeline fell behind), per sample
kind, the time of the first skipped sample [s] and the deadline [ms].
"""

from __future__ import annotations

__all__ = ["DeadlineGuard", "DEFAULT_DEADLINE_S"]

DEFAULT_DEADLINE_S = 0.1
"""Wall seconds an IMU sample may be late before the pipeline skips work (module docstring)."""


class DeadlineGuard:
    """``skip(sample)``: whether to skip ``sample`` (module docstring); ``clock``: the bench
    clock (``now_ns()`` on the samples' axis, ``speed``); ``hold_s``: the input sequencer's
    hold [bench s]; ``deadline_s=None``: never skip."""

    def __init__(self, clock, deadline_s: float | None = DEFAULT_DEADLINE_S, hold_s: float = 0.0):
        self.clock = clock
        speed = getattr(clock, "speed", 1.0)
        self.deadline_ns = (None if deadline_s is None
                            else max(int(round(deadline_s * speed * 1e9)), int(2e9 * hold_s)))
        self.resume_ns = None if deadline_s is None else self.deadline_ns // 2
        self.shedding = False
        self._imu_from_ns = None  # time of the first IMU sample skipped in this episode
        self._c = {"samples": 0, "episodes": 0, "by_kind": {}, "first_t_s": None,
                   "deadline_ms": None if deadline_s is None else 1e3 * deadline_s}

    def skip(self, s, now_ns: int | None = None) -> bool:
        """``now_ns``: the bench clock now, when the caller has just read it."""
        if self.deadline_ns is None:
            return False
        c = self._c
        if not s.kind.startswith("gnss"):  # stamped at the wire (module docstring)
            late_ns = (self.clock.now_ns() if now_ns is None else now_ns) - s.t_ns
            if not self.shedding:
                if late_ns > self.deadline_ns:
                    self.shedding = True
                    self._imu_from_ns = None
                    c["episodes"] += 1
            elif s.kind == "imu":  # only the IMU ends an episode, after half a deadline of it
                if self._imu_from_ns is None:
                    self._imu_from_ns = s.t_ns
                if late_ns <= self.resume_ns and s.t_ns - self._imu_from_ns >= self.resume_ns:
                    self.shedding = False
        if not self.shedding:
            return False
        c["samples"] += 1
        c["by_kind"][s.kind] = c["by_kind"].get(s.kind, 0) + 1
        if c["first_t_s"] is None:
            c["first_t_s"] = s.t_ns / 1e9
        return True

    def counts(self) -> dict:
        return {**self._c, "by_kind": dict(self._c["by_kind"])}
