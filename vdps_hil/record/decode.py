"""Decode a recording's ``/raw/`` topics into bus samples, in ``t_ns`` order, streaming.

``decode_recording(path_or_reader, *, dbc=None, signalmap=None, bus_map=None)`` reads ONLY the
``/raw/`` topics of a recording (``/raw/can/<bus>`` frames and ``/raw/serial/<device>`` read
chunks) and the channel metadata of those channels (a serial device's ``baud`` and ``format``).
It never reads ``/truth/``, ``/decoded/`` or the file's metadata records, so an estimator fed
from it sees exactly what a live logger saw on the wires.

Decoders (the project's codecs, the same the live adapters use)
----------------------------------------------------------------
=====================  =====================================================================
``/raw/can/<bus>``     default: bus ``vdps`` with ``dbc/vdps.dbc`` (``VdpsCanDecoder``: counters,
                       CRC and range checks); other buses are counted ``undecoded``.
                       ``signalmap``: every bus the map names (``bus_map`` renames recording
                       buses to map buses) with the map's DBC or ``dbc`` (``build_decoder``).
``/raw/serial/<dev>``  by the channel's ``format``: ``nmea`` -> ``LineFramer`` +
                       ``NmeaDecoder``; ``xsens-mtdata2`` (or ``imu``) -> ``ImuDecoder``; an
                       empty format falls back to the device name (``imu*`` binary, else NMEA);
                       an unknown format is counted ``undecoded``.
=====================  =====================================================================

Sample sources: ``can.<bus>`` (CAN), the device name (serial: ``imu``, ``gnss``).

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

Ordering: decoded samples may be stamped earlier than the raw record that carried them (by the
wire and chunk time, GNSS latency), so they pass a reorder buffer released ``reorder_window_s``
(default 1 s, longer than a clock step takes to confirm) behind the newest raw time: the output
is in ``t_ns`` order (ties in arrival order) and memory is bounded by that window, never the
drive. A sample older than what was
already released is emitted at once and counted ``late``.

Counters (``DecodedRecording.counters``): per source (``can.<bus>``, ``serial.<device>``)
the decoder's own counters, per device ``clock.<device>`` (offset, observations, jumps,
messages without a device time), and ``reader`` (undecodable raw messages, problems, ``late``,
``raw_records``). ``rejected()`` sums the rejects per source.

The raw records can be passed on unchanged (``raw_sink``), e.g. to copy them to an output
recording in the same single pass.
"""

from __future__ import annotations

import base64
import heapq
import json
import math
import os
import re
from binascii import unhexlify
from typing import Callable, Iterator, Mapping

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.framing import BITS_PER_BYTE_8N1, LineFramer, transmission_time_ns
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.imu_mtdata2 import IMU_RATE_HZ, NS_PER_FINE_TICK
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.record import schemas as S
from vdps_hil.record.reader import RawRecord, RecordingReader

__all__ = ["ClockAligner", "DeviceStamper", "Unwrapper", "DecodedRecording", "DecodeError", "decode_recording",
           "raw_copier", "copy_raw_topics", "IMU_FORMATS", "NMEA_FORMATS"]

IMU_FORMATS = ("xsens-mtdata2", "imu")
NMEA_FORMATS = ("nmea",)
DEFAULT_NMEA_BAUD = 115_200
DAY_NS = 86_400 * 1_000_000_000
_COUNTER_MOD = 1 << 16


class DecodeError(ValueError):
    """Decoding cannot start (a bad signal map or DBC, an unreadable file): one line."""


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


_IMU_PACKET_BYTES = 47  # PacketCounter + SampleTimeFine + float32 acc + gyro (codecs.imu_mtdata2)


