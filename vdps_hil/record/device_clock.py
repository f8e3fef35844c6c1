"""Device time -> host time: unwrapping device counters and clocks, a leaky running minimum of
host minus device time, and stamping read chunks by it (used by :mod:`vdps_hil.record.decode`
and the bench's live pipeline, ``hil.node``).

Time stamps from the devices' own clocks (``device_time=True``)
---------------------------------------------------------------
A serial recording holds read chunks (5 ms windows); the receive-time rule
(``codecs.framing``) stamps a message by its last byte assuming back-to-back bytes, so the
packets of one chunk are stamped too close together (an IMU packet takes 0.51 ms on the wire
at 921600 Bd but is sent every 1 ms) and late by the wire time. Each device's own time -- the
IMU's SampleTimeFine (10 kHz ticks; the packet counter times a nominal period when absent) and
the UTC time of day of NMEA sentences -- is mapped onto the host clock::

    d_k      = host time of the start of message k  -  device time of message k
             = (t_rule,k - T_wire,k) - t_dev,k              T_wire,k = n_k * 10 / baud
    o_k      = min(o_{k-1} + leak * (t_dev,k - t_dev,k-1),  d_k)       (leaky running minimum)
    t_k      = t_dev,k + o_k                                  (the sample's t_ns)

The message with the least queueing (the last one of a chunk, the first sentence of a GNSS
epoch) has d_k = transport latency exactly, so the minimum is the device-to-host offset plus
the latency and t_k is the device's measurement instant on the host clock, without the chunk
quantisation. ``leak`` (default 100 ppm, twice a typical crystal tolerance) lets the offset
follow a device clock that runs slower than the host. The observations of one IMU chunk are
all taken before any of its packets is stamped. Device times are unwrapped (SampleTimeFine
modulo 2^32 ticks, packet counter modulo 2^16, UTC modulo one day) by the signed shortest step.

Clock steps: a step of the device clock ahead (d_k drops) by more than ``jump_s`` and a step
back (d_k rises by more than ``jump_s``) are believed only when they persist for
``confirm_s`` of device time (then the offset is re-anchored at the least d of that span and
``clock_jumps`` counts it); a single corrupted time stamp cannot move the offset. Until then
the old offset is used. A message without a device time (``$GPHDT`` has no UTC) keeps its
receive-time stamp.

Symbols: t_rule receive-time-rule stamp [ns]; T_wire wire time of the message [ns]; n_k its
length [bytes]; t_dev device time [ns]; d_k, o_k offsets [ns]; leak [1].
"""

from __future__ import annotations

from vdps_hil.bus.samples import Sample

__all__ = ["ClockAligner", "DeviceStamper", "Unwrapper"]


class Unwrapper:
    """Unwraps a counter or clock that wraps modulo ``modulus`` by the signed shortest step
    (call once per reading, in order)."""

    __slots__ = ("modulus", "_last", "_value")

    def __init__(self, modulus: int):
        self.modulus = int(modulus)
        self._last: int | None = None
        self._value = 0

    def __call__(self, raw: int) -> int:
        if self._last is None:
            self._value = raw
        else:
            m = self.modulus
            step = (raw - self._last) % m
            if step >= m // 2:
                step -= m
            self._value += step
        self._last = raw
        return self._value


