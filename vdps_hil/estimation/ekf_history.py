"""The EKF's latency history: what a late measurement needs to rewind the filter.

Before every predict and update the filter records an event (``Event``): its kind (predict or
update), the filter time t0 and the snapshot (x, P) before it, its end time t1 (predict: the
time predicted to; update: the measurement time) and its payload (predict: the IMU input;
update: kind, z, R, aux). Events older than the span (``history_s``) are dropped. The events are
in processing order, so their end times never decrease (each event ends at or after the filter
time it starts from). A measurement at t_m in the filter's past takes the events from the first
one ending after t_m on (``EventHistory.take_from``), rewinds to that event's snapshot and
re-runs them (``ekf`` module docstring, "Latency").
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass
class Event:
    """One recorded predict or update (module docstring)."""

    is_predict: bool
    t0: int  # filter time before the event
    x0: np.ndarray
    p0: np.ndarray
    t1: int  # predict: end time; update: measurement time
    payload: tuple


def _event_end(ev: Event) -> int:
    return ev.t1


class EventHistory:
    """The events of the last ``span_ns`` nanoseconds, in processing order."""

    def __init__(self, span_ns: int):
        self._span_ns = span_ns
        self._events: deque[Event] = deque()

    def record(self, event: Event) -> None:
        """Append ``event`` and drop the events that ended before its start minus the span."""
        events = self._events
        events.append(event)
        horizon = event.t0 - self._span_ns
        while events and events[0].t1 < horizon:
            events.popleft()

    def clear(self) -> None:
        self._events.clear()

    def reaches(self, t_m: int) -> bool:
        """Whether the oldest event starts at or before ``t_m``."""
        return bool(self._events) and self._events[0].t0 <= t_m

    def take_from(self, t_m: int) -> list[Event] | None:
        """Remove and return (in processing order) the events from the first one ending after
        ``t_m`` on; [] when none ends after t_m; None (nothing removed) when that first event
        starts after t_m (the history does not reach back to t_m)."""
        events = self._events
        i = bisect.bisect_right(events, t_m, key=_event_end)
        if i == len(events):
            return []
        if events[i].t0 > t_m:
            return None
        taken = [events.pop() for _ in range(len(events) - i)]
        taken.reverse()
        return taken