class _ImuStream:
    """One MTi device: decoder + clock alignment (module docstring)."""

    def __init__(self, device: str, baud: int, device_time: bool, rate_hz: float):
        self.device = device
        self.baud = baud
        self.dec = ImuDecoder(device, baud=baud)
        self.device_time = device_time
        self.stamper = DeviceStamper(ClockAligner(jump_s=0.02, confirm_s=0.2))
        self.counter_stamper = DeviceStamper(ClockAligner(jump_s=0.02, confirm_s=0.2))
        self._stf = Unwrapper(1 << 32)
        self._cnt = Unwrapper(_COUNTER_MOD)
        self.period_ns = int(round(1e9 / rate_hz))
        self.wire_ns = transmission_time_ns(_IMU_PACKET_BYTES, baud)
        self.no_device_time = 0

    def feed(self, t_ns: int, data: bytes | None) -> list[Sample]:
        dec = self.dec
        msgs = dec.feed_messages(t_ns, data) if data is not None else dec.flush_messages()
        if not self.device_time:
            return dec.samples(msgs)
        by_stf, by_cnt, plain = [], [], []
        wire = self.wire_ns
        for m in msgs:
            pkt = m[2]
            if pkt.sample_time_fine is not None:
                by_stf.append((m, m[0] - wire, self._stf(pkt.sample_time_fine) * NS_PER_FINE_TICK))
            elif pkt.packet_counter is not None:
                by_cnt.append((m, m[0] - wire, self._cnt(pkt.packet_counter) * self.period_ns))
            else:
                plain.append(m)
        self.no_device_time += len(plain)
        res = dec.samples(plain)
        if by_stf:
            res += dec.samples(*self.stamper.times(by_stf))
        if by_cnt:
            res += dec.samples(*self.counter_stamper.times(by_cnt))
        if data is None:
            res += dec.samples(self.stamper.release() + self.counter_stamper.release())
        return res

    def counters(self) -> dict:
        return dict(self.dec.counters)

    def clock_status(self) -> dict:
        d = self.stamper.status()
        d["no_device_time"] = self.no_device_time
        if self.counter_stamper.clock.observations:
            d["counter_clock"] = self.counter_stamper.status()
        return d

    def rejected(self) -> int:
        return int(self.dec.counters["rejected"])


class _NmeaStream:
    """One NMEA device: line framer + decoder + UTC alignment (module docstring)."""

    def __init__(self, device: str, baud: int, device_time: bool):
        self.device = device
        self.baud = baud
        self.framer = LineFramer(baud)
        self.dec = NmeaDecoder(device)
        self.device_time = device_time
        self.stamper = DeviceStamper(ClockAligner(jump_s=0.1, confirm_s=0.4))
        self._utc = Unwrapper(DAY_NS)
        self.byte_ns = BITS_PER_BYTE_8N1 * 1e9 / baud
        self.no_device_time = 0

    def feed(self, t_ns: int, data: bytes | None) -> list[Sample]:
        if data is None:
            self.framer.flush()  # a partial line at the end is not a sentence
            return self.stamper.flush()
        out = []
        for t_line, line in self.framer.feed(t_ns, data):
            got = self.dec.feed_line(t_line, line)
            if not got:
                continue
            s = got[0]
            utc = self.dec.last.utc_time_s if self.dec.last is not None else None
            if not self.device_time:
                out.append(s)
            elif utc is None or not math.isfinite(utc):
                self.no_device_time += 1
                out.append(s)
            else:
                n = len(line) + 2 - self.dec.last.skipped_prefix  # the sentence + CR LF on the wire
                t_start = t_line - int(round(n * self.byte_ns))
                out += self.stamper.stamp(((s, t_start, self._utc(int(round(utc * 1e9)))),))
        return out

    def counters(self) -> dict:
        d = dict(self.dec.counters)
        d.update({f"framer_{k}": v for k, v in self.framer.counters.items()})
        return d

    def clock_status(self) -> dict:
        d = self.stamper.status()
        d["no_device_time"] = self.no_device_time
        return d

    def rejected(self) -> int:
        return int(self.dec.counters["rejected"]) + int(self.framer.counters["overflows"])


_FAST_CAN = re.compile(rb'"arbitration_id":(\d+),"is_extended_id":(true|false),"is_fd":false,'
                       rb'"is_remote_frame":false,"is_error_frame":false,"dlc":\d+,"data_hex":"([0-9a-f]*)"')
