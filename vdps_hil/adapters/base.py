"""Adapter base class: one reader per physical device, timestamping, health and fan-out.

An *adapter* owns one physical (or recorded) device -- a CAN interface, a serial port, a log
file -- and is the only thing that reads it. Subclasses implement three small methods:

* ``_open()`` / ``_close()``: acquire and release the device (``_open`` raises
  :class:`AdapterError` with one line when a person's configuration is wrong);
* ``_read(timeout_s)``: return what is waiting as ``[(t_ns | None, payload), ...]`` (``None``:
  stamp with the adapter's clock at return), raise :class:`DeviceLost` when the device vanished
  and :class:`EndOfInput` at the end of a file;
* ``_raw(t_ns, wall_time_ns, payload)`` and ``_decode(t_ns, payload)``: the raw record to keep
  and the decoded :class:`~vdps_hil.bus.samples.Sample` list.

Everything else happens here, once, for every adapter:

Time. ``t_ns`` is integer monotonic nanoseconds (orders samples across sources); the wall time
is ``wall_time_ns = t_ns + (wall0 - mono0)`` with the offset taken once when the clock starts,
so the two never disagree about order (:class:`SystemClock`). Recorded input brings its own
``t_ns`` (:class:`ReplayClock`: ``wall_time_ns = t_ns``, the file's own clock).

Health (like opendbc's ``MessageState``), per source and per sample kind ``k``::

    period_k  = (t_last - t_first) / (n - 1)               for the first 100 samples
    period_k <- 0.99 period_k + 0.01 (t_n - t_{n-1})        afterwards (learned, EMA)
    (intervals longer than the timeout are gaps: counted, kept out of the period)
    rate_hz_k = 1e9 / period_k
    timed out when  now - t_last > timeout_periods * period_k   (default 10 periods)

plus counters: records, bytes, samples, invalid samples, ``time_backwards`` (a record or a
sample whose time is below the previous one of the same stream: kept, counted, the sample
marked ``valid=False``), ``queue_overflow`` (a listener's queue was full: the event is dropped
for that listener only and counted), ``reconnects``/``outages``/``outage_s`` (device lost and back), ``read_errors``,
``decoder_exceptions`` (a decoder raised: a bug, counted, never a crash), and the decoder's own
counters (unknown IDs, DLC mismatches, bad checksums, garbage, non-UTF-8 ...) merged in.

Fan-out. Listeners receive events (``RawCan``, ``RawSerial``, ``Sample``) through
:class:`Subscription` objects: bounded queues, never blocking the reader; an overflow drops the
event for that subscription and counts it (on the subscription per source, and in the source's
``queue_overflow``). A subscription may be attached to many adapters (fan-in to one recorder).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from typing import Any, Callable, Iterable, Mapping, Sequence

from vdps_hil.bus.samples import Sample

__all__ = [
    "Adapter", "AdapterError", "DeviceLost", "EndOfInput", "SystemClock", "ReplayClock",
    "RawCan", "RawSerial", "Subscription", "SourceHealth", "KindStats",
]

NS_PER_S = 1_000_000_000


class AdapterError(Exception):
    """A configuration mistake (bad interface string, missing port, unreadable file): the
    message is one line and the CLI exits 2."""


class DeviceLost(Exception):
    """Raised by ``_read`` when the device disappeared (unplugged, pty closed, bus down)."""


class EndOfInput(Exception):
    """Raised by ``_read`` of a file adapter after the last record."""


# --- clocks ---------------------------------------------------------------------------------

class SystemClock:
    """Host clock: ``now() -> (t_ns, wall_time_ns)``, ``t_ns`` from ``time.monotonic_ns`` and
    ``wall_time_ns = t_ns + offset`` with the wall-minus-monotonic offset fixed at creation."""

    replay = False

    def __init__(self):
        self.offset_ns = time.time_ns() - time.monotonic_ns()

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


# --- events ---------------------------------------------------------------------------------

class RawCan:
    """A received (or sent) CAN frame: ``msg`` is the ``can.Message`` as the interface gave it;
    ``device_time_ns`` the interface's own time stamp (``msg.timestamp``) in ns, or None."""

    __slots__ = ("t_ns", "wall_time_ns", "source", "msg", "direction", "device_time_ns")

    def __init__(self, t_ns: int, wall_time_ns: int, source: str, msg: Any,
                 direction: str = "rx", device_time_ns: int | None = None):
        self.t_ns, self.wall_time_ns, self.source = t_ns, wall_time_ns, source
        self.msg, self.direction, self.device_time_ns = msg, direction, device_time_ns

    def __repr__(self) -> str:
        return (f"RawCan({self.source} t={self.t_ns} id=0x{self.msg.arbitration_id:X} "
                f"data={bytes(self.msg.data).hex()})")