class ClockAligner:
    """Device time -> host time by a leaky running minimum of host - device (module docstring).

    ``observe(host_ns, dev_ns)`` feeds one message (device time already unwrapped);
    ``to_host(dev_ns)`` stamps one. ``jump_s``/``confirm_s``: a step of the offset larger than
    ``jump_s`` is believed once it has lasted ``confirm_s`` of device time."""

    __slots__ = ("leak", "jump_ns", "confirm_ns", "offset_ns", "observations", "jumps", "_last_dev",
                 "_pending")

    def __init__(self, *, leak_ppm: float = 100.0, jump_s: float = 0.02, confirm_s: float = 0.2):
        if not (leak_ppm >= 0 and jump_s > 0 and confirm_s >= 0):
            raise ValueError("leak_ppm >= 0, jump_s > 0 and confirm_s >= 0 are required")
        self.leak = leak_ppm * 1e-6
        self.jump_ns = int(round(jump_s * 1e9))
        self.confirm_ns = int(round(confirm_s * 1e9))
        self.offset_ns: int | None = None
        self.observations = 0
        self.jumps = 0
        self._last_dev: int | None = None
        self._pending: tuple[int, int, bool] | None = None  # (device time first seen, least d, step up)

    def observe(self, host_ns: int, dev_ns: int) -> str:
        """Feed one message; returns ``"ok"`` (consistent; a pending step, if any, was not
        confirmed: those messages were outliers), ``"pending"`` (a step is being watched: hold
        the message) or ``"jump"`` (a step confirmed: the offset is re-anchored)."""
        self.observations += 1
        d = host_ns - dev_ns
        o = self.offset_ns
        if o is None:
            self.offset_ns, self._last_dev = d, dev_ns
            return "ok"
        if dev_ns > self._last_dev:
            o += int(self.leak * (dev_ns - self._last_dev))
        self._last_dev = dev_ns
        delta = d - o
        if -self.jump_ns <= delta <= self.jump_ns:
            self._pending = None
            self.offset_ns = o if o < d else d
            return "ok"
        # a clock step, a host stall or a corrupt time stamp: believed only if it lasts
        up = delta > 0
        p = self._pending
        self.offset_ns = o
        if p is None or p[2] != up:
            self._pending = (dev_ns, d, up)
            return "pending"
        least = p[1] if p[1] < d else d
        if dev_ns - p[0] >= self.confirm_ns:
            self.offset_ns = least
            self._pending = None
            self.jumps += 1
            return "jump"
        self._pending = (p[0], least, up)
        return "pending"

    def to_host(self, dev_ns: int) -> int:
        return dev_ns + (self.offset_ns or 0)

    def status(self) -> dict:
        return {"offset_ns": self.offset_ns, "observations": self.observations, "clock_jumps": self.jumps}


def _restamp(s: Sample, t_ns: int) -> Sample:
    return Sample(t_ns, s.source, s.kind, s.fields, s.wall_time_ns, s.valid)  # every field, in order


class DeviceStamper:
    """Stamps messages by a :class:`ClockAligner`: ``stamp([(sample, host_ns, dev_ns), ...])``
    observes a batch (one read chunk) first and then stamps it, so the batch's least-delayed
    message sets the offset for all of it. Messages seen while a clock step is pending are held;
    a confirmed step stamps them with the new offset, an unconfirmed one releases them with
    their receive-time stamps (``outliers``). ``times``/``release`` do the same for messages of
    any kind (the caller makes the samples)."""

    __slots__ = ("clock", "held", "outliers")

    def __init__(self, clock: ClockAligner):
        self.clock = clock
        self.held: list[tuple[object, int]] = []
        self.outliers = 0

    def stamp(self, batch) -> list[Sample]:
        items, times = self.times(batch)
        return [s if t is None else _restamp(s, t) for s, t in zip(items, times)]

    def times(self, batch) -> tuple[list, list[int | None]]:
        """``batch``: ``[(message, host_ns, dev_ns), ...]`` -> (messages in output order, their
        stamps [ns]; None: an outlier, it keeps its receive-time stamp)."""
        clock = self.clock
        items: list = []
        times: list[int | None] = []  # device time until the offset is added (indices in todo)
        todo: list[int] = []
        for m, host, dev in batch:
            before = clock.offset_ns
            st = clock.observe(host, dev)
            if st == "pending":
                self.held.append((m, dev))
                continue
            if st == "jump":
                off = before or 0  # stamped with the offset before the step
                for i in todo:
                    times[i] += off
                todo = []
                for m0, d0 in self.held:
                    todo.append(len(items))
                    items.append(m0)
                    times.append(d0)
            elif self.held:  # the step did not last: those were outliers
                self.outliers += len(self.held)
                for m0, _ in self.held:
                    items.append(m0)
                    times.append(None)
            self.held = []
            todo.append(len(items))
            items.append(m)
            times.append(dev)
        off = clock.offset_ns or 0
        for i in todo:
            times[i] += off
        return items, times

    def release(self) -> list:
        """End of stream: the held messages (an unconfirmed step: outliers, they keep their
        receive-time stamps)."""
        held, self.held = self.held, []
        self.outliers += len(held)
        return [m for m, _ in held]

    def flush(self) -> list[Sample]:
        """``release`` of samples."""
        return self.release()

    def status(self) -> dict:
        d = self.clock.status()
        d["outliers"] = self.outliers
        return d