"""The raw CAN document as ``RecordingWriter`` writes a classic data frame (fixed key order):
read without building a dict; anything else goes through ``json.loads``."""


class _CanStream:
    def __init__(self, bus: str, decoder, info: dict):
        self.bus = bus
        self.dec = decoder
        self._decode_frame = getattr(decoder, "decode_frame", decoder.decode)  # typed fields: no conversions
        self.info = info
        self.malformed = 0

    def feed_raw(self, t_ns: int, data: bytes) -> list[Sample]:
        m = _FAST_CAN.search(data)
        if m is not None:
            aid, ext, hx = m.groups()
            try:
                payload = unhexlify(hx)
            except ValueError:  # binascii.Error: odd length
                payload = None
            if payload is not None:
                return self._decode_frame(t_ns, int(aid), payload, ext == b"true")
        try:
            doc = json.loads(data)
        except ValueError:
            self.malformed += 1
            return []
        return self.feed(t_ns, doc)

    def feed(self, t_ns: int, doc) -> list[Sample]:
        try:
            if doc["is_error_frame"] or doc["is_remote_frame"]:
                self.malformed += 1
                return []
            data = bytes.fromhex(doc["data_hex"])
            return self.dec.decode(t_ns, doc["arbitration_id"], data, bool(doc["is_extended_id"]))
        except (KeyError, TypeError, ValueError):
            self.malformed += 1
            return []

    def counters(self) -> dict:
        c = self.dec.counters
        out = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in c.items()}
        out["raw_malformed"] = self.malformed
        return out

    def rejected(self) -> int:
        n = self.malformed
        tr = getattr(self.dec, "total_rejected", None)
        if tr is not None:
            return n + int(tr)
        c = self.dec.counters
        return n + sum(int(c.get(k, 0)) for k in ("undecodable", "checksum_mismatch", "counter_jump",
                                                   "dlc_mismatch", "missing_signal"))


