"""Adapter base class: one reader per physical device, timestamping, health and fan-out.

An *adapter* owns one device (CAN interface, serial port, log file), its only reader. Subclasses:

* ``_open()`` / ``_close()``: acquire and release the device (``_open`` raises
  :class:`AdapterError` with one line when a person's configuration is wrong);
* ``_read(timeout_s)``: return what is waiting as ``[(t_ns | None, payload), ...]`` (``None``:
  stamp with the adapter's clock at return), raise :class:`DeviceLost` when the device vanished
  and :class:`EndOfInput` at the end of a file;
* ``_raw(t_ns, wall_time_ns, payload)`` and ``_decode(t_ns, payload)``: the raw record to keep
  and the decoded :class:`~vdps_hil.bus.samples.Sample` list.

Everything else happens here, once, for every adapter. Time: every record is stamped by the
adapter's clock (``vdps_hil.bus.clocks``: ``SystemClock`` live, monotonic ``t_ns`` and wall time
from one fixed offset; ``ReplayClock`` for recorded input, the file's own ``t_ns``). Health: per
source and sample kind, learned rates, timeouts and counters (``adapters.health.SourceHealth``).
Fan-out: listeners receive events (``RawCan``, ``RawSerial``, ``Sample``; ``vdps_hil.bus.raw``)
through ``bus.subscription.Subscription`` objects, bounded queues that never block the reader;
an overflow drops the event for that subscription and counts it (per source, ``queue_overflow``).
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from typing import Any, Iterable, Mapping, Sequence

from vdps_hil.adapters.health import KindStats, SourceHealth
from vdps_hil.bus.clocks import SystemClock
from vdps_hil.bus.raw import RawCan, RawSerial
from vdps_hil.bus.samples import Sample
from vdps_hil.bus.subscription import Subscription
from vdps_hil.units import NS_PER_S

__all__ = ["Adapter", "AdapterError", "DeviceLost", "EndOfInput"]

_DECODE_GAP = object()
"""Payload marking a break in the input (device lost): the decoder forgets partial input there."""


class AdapterError(Exception):
    """A configuration mistake (bad interface string, missing port, unreadable file): the
    message is one line and the CLI exits 2."""


class DeviceLost(Exception):
    """Raised by ``_read`` when the device disappeared (unplugged, pty closed, bus down)."""


class EndOfInput(Exception):
    """Raised by ``_read`` of a file adapter after the last record."""


# --- the base class -------------------------------------------------------------------------

class Adapter(ABC):
    """Base of every adapter. Subclasses read and decode; this class does the rest.

    ``name``: the source name (``can.<bus>`` for CAN buses, the device name for serial).
    ``clock``: ``bus.clocks.SystemClock`` (live, default) or ``bus.clocks.ReplayClock`` (files).
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
        if self.reader is not None:
            self._reader.stop()
            self._reader = None
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

    def _lost(self, why: str, reset_decoder: bool = True) -> None:
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
        if reset_decoder:
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
        """Stamp, record and decode payloads (the common path of live and replay input): each
        payload's raw record is published, then its samples."""
        for t_ns, wall, payload, backwards in self.stamp(items):
            raw = self._raw(t_ns, wall, payload)
            if raw is not None:
                self._publish(raw)
            for s in self._decode_one(t_ns, wall, payload, backwards):
                self._publish(s)

    def stamp(self, items: Iterable[tuple[int | None, Any]]) -> list[tuple[int, int, Any, bool]]:
        """``(t_ns, wall_time_ns, payload, went_backwards)`` of each payload: a ``None`` time
        stamped with the clock now (once per call), the records counted."""
        clock = self.clock
        h = self.health
        stamp = None
        out = []
        last = self._last_raw_t_ns
        gaps = 0
        for t_ns, payload in items:
            if payload is _DECODE_GAP:
                out.append((t_ns, 0, payload, False))
                gaps += 1
                continue
            if t_ns is None:
                if stamp is None:
                    stamp = clock.now()
                t_ns, wall = stamp
            else:
                wall = clock.wall(t_ns)
                if clock.replay:
                    clock.last_ns = t_ns
            if t_ns < last:
                h.count("time_backwards")
                out.append((t_ns, wall, payload, True))
            else:
                last = t_ns
                out.append((t_ns, wall, payload, False))
        h.records += len(out) - gaps
        self._last_raw_t_ns = last
        return out

    def raw_events(self, stamped: Sequence[tuple[int, int, Any, bool]]) -> list:
        """The raw records (``RawCan``/``RawSerial``) of stamped payloads."""
        raw = self._raw
        out = []
        for t_ns, wall, payload, _ in stamped:
            if payload is _DECODE_GAP:
                continue
            r = raw(t_ns, wall, payload)
            if r is not None:
                out.append(r)
        return out

    def decode_stamped(self, stamped: Sequence[tuple[int, int, Any, bool]]) -> list[Sample]:
        """The samples of stamped payloads, health kept (a decoder exception is counted)."""
        out = []
        for t_ns, wall, payload, backwards in stamped:
            if payload is _DECODE_GAP:
                self._decode_gap()
                continue
            out += self._decode_one(t_ns, wall, payload, backwards)
        return out

    def skip_decoding(self, stamped: Sequence[tuple[int, int, Any, bool]],
                      counter: str = "decoded_skipped") -> None:
        """Payloads recorded raw but not decoded (the decoder was behind): counted as
        ``counter``; the decoder forgets its sequence state so the skipped payloads are not
        taken for data lost before us."""
        n = sum(1 for it in stamped if it[2] is not _DECODE_GAP)
        if n:
            self.health.count(counter, n)
            self._decode_gap()

    def _decode_gap(self) -> None:
        """Hook: the decoder does not see some payloads (skipped, or the device was lost):
        forget partial input and sequence state (default: :meth:`_on_lost`)."""
        self._on_lost()

    def _decode_one(self, t_ns: int, wall: int, payload: Any, backwards: bool) -> list[Sample]:
        h = self.health
        try:
            samples = self._decode(t_ns, payload)
        except Exception as e:  # noqa: BLE001 - a decoder bug must not stop the logger
            h.count("decoder_exceptions")
            h.last_error = f"decoder: {type(e).__name__}: {e}".splitlines()[0]
            return []
        return [self._account_sample(s, t_ns, wall, backwards) for s in samples]

    def _account_sample(self, s: Sample, t_ns: int, wall: int, backwards: bool) -> Sample:
        """Health of one decoded sample; returns it with its wall time and validity set."""
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
        if s.wall_time_ns == 0 or valid != s.valid:  # the constructor: 3x cheaper than replace()
            s = Sample(s.t_ns, s.source, s.kind, s.fields, s.wall_time_ns or (wall + s.t_ns - t_ns), valid)
        return s

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
            self._publish(self._account_sample(s, s.t_ns, self.clock.wall(s.t_ns), False))

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

    def _publish_sample(self, s: Sample, t_ns: int, wall: int, backwards: bool) -> None:
        self._publish(self._account_sample(s, t_ns, wall, backwards))

    # -- the reader path (LogSession): reading apart from decoding and writing ----------------

    def reader_fd(self) -> int | None:
        """Hook: a file descriptor a reader process may drain (None: a reader thread calls
        ``_read``)."""
        return None

    def _chunk_items(self, t_ns: int, data: bytes) -> list[tuple[int, Any]]:
        """Hook: the payloads in bytes a reader process read (default: the chunk itself)."""
        self.health.bytes += len(data)
        return [(t_ns, data)]

    def _reader_lost(self) -> None:
        """Hook: the reader lost the device; forget partial bytes of ``_chunk_items``."""

    def check_os_counters(self) -> None:
        """Read the OS's loss counters of the device (``adapters.oscount``) into the health."""
        fd = self.reader_fd() if self._open_flag else None
        if fd is not None:
            from vdps_hil.adapters.oscount import OsCounters

            if getattr(self, "_os_counters", None) is None:
                self._os_counters = OsCounters(self.health)
            self._os_counters.update(fd)

    def start_reader(self, max_buffer_bytes: int | None = None) -> None:
        """Start draining the device in a process (``reader_fd``) or a thread of its own;
        :meth:`collect` then takes what it read. Opens the device if it is closed."""
        from vdps_hil.adapters import reader as R

        if not self._open_flag and self.health.state == "closed":
            self.open()
        fd = self.reader_fd() if self._open_flag else None
        if fd is not None and not self.clock.replay:
            kw = {} if max_buffer_bytes is None else {"max_buffer_bytes": max_buffer_bytes}
            self._reader = R.FdReader(self.name, **kw)
            self._reader.give(fd)
            self.health.reader = "process"
        else:
            now = (lambda: self.clock.now()[0])
            self._reader = R.ThreadReader(self.name, self._read, now, lost=(DeviceLost,),
                                          end=(EndOfInput,))
            self.health.reader = "thread"

    @property
    def reader(self):
        return getattr(self, "_reader", None)

    def collect(self, final: bool = False) -> list[tuple[int, int, Any, bool]]:
        """What the reader read since the last call, stamped (never waits); device losses,
        reader overflows and failed reads are accounted here, and a lost device is reopened
        every ``reconnect_s``. ``final``: stop the reader and take its last records."""
        from vdps_hil.adapters import reader as R

        rd = self._reader
        recs = rd.stop() if final else rd.take()
        h = self.health
        items: list = []
        for kind, t_ns, body in recs:
            if kind == R.DATA:
                if isinstance(body, (bytes, bytearray)) and rd.fileno() is not None:
                    items += self._chunk_items(t_ns, body)
                else:
                    items.append((t_ns, body))
            elif kind == R.LOST:
                if self._open_flag:
                    self._lost(body, reset_decoder=False)
                self._reader_lost()
                items.append((t_ns, _DECODE_GAP))
            elif kind == R.OVERFLOW:
                h.count("reader_overflow", body[0])
                if body[1]:
                    h.count("reader_overflow_bytes", body[1])
                h.last_error = f"reader buffer full: {body[0]} reads dropped"
            elif kind == R.ERROR:
                h.count("read_errors")
                h.last_error = body
        if not final and not self._open_flag and h.state == "lost" and self._try_reconnect():
            rd.give(self.reader_fd())
        if not self.clock.replay:
            now, _ = self.clock.now()
            if now - self._last_check_ns > 10_000_000:
                self._last_check_ns = now
                self.check_timeouts(now)
        return self.stamp(items)

    def stop_reader(self) -> list[tuple[int, int, Any, bool]]:
        """Stop the reader; returns what it still held, stamped."""
        if self.reader is None:
            return []
        try:
            return self.collect(final=True)
        finally:
            self._reader = None

    def status(self) -> dict:
        """A snapshot of the health for a status line or a recording."""
        now, _ = self.clock.now()
        return self.health.snapshot(now)

    def status_line(self) -> str:
        """``imu: 5000 rec, 1000.0 Hz imu | drops 0 (os ?, reader 0, seq 0), decode skipped 0,
        errors 0`` (``os ?``: the OS keeps no loss counters for this device)."""
        h = self.health
        rates = ", ".join(f"{k.rate_hz:.1f} Hz {name}{' TIMEOUT' if k.timed_out else ''}"
                          for name, k in sorted(h.kinds.items())) or "no samples"
        state = "" if h.state == "open" else f" [{h.state.upper()}]"
        c = h.all_counters()
        loss = h.loss(c)
        os_ = loss["os"] if h.os_counters == "yes" else "?"
        return (f"{self.name}: {h.records} rec, {rates} | drops {h.drops} (os {os_}, reader "
                f"{loss['reader']}, seq {loss['sequence']}), decode skipped "
                f"{loss['decoded_skipped']}, errors {h.error_total()}{state}")