class RawSerial:
    """One chunk of bytes as one read returned them (``t_ns`` = when the read returned)."""

    __slots__ = ("t_ns", "wall_time_ns", "source", "data", "baud", "fmt")

    def __init__(self, t_ns: int, wall_time_ns: int, source: str, data: bytes,
                 baud: int | None = None, fmt: str | None = None):
        self.t_ns, self.wall_time_ns, self.source = t_ns, wall_time_ns, source
        self.data, self.baud, self.fmt = data, baud, fmt

    def __repr__(self) -> str:
        return f"RawSerial({self.source} t={self.t_ns} {len(self.data)} B)"


Event = RawCan | RawSerial | Sample


class Subscription:
    """A bounded queue from one or more adapters to one listener.

    ``put`` never blocks: when ``maxsize`` events are waiting the new one is dropped and
    counted (``overflows``, and per source in ``overflows_by_source``). ``raw`` / ``samples``
    select which events this listener wants. ``drain(max_n)`` returns what is waiting (oldest
    first); ``wait(timeout_s)`` sleeps until something was put (or the timeout passed).
    """

    def __init__(self, name: str = "listener", maxsize: int = 100_000, *, raw: bool = True,
                 samples: bool = True):
        if maxsize < 1:
            raise ValueError("maxsize must be >= 1")
        self.name, self.maxsize = name, int(maxsize)
        self.raw, self.samples = bool(raw), bool(samples)
        self._q: deque = deque()
        self._event = threading.Event()
        self.overflows = 0
        self.overflows_by_source: dict[str, int] = {}
        self.delivered = 0
        self.high_water = 0

    def wants(self, ev: Event) -> bool:
        return self.samples if isinstance(ev, Sample) else self.raw

    def put(self, ev: Event) -> bool:
        q = self._q
        n = len(q)
        if n >= self.maxsize:
            self.overflows += 1
            src = ev.source
            self.overflows_by_source[src] = self.overflows_by_source.get(src, 0) + 1
            return False
        q.append(ev)
        if n == 0:
            self._event.set()
        elif n >= self.high_water:
            self.high_water = n + 1
        return True

    def drain(self, max_n: int | None = None) -> list:
        q = self._q
        out = []
        pop = q.popleft
        n = len(q) if max_n is None else min(max_n, len(q))
        for _ in range(n):
            out.append(pop())
        self.delivered += len(out)
        return out

    def wait(self, timeout_s: float) -> bool:
        if self._q:
            return True
        self._event.clear()
        if self._q:  # put between the check and the clear
            return True
        return self._event.wait(timeout_s)

    def __len__(self) -> int:
        return len(self._q)


# --- health ---------------------------------------------------------------------------------