class DecodedRecording:
    """Iterator of decoded :class:`Sample` objects of one recording (module docstring).

    Iterate once; ``counters`` and ``rejected()`` are live and complete after the end.
    ``raw_sink(record)`` (optional) receives every ``/raw/`` :class:`RawRecord` as read."""

    def __init__(self, source: str | os.PathLike | RecordingReader, *, dbc: str | os.PathLike | None = None,
                 signalmap: str | os.PathLike | None = None, bus_map: Mapping[str, str] | None = None,
                 device_time: bool = True, reorder_window_s: float = 1.0, imu_rate_hz: float = IMU_RATE_HZ,
                 raw_sink: Callable[[RawRecord], None] | None = None):
        if dbc is not None and signalmap is None:
            raise DecodeError("--dbc needs --signalmap saying which frames feed which fields "
                              "(see configs/signalmaps/)")
        if not reorder_window_s >= 0:
            raise DecodeError("reorder_window_s must be >= 0")
        self._sigmap = None
        if signalmap is not None:
            from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap

            try:
                self._sigmap = load_signalmap(signalmap)
            except SignalMapError as e:
                raise DecodeError(str(e)) from None
        if isinstance(source, RecordingReader):
            self.reader, self._owns = source, False
        else:
            from vdps_hil.record.reader import RecordingError

            try:
                self.reader, self._owns = RecordingReader(source), True
            except RecordingError as e:
                raise DecodeError(str(e)) from None
        self._dbc = dbc
        self._bus_map = dict(bus_map or {})
        self.device_time = bool(device_time)
        self._window_ns = int(round(reorder_window_s * 1e9))
        self._imu_rate = float(imu_rate_hz)
        self._raw_sink = raw_sink
        self._can: dict[str, _CanStream | None] = {}
        self._serial: dict[str, object | None] = {}
        self._undecoded: dict[str, int] = {}
        self._late = 0
        self._raw_records = 0
        self._emitted = 0
        self.decoding: dict[str, dict] = {}
        try:
            for topic in self.reader.topics():
                if topic.startswith(S.RAW_CAN_PREFIX):
                    self._can_stream(topic[len(S.RAW_CAN_PREFIX):])  # fail early on a bad map/DBC
        except DecodeError:
            self.close()
            raise
        self._it = self._run()

    def close(self) -> None:
        """Close the reader if this object opened it (also done at the end of iteration)."""
        if self._owns:
            self.reader.close()

    # ---------------------------------------------------------------- setup per source
    def _can_stream(self, bus: str) -> _CanStream | None:
        if bus in self._can:
            return self._can[bus]
        from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap
        from vdps_hil.adapters.signalmap_decoder import build_decoder

        sigmap = self._sigmap
        map_bus = self._bus_map.get(bus, bus)
        try:
            if sigmap is None and map_bus == "vdps":
                sigmap = load_signalmap("vdps")
            if sigmap is None:
                dec, info = None, {"decoded": False, "reason": "no signal map for this bus"}
            else:
                dec, info = build_decoder(sigmap, map_bus, self._dbc, source=f"can.{bus}")
                info = dict(info) if dec is not None else \
                    {"decoded": False, "reason": f"signal map {sigmap.name} has no bus {map_bus}"}
        except SignalMapError as e:
            raise DecodeError(str(e)) from None
        if dec is not None:
            info["decoded"] = True
        self.decoding[f"can.{bus}"] = info
        st = _CanStream(bus, dec, info) if dec is not None else None
        self._can[bus] = st
        return st

    def _serial_stream(self, device: str):
        if device in self._serial:
            return self._serial[device]
        baud, fmt = self.reader.serial_config(device)  # the /raw/ channel's own metadata only
        f = (fmt or "").lower()
        if not f:
            f = "imu" if device.lower().startswith("imu") else "nmea"
        st = None
        if f in IMU_FORMATS:
            from vdps_hil.codecs.imu_mtdata2 import DEFAULT_BAUD as IMU_BAUD

            st = _ImuStream(device, baud or IMU_BAUD, self.device_time, self._imu_rate)
        elif f in NMEA_FORMATS:
            st = _NmeaStream(device, baud or DEFAULT_NMEA_BAUD, self.device_time)
        self.decoding[f"serial.{device}"] = ({"decoded": True, "format": f, "baud": st.baud} if st else
                                             {"decoded": False, "reason": f"unknown serial format {fmt!r}"})
        self._serial[device] = st
        return st

    # ---------------------------------------------------------------- iteration
    def __iter__(self) -> Iterator[Sample]:
        return self._it  # the generator itself: a for loop then skips __next__ below

    def __next__(self) -> Sample:
        return next(self._it)

    def _run(self) -> Iterator[Sample]:
        heap: list[tuple[int, int, Sample]] = []
        seq = 0
        newest = -(1 << 62)
        last_out = -(1 << 62)
        loads, b64 = json.loads, base64.b64decode
        push, pop = heapq.heappush, heapq.heappop
        sink = self._raw_sink
        can_pre, ser_pre = S.RAW_CAN_PREFIX, S.RAW_SERIAL_PREFIX
        ncan, nser = len(can_pre), len(ser_pre)
        can_feed: dict = {}  # topic -> the CAN stream's feed_raw (None: undecoded)
        try:
            for rec in self.reader.iter_records(prefixes=(S.RAW_PREFIX,)):
                self._raw_records += 1
                if sink is not None:
                    sink(rec)
                topic, t = rec.topic, rec.t_ns
                out = ()
                feed = can_feed.get(topic, False)
                if feed is not False or topic.startswith(can_pre):
                    if feed is False:
                        st = self._can_stream(topic[ncan:])
                        feed = can_feed[topic] = None if st is None else st.feed_raw
                    if feed is None:
                        self._undecoded[topic] = self._undecoded.get(topic, 0) + 1
                    else:
                        out = feed(t, rec.data)
                elif topic.startswith(ser_pre):
                    st = self._serial_stream(topic[nser:])
                    if st is None:
                        self._undecoded[topic] = self._undecoded.get(topic, 0) + 1
                    else:
                        try:
                            data = b64(loads(rec.data)["data_b64"], validate=True)
                        except (ValueError, KeyError, TypeError):
                            self._undecoded[topic] = self._undecoded.get(topic, 0) + 1
                            continue
                        out = st.feed(t, data)
                else:
                    self._undecoded[topic] = self._undecoded.get(topic, 0) + 1
                for s in out:
                    push(heap, (s.t_ns, seq, s))
                    seq += 1
                if t > newest:
                    newest = t
                limit = newest - self._window_ns
                while heap and heap[0][0] <= limit:
                    ts, _, s = pop(heap)
                    if ts < last_out:
                        self._late += 1
                    else:
                        last_out = ts
                    self._emitted += 1
                    yield s
            for st in self._serial.values():  # end of the recording: release what is held
                if st is not None:
                    for s in st.feed(newest, None):
                        push(heap, (s.t_ns, seq, s))
                        seq += 1
            while heap:
                ts, _, s = pop(heap)
                if ts < last_out:
                    self._late += 1
                else:
                    last_out = ts
                self._emitted += 1
                yield s
        finally:
            if self._owns:
                self.reader.close()

    # ---------------------------------------------------------------- health
    @property
    def counters(self) -> dict:
        out: dict = {}
        for bus, st in self._can.items():
            if st is not None:
                out[f"can.{bus}"] = st.counters()
        for dev, st in self._serial.items():
            if st is not None:
                out[f"serial.{dev}"] = st.counters()
                out[f"clock.{dev}"] = st.clock_status()
        out["reader"] = {"raw_records": self._raw_records, "samples": self._emitted, "late": self._late,
                         "undecodable_raw": self.reader.rejected, "undecoded": dict(self._undecoded),
                         "problems": list(self.reader.problems)}
        return out

    def rejected(self) -> dict[str, int]:
        """Rejected frames/messages per source (decoder rejects, malformed raw records)."""
        out = {}
        for bus, st in self._can.items():
            if st is not None:
                out[f"can.{bus}"] = st.rejected()
        for dev, st in self._serial.items():
            if st is not None:
                out[f"serial.{dev}"] = st.rejected()
        return out


