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
                       CRC and range checks; ``dbc/vdps_v1.dbc`` when the recording names that
                       layout's hash); other buses are counted ``undecoded``.
                       ``signalmap``: every bus the map names (``bus_map`` renames recording
                       buses to map buses) with the map's DBC or ``dbc`` (``build_decoder``).
``/raw/serial/<dev>``  by the channel's ``format``: ``nmea`` -> ``LineFramer`` +
                       ``NmeaDecoder``; ``xsens-mtdata2`` (or ``imu``) -> ``ImuDecoder``; an
                       empty format falls back to the device name (``imu*`` binary, else NMEA);
                       an unknown format is counted ``undecoded``.
=====================  =====================================================================

Sample sources: ``can.<bus>`` (CAN), the device name (serial: ``imu``, ``gnss``).

Time stamps from the devices' own clocks (``device_time=True``, default): each serial device's
own time (the IMU's SampleTimeFine or packet counter, the UTC time of NMEA sentences) is mapped
onto the host clock by a leaky running minimum of host minus device time, which removes the
read-chunk quantisation and the wire time (:mod:`vdps_hil.record.device_clock`); a message
without a device time keeps its receive-time stamp. The per-source decoders are in
:mod:`vdps_hil.record.streams`.

Ordering: decoded samples may be stamped earlier than the raw record that carried them (by the
wire and chunk time, GNSS latency), so they pass a reorder buffer released ``reorder_window_s``
(default 1 s, longer than a clock step takes to confirm) behind the newest raw time: the output
is in ``t_ns`` order (ties in arrival order) and memory is bounded by that window, never the
drive. A sample older than what was
already released is emitted at once and counted ``late``.

CAN in bulk: the raw records are read in runs of ``BATCH_RECORDS``; the CAN frames of a run are
decoded together per bus (``CanStream.feed_many`` -> ``VdpsCanDecoder.decode_many``: one numpy
block per message, ``codecs.can_bulk``) before the run is walked record by record as before, so
the samples, their order and every counter are those of the per-frame path (tested on drives,
faults, malformed frames and the real RAV4 drive, ``tests/test_decode.py``); only the CAN
counters run up to one run ahead of the samples yielded while iterating.

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
import os
from typing import Callable, Iterator, Mapping

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.imu_mtdata2 import IMU_RATE_HZ
from vdps_hil.record import schemas as S
from vdps_hil.record.reader import RawRecord, RecordingReader
from vdps_hil.record.streams import CanStream, ImuStream, NmeaStream

__all__ = ["DecodedRecording", "DecodeError", "decode_recording", "raw_copier", "copy_raw_topics", "IMU_FORMATS",
           "NMEA_FORMATS"]

IMU_FORMATS = ("xsens-mtdata2", "imu")
NMEA_FORMATS = ("nmea",)
DEFAULT_NMEA_BAUD = 115_200
BATCH_RECORDS = 4096
"""Raw records read ahead and decoded together (the CAN frames of a bus in bulk per message)."""
_PER_RECORD = object()  # a record not decoded in bulk: decoded in the walk


class DecodeError(ValueError):
    """Decoding cannot start (a bad signal map or DBC, an unreadable file): one line."""


class DecodedRecording:
    """Iterator of decoded :class:`Sample` objects of one recording (module docstring).

    Iterate once; ``counters`` and ``rejected()`` are live (the CAN ones up to ``BATCH_RECORDS``
    raw records ahead) and complete after the end.
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
        self._can: dict[str, CanStream | None] = {}
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
    def _can_stream(self, bus: str) -> CanStream | None:
        if bus in self._can:
            return self._can[bus]
        from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap
        from vdps_hil.adapters.signalmap_decoder import build_decoder

        sigmap = self._sigmap
        map_bus = self._bus_map.get(bus, bus)
        try:
            if sigmap is None and map_bus == "vdps":
                sigmap = load_signalmap(self._vdps_map_name())
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
        st = CanStream(bus, dec, info) if dec is not None else None
        self._can[bus] = st
        return st

    def _vdps_map_name(self) -> str:
        """``vdps``, or ``vdps_v1`` for a recording made with layout 1 of the chassis bus (the DBC
        hash it names, ``codecs.can_dbc.recorded_vdps_dbc``)."""
        from vdps_hil.codecs.can_dbc import recorded_vdps_dbc

        legacy = self._dbc is None and recorded_vdps_dbc(self.reader.metadata().get(S.METADATA_NAME, {}))
        return "vdps_v1" if legacy else "vdps"

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

            st = ImuStream(device, baud or IMU_BAUD, self.device_time, self._imu_rate)
        elif f in NMEA_FORMATS:
            st = NmeaStream(device, baud or DEFAULT_NMEA_BAUD, self.device_time)
        self.decoding[f"serial.{device}"] = ({"decoded": True, "format": f, "baud": st.baud} if st else
                                             {"decoded": False, "reason": f"unknown serial format {fmt!r}"})
        self._serial[device] = st
        return st

    # ---------------------------------------------------------------- iteration
    def __iter__(self) -> Iterator[Sample]:
        return self._it  # the generator itself: a for loop then skips __next__ below

    def __next__(self) -> Sample:
        return next(self._it)

    def _batches(self) -> Iterator[tuple[list[RawRecord], list]]:
        """The ``/raw/`` records in ``BATCH_RECORDS`` runs, each with what its CAN records of
        buses decoded in bulk gave (``CanStream.feed_many``: a sample or None; ``_PER_RECORD``
        for the other records). An error of the reader is raised after the records read before it."""
        it = self.reader.iter_records(prefixes=(S.RAW_PREFIX,))
        can_pre, ncan = S.RAW_CAN_PREFIX, len(S.RAW_CAN_PREFIX)
        while True:
            batch, error = [], None
            try:
                for rec in it:
                    batch.append(rec)
                    if len(batch) >= BATCH_RECORDS:
                        break
            except Exception as e:  # noqa: BLE001 - raised below, after what was read
                error = e
            per_bus: dict[str, list[int]] = {}
            for i, rec in enumerate(batch):
                if rec.topic.startswith(can_pre):
                    per_bus.setdefault(rec.topic, []).append(i)
            decoded = [_PER_RECORD] * len(batch)
            for topic, idx in per_bus.items():
                st = self._can_stream(topic[ncan:])
                if st is not None and st.bulk:
                    got = st.feed_many([batch[i].t_ns for i in idx], [batch[i].data for i in idx])
                    for i, s in zip(idx, got):
                        decoded[i] = s
            if batch:
                yield batch, decoded
            if error is not None:
                raise error
            if len(batch) < BATCH_RECORDS:
                return

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
            for batch, decoded in self._batches():
                for i, rec in enumerate(batch):
                    self._raw_records += 1
                    if sink is not None:
                        sink(rec)
                    topic, t = rec.topic, rec.t_ns
                    out = decoded[i]
                    if out is not _PER_RECORD:  # a CAN frame decoded in bulk: its sample or None
                        out = () if out is None else (out,)
                    elif topic.startswith(can_pre):  # a bus decoded frame by frame (a signal map's)
                        feed = can_feed.get(topic, False)
                        if feed is False:
                            st = self._can_stream(topic[ncan:])
                            feed = can_feed[topic] = None if st is None else st.feed_raw
                        if feed is None:
                            self._undecoded[topic] = self._undecoded.get(topic, 0) + 1
                            out = ()
                        else:
                            out = feed(t, rec.data)
                    elif topic.startswith(ser_pre):
                        st = self._serial_stream(topic[nser:])
                        out = ()
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
                        out = ()
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