@dataclasses.dataclass
class KindStats:
    """Learned rate and timeouts of one sample kind of one source."""

    count: int = 0
    first_t_ns: int = -1
    last_t_ns: int = -1
    period_ns: float = 0.0
    timeouts: int = 0
    timed_out: bool = False
    max_gap_ns: int = 0
    _gap_ns: int = 0
    _gaps: int = 0

    LEARN_N = 100
    EMA = 0.01

    @property
    def rate_hz(self) -> float:
        return NS_PER_S / self.period_ns if self.period_ns > 0 else 0.0

    def timeout_ns(self, periods: float, min_timeout_ns: int) -> float:
        return max(periods * self.period_ns, float(min_timeout_ns)) if self.period_ns > 0 \
            else float("inf")

    def add(self, t_ns: int, periods: float, min_timeout_ns: int) -> tuple[bool, bool]:
        """Account one sample at ``t_ns``; returns (went_backwards, resumed_after_timeout)."""
        backwards = resumed = False
        if self.count == 0:
            self.first_t_ns = t_ns
        else:
            dt = t_ns - self.last_t_ns
            if dt < 0:
                backwards = True
            else:
                if dt > self.max_gap_ns:
                    self.max_gap_ns = dt
                gap = self.count >= 2 and dt > self.timeout_ns(periods, min_timeout_ns)
                if gap:
                    if not self.timed_out:
                        self.timeouts += 1  # a gap seen only now (replay, or between polls)
                    resumed = True
                    self._gap_ns += dt  # a gap is not a period: keep it out of the rate
                elif self.timed_out:
                    resumed = True
                if not gap:
                    if self.count < self.LEARN_N:
                        self.period_ns = (t_ns - self.first_t_ns - self._gap_ns) / \
                            (self.count - self._gaps)
                    else:
                        self.period_ns += self.EMA * (dt - self.period_ns)
                else:
                    self._gaps += 1
        self.timed_out = False
        self.count += 1
        if not backwards:
            self.last_t_ns = t_ns
        return backwards, resumed

    def check(self, now_ns: int, periods: float, min_timeout_ns: int) -> bool:
        """Mark (and count once) a timeout when nothing came for too long; True if newly."""
        if self.timed_out or self.count < 2:
            return False
        if now_ns - self.last_t_ns > self.timeout_ns(periods, min_timeout_ns):
            self.timed_out = True
            self.timeouts += 1
            return True
        return False

    def snapshot(self) -> dict:
        return {"count": self.count, "rate_hz": round(self.rate_hz, 3),
                "timeouts": self.timeouts, "timed_out": self.timed_out,
                "max_gap_s": self.max_gap_ns / NS_PER_S}


class SourceHealth:
    """Per-source health: counters, per-kind rates and the device state."""

    def __init__(self, source: str, transport: str, device: str):
        self.source, self.transport, self.device = source, transport, device
        self.state = "closed"
        self.counters: dict[str, int] = {}
        self.kinds: dict[str, KindStats] = {}
        self.records = 0
        self.bytes = 0
        self.samples = 0
        self.outage_ns = 0
        self.lost_since_ns: int | None = None
        self.last_record_t_ns = -1
        self.last_error = ""
        self.decoder_counters: Callable[[], Mapping[str, int]] | None = None

    def count(self, name: str, n: int = 1) -> None:
        self.counters[name] = self.counters.get(name, 0) + n

    @property
    def drops(self) -> int:
        """Lost data: our queue overflows plus what the decoders saw missing (sequence
        counters: ``seq_gaps``, ``lost_frames``)."""
        c = self.all_counters()
        return sum(c.get(k, 0) for k in DROP_COUNTERS)

    def all_counters(self) -> dict[str, int]:
        """Own counters merged with the decoder's. A decoder's nested counters (per message,
        ``{"bus": {...}, "VDPS_WheelSpeedFront": {"accepted": ..}}``) are summed per name;
        ours win on a clash."""
        merged: dict[str, int] = {}
        if self.decoder_counters is not None:
            try:
                _flatten_into(merged, self.decoder_counters())
            except Exception:  # noqa: BLE001 - health must never raise
                merged["decoder_counters_unavailable"] = 1
        merged.update(self.counters)
        return merged

    def snapshot(self, now_ns: int | None = None) -> dict:
        outage = self.outage_ns
        if self.lost_since_ns is not None and now_ns is not None:
            outage += max(0, now_ns - self.lost_since_ns)
        return {"source": self.source, "transport": self.transport, "device": self.device,
                "state": self.state, "records": self.records, "bytes": self.bytes,
                "samples": self.samples, "drops": self.drops, "outage_s": outage / NS_PER_S,
                "last_error": self.last_error, "counters": self.all_counters(),
                "kinds": {k: v.snapshot() for k, v in sorted(self.kinds.items())}}

    def error_total(self) -> int:
        """Everything that is a reject or a fault (for a one-line status)."""
        c = self.all_counters()
        return sum(c.get(k, 0) for k in ERROR_COUNTERS)