def decode_recording(source: str | os.PathLike | RecordingReader, *, dbc: str | os.PathLike | None = None,
                     signalmap: str | os.PathLike | None = None, bus_map: Mapping[str, str] | None = None,
                     **kw) -> DecodedRecording:
    """The decoded ``/raw/`` samples of a recording in ``t_ns`` order (module docstring); the
    returned iterator carries the decode counters. Raises :class:`DecodeError` (one line)."""
    return DecodedRecording(source, dbc=dbc, signalmap=signalmap, bus_map=bus_map, **kw)


def raw_copier(reader: RecordingReader, writer) -> Callable[[RawRecord], None]:
    """A ``raw_sink`` writing each ``/raw/`` record unchanged (same bytes, ``t_ns``, ``log_time``
    and channel metadata) to ``writer`` (a :class:`~vdps_hil.record.writer.RecordingWriter`;
    its :meth:`~vdps_hil.record.writer.RecordingWriter.copier` queues the records and writes
    them in runs per channel)."""
    schemas = {S.RAW_CAN_PREFIX: S.RAW_CAN, S.RAW_SERIAL_PREFIX: S.RAW_SERIAL}

    def channel_of(topic: str) -> tuple[str, dict] | None:
        schema = next((v for k, v in schemas.items() if topic.startswith(k)), None)
        return None if schema is None else (schema, reader.channel_metadata(topic))

    return writer.copier(channel_of)


def copy_raw_topics(source: str | os.PathLike, target: str | os.PathLike) -> int:
    """Write a new recording holding only the ``/raw/`` topics of ``source`` (no truth, no
    decoded samples, no metadata but the writer's own); returns the records copied."""
    from vdps_hil.record.writer import RecordingWriter

    with RecordingReader(source) as reader, RecordingWriter(target, metadata={"source": "raw copy"}) as w:
        sink = raw_copier(reader, w)
        n = 0
        for rec in reader.iter_records(prefixes=(S.RAW_PREFIX,)):
            sink(rec)
            n += 1
    return n
