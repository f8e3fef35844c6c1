"""The decoder of one raw source of a recording: a CAN bus (:class:`CanStream`), an MTi IMU
(:class:`ImuStream`) or an NMEA receiver (:class:`NmeaStream`), each with its device clock
alignment (:mod:`vdps_hil.record.device_clock`); :mod:`vdps_hil.record.decode` feeds them the
``/raw/`` records in ``t_ns`` order."""

from __future__ import annotations

import json
import math
import re
from binascii import unhexlify
from typing import Mapping

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.framing import BITS_PER_BYTE_8N1, LineFramer, transmission_time_ns
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.imu_mtdata2 import NS_PER_FINE_TICK
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.record.device_clock import ClockAligner, DeviceStamper, Unwrapper

__all__ = ["CanStream", "ImuStream", "NmeaStream", "DAY_NS"]

DAY_NS = 86_400 * 1_000_000_000
_COUNTER_MOD = 1 << 16


_IMU_PACKET_BYTES = 47  # PacketCounter + SampleTimeFine + float32 acc + gyro (codecs.imu_mtdata2)


class ImuStream:
    """One MTi device: decoder + clock alignment (:mod:`vdps_hil.record.device_clock`)."""

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


class NmeaStream:
    """One NMEA device: line framer + decoder + UTC alignment (:mod:`vdps_hil.record.device_clock`)."""

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


class CanStream:
    """One CAN bus: ``feed_raw`` (a raw record), ``feed`` (its JSON document) and ``feed_many``
    (records decoded together when the decoder has ``decode_many``), the same samples and counts."""

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
        got = self._from_doc(t_ns, doc, self.dec.decode)
        return [] if got is None else got

    def _from_doc(self, t_ns: int, doc, call):
        """``call(t_ns, id, payload, is_extended_id, **flags)`` of a raw CAN document, or None
        with a malformed document counted."""
        try:
            if doc["is_error_frame"]:
                self.malformed += 1
                return None
            data = bytes.fromhex(doc["data_hex"])
            flags = {k: True for k in ("is_fd", "is_remote_frame") if doc[k]}  # counted rejects
            return call(t_ns, doc["arbitration_id"], data, bool(doc["is_extended_id"]), **flags)
        except (KeyError, TypeError, ValueError):
            self.malformed += 1
            return None

    @property
    def bulk(self) -> bool:
        """Whether the decoder decodes many frames at once (``decode_many``: :meth:`feed_many`)."""
        return hasattr(self.dec, "decode_many")

    def feed_many(self, ts: list[int], datas: list[bytes]) -> list[Sample | None]:
        """``feed_raw(ts[k], datas[k])`` of each record in order, decoded together by the
        decoder's ``decode_many`` (:attr:`bulk`): per record its sample or None, the same
        samples and counters as record by record."""
        frames, skipped = [], []  # skipped: positions of the records with nothing to decode
        search, frame_of = _FAST_CAN.search, self.dec.frame_of
        for k, (t_ns, data) in enumerate(zip(ts, datas)):
            m = search(data)
            if m is not None:
                aid, ext, hx = m.groups()
                try:
                    frames.append((t_ns, int(aid), unhexlify(hx), ext == b"true"))
                    continue
                except ValueError:  # binascii.Error: odd length
                    pass
            try:
                fr = self._from_doc(t_ns, json.loads(data), frame_of)
            except ValueError:
                fr = None
                self.malformed += 1
            if fr is None:
                skipped.append(k)
            else:
                frames.append(fr)
        out = self.dec.decode_many(frames)
        for k in skipped:
            out.insert(k, None)
        return out

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
                                                   "dlc_mismatch", "missing_signal", "remote_frame",
                                                   "fd_mismatch"))