def _flatten_into(out: dict[str, int], counters: Mapping) -> None:
    for k, v in counters.items():
        if isinstance(v, Mapping):
            for kk, vv in v.items():
                if isinstance(vv, (int, float)) and not isinstance(vv, bool):
                    out[str(kk)] = out.get(str(kk), 0) + int(vv)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[str(k)] = int(v)


ERROR_COUNTERS = frozenset({
    # serial decoders (NMEA, IMU): every reject, whatever the reason, is in "rejected"
    "rejected",
    # CAN decoders (VdpsCanDecoder, SignalMapDecoder): per-frame rejects
    "dlc_mismatch", "undecodable", "out_of_range", "crc_mismatch", "checksum_mismatch",
    "counter_repeat", "counter_jump", "malformed", "bad_frames",
    # file adapters: lines of a text log that could not be read
    "bad_lines", "non_utf8_lines",
    # this base class
    "time_backwards", "decoder_exceptions", "read_errors"})
"""Counter names that mean a rejected or faulty input (summed as ``errors`` in the status).
Unknown CAN IDs, unsupported sentences and frames of other channels are not errors."""

DROP_COUNTERS = ("queue_overflow", "seq_gaps", "lost_frames")
"""Counter names that mean data lost on the way (summed as ``drops``)."""


# --- the base class -------------------------------------------------------------------------

