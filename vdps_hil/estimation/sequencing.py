"""Sequencing of the estimator's input: a measurement waits for the IMU samples up to its time.

The filter predicts to a measurement's time with the mean of the IMU samples it has. A
measurement that arrives before the IMU samples up to its time (live: a CAN frame up to a serial
read window ahead of the IMU packets of the same instant) would make it advance on a stale mean
and then count those IMU samples into the next interval. So a measurement that can advance the
filter (GNSS, suspension; wheel speeds when the filter takes them: the kinds of
``kind_latency_ns``) whose time is later than the newest IMU sample's is held until an IMU sample
at or after its time arrives, and the held ones go first, in time order -- the order a
time-ordered input has anyway -- or until the newest sample time has moved ``hold_ns``
(``PipelineConfig.imu_hold_s``, default 50 ms) past its arrival (the IMU stopped; counted
``hold_expired``), plus the IMU's latency beyond the measurement's own: an IMU whose time stamps
lag (rtklib-car: 0.125 s) reaches a measurement's time only that much after the measurement
arrived, and a 50 ms hold alone released every GNSS fix of that drive before its IMU samples.
Other samples (torques, steering, wheel speeds feeding only the alpha-beta filters) go on at
once. ``release_all`` hands on what is held at the end of the input. Before the
first IMU sample nothing is held. Times are compared with the per-sensor latencies removed.
"""

from __future__ import annotations

import heapq


class ImuSequencer:
    """Holds measurements until the IMU has reached their time (module docstring).

    ``imu_latency_ns``: latency of the IMU samples; ``kind_latency_ns``: {kind: latency} of the
    kinds that may be held. Counters: ``held`` (measurements held), ``hold_expired`` (released
    because the IMU stopped); ``holding``: held now."""

    def __init__(self, hold_ns: int, imu_latency_ns: int, kind_latency_ns: dict[str, int]):
        self._hold_ns = hold_ns
        self._imu_lat = imu_latency_ns
        self._kind_lat = kind_latency_ns
        self._imu_mark: int | None = None  # newest IMU sample time (latency removed)
        self._newest = -(1 << 62)  # newest sample time seen
        self._held: list = []  # heap of (t, seq, arrival time, sample, handler)
        self._held_seq = 0
        self.held = 0
        self.hold_expired = 0

    @property
    def holding(self) -> int:
        return len(self._held)

    def offer(self, sample, kind: str, fn, out: list) -> bool:
        """Take ``sample`` of ``kind`` (handler ``fn(sample, out)``): True when it was handed on
        or held here, False when the caller hands it on itself (nothing held and not a kind that
        may be held; an IMU sample then only moves the mark)."""
        t_s = sample.t_ns
        if t_s > self._newest:
            self._newest = t_s
        if self._held or kind in self._kind_lat:
            self._sequence(sample, kind, fn, out)
            return True
        if kind == "imu":  # nothing held: only the mark moves
            t = t_s - self._imu_lat
            if self._imu_mark is None or t > self._imu_mark:
                self._imu_mark = t
        return False

    def _sequence(self, sample, kind: str, fn, out: list) -> None:
        """Hand ``sample`` on now or hold it until the IMU has reached its time."""
        held = self._held
        t_s = sample.t_ns
        if kind == "imu":
            t = t_s - self._imu_lat
            while held and held[0][0] <= t:
                h = heapq.heappop(held)
                h[4](h[3], out)
            if self._imu_mark is None or t > self._imu_mark:
                self._imu_mark = t
            fn(sample, out)
        else:
            lat = self._kind_lat.get(kind)
            if lat is None or self._imu_mark is None or t_s - lat <= self._imu_mark:
                fn(sample, out)
            else:
                self._held_seq += 1
                self.held += 1
                # its deadline: hold_ns past its arrival, plus what the IMU's time stamps lag behind
                # its own (rtklib-car: 0.125 s; the IMU mark trails the newest sample time by that)
                deadline = self._newest + self._hold_ns + max(0, self._imu_lat - lat)
                heapq.heappush(held, (t_s - lat, self._held_seq, deadline, sample, fn))
        while held and self._newest >= held[0][2]:  # the IMU has stopped
            h = heapq.heappop(held)
            self.hold_expired += 1
            h[4](h[3], out)

    def release_all(self, out: list) -> None:
        """End of the input: hand on what is held, in time order."""
        while self._held:
            h = heapq.heappop(self._held)
            h[4](h[3], out)