class Adapter(ABC):
    """Base of every adapter. Subclasses read and decode; this class does the rest.

    ``name``: the source name (``can.<bus>`` for CAN buses, the device name for serial).
    ``clock``: :class:`SystemClock` (live, default) or :class:`ReplayClock` (files).
    ``reconnect_s``: how often a lost device is retried. ``timeout_periods``: a sample kind
    times out after this many learned periods (``min_timeout_s`` at least).
    """

    transport: str = "?"

    def __init__(self, name: str, device: str = "", *, clock=None, reconnect_s: float = 0.25,
                 timeout_periods: float = 10.0, min_timeout_s: float = 0.02):
        self.name = str(name)
        self.device = str(device)
        self.clock = clock if clock is not None else SystemClock()
        self.reconnect_s = float(reconnect_s)
        self.timeout_periods = float(timeout_periods)
        self.min_timeout_ns = int(min_timeout_s * NS_PER_S)
        self.health = SourceHealth(self.name, self.transport, self.device)
        self.health.decoder_counters = self.decoder_counters
        self._subs: list[Subscription] = []
        self._open_flag = False
        self._next_retry_ns = 0
        self._last_check_ns = 0
        self._last_raw_t_ns = -1

    # -- subclass interface ------------------------------------------------------------------

    @abstractmethod
    def _open(self) -> None:
        """Acquire the device; raise AdapterError (one line) or DeviceLost."""

    @abstractmethod
    def _close(self) -> None:
        """Release the device (must not raise)."""

    @abstractmethod
    def _read(self, timeout_s: float) -> Sequence[tuple[int | None, Any]]:
        """What is waiting, up to ``timeout_s``: ``[(t_ns or None, payload), ...]``."""

    @abstractmethod
    def _raw(self, t_ns: int, wall_time_ns: int, payload: Any) -> RawCan | RawSerial | None:
        """The raw record of one payload (None: nothing to record)."""

    @abstractmethod
    def _decode(self, t_ns: int, payload: Any) -> Iterable[Sample]:
        """Decoded samples of one payload (may be empty)."""

    def decoder_counters(self) -> Mapping[str, int]:
        """The decoder's counters (unknown IDs, bad checksums ...); empty by default."""
        return {}

    # -- listeners ---------------------------------------------------------------------------

    def subscribe(self, sub: Subscription | None = None, **kw) -> Subscription:
        """Attach a subscription (or make one with ``Subscription(**kw)``) and return it."""
        if sub is None:
            sub = Subscription(**kw)
        self._subs.append(sub)
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        self._subs = [s for s in self._subs if s is not sub]

    def _publish(self, ev) -> None:
        for sub in self._subs:
            if sub.wants(ev) and not sub.put(ev):
                self.health.count("queue_overflow")

    # -- lifecycle ---------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        return self._open_flag

    def open(self) -> None:
        """Open the device now; a failure is the person's mistake (AdapterError, one line)."""
        try:
            self._open()
        except DeviceLost as e:
            raise AdapterError(f"{self.name}: cannot open {self.device}: {e}") from None
        self._open_flag = True
        self.health.state = "open"

    def close(self) -> None:
        if self._open_flag:
            self._open_flag = False
            try:
                self._close()
            except Exception:  # noqa: BLE001 - closing must not raise
                pass
        if self.health.lost_since_ns is not None:
            now, _ = self.clock.now()
            self.health.outage_ns += max(0, now - self.health.lost_since_ns)
            self.health.lost_since_ns = None
        self.health.state = "closed"

    def __enter__(self):
        if not self._open_flag:
            self.open()
        return self

    def __exit__(self, *exc):
        self.close()

    def _lost(self, why: str) -> None:
        h = self.health
        self._open_flag = False
        try:
            self._close()
        except Exception:  # noqa: BLE001
            pass
        now, _ = self.clock.now()
        h.count("outages")
        h.lost_since_ns = now
        h.state = "lost"
        h.last_error = why.splitlines()[0] if why else "device lost"
        self._next_retry_ns = now + int(self.reconnect_s * NS_PER_S)
        self._on_lost()

    def _on_lost(self) -> None:
        """Hook: reset decoder state (a partial line) when the device is lost."""

    def _try_reconnect(self) -> bool:
        now, _ = self.clock.now()
        if now < self._next_retry_ns:
            return False
        try:
            self._open()
        except (DeviceLost, AdapterError, OSError) as e:
            self._next_retry_ns = now + int(self.reconnect_s * NS_PER_S)
            self.health.last_error = str(e).splitlines()[0] if str(e) else "reconnect failed"
            return False
        h = self.health
        self._open_flag = True
        h.count("reconnects")
        if h.lost_since_ns is not None:
            h.outage_ns += max(0, self.clock.now()[0] - h.lost_since_ns)
            h.lost_since_ns = None
        h.state = "open"
        return True

    # -- the loop ----------------------------------------------------------------------------

    def poll(self, timeout_s: float = 0.05) -> int:
        """Read once (waiting at most ``timeout_s``), stamp, decode and publish. Returns the
        number of payloads handled; raises EndOfInput at the end of a file."""
        if not self._open_flag:
            if self.health.state == "closed":
                self.open()
            elif not self._try_reconnect():
                time.sleep(min(timeout_s, self.reconnect_s))
                return 0
        try:
            items = self._read(timeout_s)
        except DeviceLost as e:
            self._lost(str(e))
            return 0
        except EndOfInput:
            self._end_of_input()
            raise
        except (OSError, ValueError) as e:
            self.health.count("read_errors")
            self.health.last_error = str(e).splitlines()[0] if str(e) else type(e).__name__
            return 0
        if items:
            self.ingest(items)
        if not self.clock.replay:
            now, _ = self.clock.now()
            if now - self._last_check_ns > 10_000_000:
                self._last_check_ns = now
                self.check_timeouts(now)
        return len(items)

    def ingest(self, items: Iterable[tuple[int | None, Any]]) -> None:
        """Stamp, record and decode payloads (the common path of live and replay input)."""
        clock = self.clock
        h = self.health
        stamp = None
        for t_ns, payload in items:
            if t_ns is None:
                if stamp is None:
                    stamp = clock.now()
                t_ns, wall = stamp
            else:
                wall = clock.wall(t_ns)
                if clock.replay:
                    clock.last_ns = t_ns
            h.records += 1
            if t_ns < self._last_raw_t_ns:
                h.count("time_backwards")
                backwards = True
            else:
                self._last_raw_t_ns = t_ns
                backwards = False
            raw = self._raw(t_ns, wall, payload)
            if raw is not None:
                self._publish(raw)
            try:
                samples = self._decode(t_ns, payload)
            except Exception as e:  # noqa: BLE001 - a decoder bug must not stop the logger
                h.count("decoder_exceptions")
                h.last_error = f"decoder: {type(e).__name__}: {e}".splitlines()[0]
                continue
            for s in samples:
                self._publish_sample(s, t_ns, wall, backwards)

    def _publish_sample(self, s: Sample, t_ns: int, wall: int, backwards: bool) -> None:
        h = self.health
        ks = h.kinds.get(s.kind)
        if ks is None:
            ks = h.kinds[s.kind] = KindStats()
        back, _ = ks.add(s.t_ns, self.timeout_periods, self.min_timeout_ns)
        valid = s.valid
        if back or backwards:
            if back and not backwards:
                h.count("time_backwards")
            valid = False
        h.samples += 1
        if not valid:
            h.count("invalid_samples")
        if s.wall_time_ns == 0 or valid != s.valid:
            s = dataclasses.replace(s, wall_time_ns=s.wall_time_ns or (wall + s.t_ns - t_ns),
                                    valid=valid)
        self._publish(s)

    def _flush_decoder(self) -> Iterable[Sample]:
        """Hook: samples a decoder still holds at the end of the input (default none)."""
        return ()

    def _end_of_input(self) -> None:
        if getattr(self, "_ended", False):
            return
        self._ended = True
        try:
            samples = list(self._flush_decoder())
        except Exception as e:  # noqa: BLE001
            self.health.count("decoder_exceptions")
            self.health.last_error = f"decoder flush: {type(e).__name__}: {e}".splitlines()[0]
            return
        for s in samples:
            self._publish_sample(s, s.t_ns, self.clock.wall(s.t_ns), False)

    def check_timeouts(self, now_ns: int) -> list[str]:
        """Mark sample kinds that stopped arriving; returns those newly timed out."""
        out = []
        for kind, ks in self.health.kinds.items():
            if ks.check(now_ns, self.timeout_periods, self.min_timeout_ns):
                out.append(kind)
        return out

    def run(self, stop: threading.Event, poll_s: float = 0.05) -> None:
        """Poll until ``stop`` is set (or the input ends); closes the device at the end. A
        person's mistake at the first open raises AdapterError before anything is read."""
        if not self._open_flag and self.health.state == "closed":
            self.open()
        try:
            while not stop.is_set():
                try:
                    self.poll(poll_s)
                except EndOfInput:
                    break
        finally:
            self.close()

    def status(self) -> dict:
        """A snapshot of the health for a status line or a recording."""
        now, _ = self.clock.now()
        return self.health.snapshot(now)

    def status_line(self) -> str:
        """``name: 1000.0 Hz imu, 5.0 Hz gnss_pos | drops 0 errors 0 [state]``."""
        h = self.health
        rates = ", ".join(f"{k.rate_hz:.1f} Hz {name}{' TIMEOUT' if k.timed_out else ''}"
                          for name, k in sorted(h.kinds.items())) or "no samples"
        state = "" if h.state == "open" else f" [{h.state.upper()}]"
        return (f"{self.name}: {h.records} rec, {rates} | drops {h.drops} errors "
                f"{h.error_total()}{state}")
