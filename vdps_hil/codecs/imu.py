"""IMU wire format: Xsens MTi (100-series, e.g. MTi-300) binary Xbus ``MTData2`` messages.

Device and why
--------------
Table 1 of the paper samples the accelerometer and the gyroscope at 1 kHz. The Xsens MTi 10/100
series outputs calibrated acceleration and rate of turn at up to 2000 Hz and the time-stamp
group (packet counter, sample time) at up to 2000 Hz (MTi User Manual MT0605P, section 4.1.1
"MTData2 output in XBus protocol", table of data outputs with their maximum frequencies), over
RS-232 at up to 921.6 kbit/s, 8N1 (MTi and MTx User Manual MT0100P section 5.7 "Default serial
connection settings": maximum 921600 bps). VectorNav's VN-100/VN-200 run their IMU at 800 Hz
(ImuRate 800 Hz; async outputs are divisors of it), so they cannot give 1 kHz packets.

Message layout (MT Low-Level Communication Protocol, "Xbus message structure" and "MTData2")
-------------------------------------------------------------------------------------------
Big-endian throughout::

    FA | FF | 36 | LEN | DATA[LEN] | CS            (LEN = 0xFF -> LEN_H LEN_L extended length)
    CS: (FF + 36 + LEN + sum(DATA) + CS) mod 256 == 0   (8-bit additive checksum from BID on)
    DATA = packets, each  XDI[2] | SIZE[1] | payload[SIZE]

    XDI 0x1020 PacketCounter   uint16   -> seq_counter (wraps at 65536)
    XDI 0x1060 SampleTimeFine  uint32   device time in 10 kHz ticks (100 us; wraps after 4.97 d)
    XDI 0x4020 Acceleration    3 x float32 [m/s^2], sensor frame: specific force (reads +g on z
                                          when level and at rest)
    XDI 0x8020 RateOfTurn      3 x float32 [rad/s], sensor frame

The low two bits of an XDI select the number format (0 float32, 1 fixed 12.20, 2 fixed 16.32,
3 float64); the decoder reads float32, float64 and 12.20 for acceleration and rate of turn.

Bandwidth at 1 kHz (``link_utilisation``), 10 bits per byte (8N1)::

    bytes/packet = 4 (FA FF 36 LEN) + 5 (counter) + 7 (sample time) + 15 (acc) + 15 (gyro) + 1
                 = 47 B  ->  47 * 10 * 1000 = 470 000 bit/s = 51.0 % of 921 600 bit/s
    VectorNav ASCII $VNIMU (mag, accel, gyro, temp, pressure as printed in the VN-100 manual,
    register 54) = 110 B  ->  1 100 000 bit/s = 119 % of 921 600 bit/s: does not fit.

Axes and mounting
-----------------
The MTi sensor frame S is right-handed and printed on the casing. Mounted with the casing x axis
forward and z up (the documented mounting of this project), S coincides with the bus body frame
(ISO 8855: x forward, y left, z up), so ``SENSOR_TO_BODY`` is the identity. For another mounting
give the signed permutation ``sensor_to_body`` (body = R @ sensor; e.g. upside down with x
forward: ``diag(1, -1, -1)``); the codec converts at the boundary. Small misalignments are the
vehicle file's ``imu_rotation_rpy_rad``, not the codec's.

Receive time
------------
A packet's ``t_ns`` follows the framing rule (``codecs.framing``): chunk time minus the wire time
of the bytes after the packet's last byte in that chunk. The device time (SampleTimeFine) is
kept on ``ImuPacket`` for clock studies; the bus sample carries the packet counter.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping, Sequence

from vdps_hil.bus.samples import Sample, axis_fields, check_fields
from vdps_hil.codecs.framing import BITS_PER_BYTE_8N1, message_time_ns

PREAMBLE = 0xFA
BID_MASTER = 0xFF
MID_MTDATA2 = 0x36
_MTDATA2_START = bytes((PREAMBLE, BID_MASTER, MID_MTDATA2))  # how an MTData2 message begins
MID_ERROR = 0x42

XDI_PACKET_COUNTER = 0x1020
XDI_SAMPLE_TIME_FINE = 0x1060
XDI_ACCELERATION = 0x4020
XDI_RATE_OF_TURN = 0x8020

SAMPLE_TIME_FINE_HZ = 10_000
"""SampleTimeFine tick rate [Hz] (100 us ticks)."""
NS_PER_FINE_TICK = 1_000_000_000 // SAMPLE_TIME_FINE_HZ

MAX_EXTENDED_LEN = 2048
"""Longest DATA an extended-length Xbus message may claim; longer claims are garbage."""

DEFAULT_BAUD = 921_600
IMU_RATE_HZ = 1000

SENSOR_TO_BODY: tuple[tuple[int, int, int], ...] = ((1, 0, 0), (0, 1, 0), (0, 0, 1))
"""Rotation body <- sensor for the documented mounting (casing x forward, z up)."""

F_FIELDS = axis_fields("specific_force_mps2")
W_FIELDS = axis_fields("angular_rate_radps")
check_fields((*F_FIELDS, *W_FIELDS, "seq_counter"))
_FX, _FY, _FZ = F_FIELDS
_WX, _WY, _WZ = W_FIELDS

IMU_REJECT_REASONS: tuple[str, ...] = ("bad_checksum", "bad_length", "malformed_payload",
                                       "unsupported_format", "no_imu_data", "overlapped")


@dataclass(frozen=True)
class ImuPacket:
    """One decoded MTData2 message, in the body frame (after ``sensor_to_body``).

    ``packet_counter``: uint16 or None; ``sample_time_fine``: uint32 10 kHz ticks or None;
    ``specific_force_mps2``, ``angular_rate_radps``: (x, y, z) or None when absent."""

    packet_counter: int | None
    sample_time_fine: int | None
    specific_force_mps2: tuple[float, float, float] | None
    angular_rate_radps: tuple[float, float, float] | None


def _checksum(bid_to_data: bytes) -> int:
    return (-sum(bid_to_data)) & 0xFF


def _xbus_message(mid: int, data: bytes) -> bytes:
    n = len(data)
    if n < 0xFF:
        head = bytes((BID_MASTER, mid, n))
    else:
        head = bytes((BID_MASTER, mid, 0xFF, n >> 8, n & 0xFF))
    body = head + data
    return bytes((PREAMBLE,)) + body + bytes((_checksum(body),))


_VALID_ROTATIONS: set = set()


def _check_rotation(r: Sequence[Sequence[float]]) -> tuple[tuple[int, int, int], ...]:
    """Validate a signed permutation matrix with determinant +1 (a proper axis remap).

    A matrix already validated (as the tuple this returns) is returned at once: the decoder
    passes its validated rotation with every packet."""
    try:
        if r in _VALID_ROTATIONS:
            return r  # type: ignore[return-value]
    except TypeError:  # unhashable (lists): validate below
        pass
    rows = tuple(tuple(int(v) for v in row) for row in r)
    if len(rows) != 3 or any(len(row) != 3 for row in rows):
        raise ValueError("sensor_to_body must be 3x3")
    for row, src in zip(rows, r):
        if any(float(a) != float(b) for a, b in zip(row, src)):
            raise ValueError("sensor_to_body entries must be -1, 0 or 1")
        if sorted(abs(v) for v in row) != [0, 0, 1]:
            raise ValueError("sensor_to_body must be a signed permutation")
    cols = [sorted(abs(rows[i][j]) for i in range(3)) for j in range(3)]
    if any(c != [0, 0, 1] for c in cols):
        raise ValueError("sensor_to_body must be a signed permutation")
    a = rows
    det = (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
           - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
           + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))
    if det != 1:
        raise ValueError("sensor_to_body must be a proper rotation (det +1)")
    _VALID_ROTATIONS.add(rows)
    return rows


def _apply(r, v) -> tuple[float, float, float]:
    """r @ v for a 3x3 r (tuple of rows) and a 3-vector."""
    (a, b, c), (d, e, f), (g, h, i) = r
    x, y, z = v
    return (a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z)


def _apply_t(r, v) -> tuple[float, float, float]:
    """r^T @ v."""
    x, y, z = (r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2] for i in range(3))
    return (x, y, z)


def t_ns_to_sample_time_fine(t_ns: int) -> int:
    """Device time [ns] -> SampleTimeFine ticks (nearest 100 us, modulo 2^32)."""
    return ((int(t_ns) + NS_PER_FINE_TICK // 2) // NS_PER_FINE_TICK) & 0xFFFFFFFF


def encode_imu_packet(t_ns: int, specific_force_mps2: Sequence[float],
                      angular_rate_radps: Sequence[float], seq: int, *,
                      sensor_to_body: Sequence[Sequence[float]] = SENSOR_TO_BODY) -> bytes:
    """One MTData2 message as the MTi sends it: PacketCounter (``seq`` mod 65536),
    SampleTimeFine (``t_ns`` device time in 100 us ticks), Acceleration and RateOfTurn
    (float32, sensor frame = ``sensor_to_body``^T @ body vector). 47 bytes."""
    f = tuple(float(v) for v in specific_force_mps2)
    w = tuple(float(v) for v in angular_rate_radps)
    if len(f) != 3 or len(w) != 3:
        raise ValueError("specific force and angular rate must have 3 components")
    r = _check_rotation(sensor_to_body)
    f_s, w_s = _apply_t(r, f), _apply_t(r, w)
    data = b"".join((
        struct.pack(">HBH", XDI_PACKET_COUNTER, 2, int(seq) & 0xFFFF),
        struct.pack(">HBI", XDI_SAMPLE_TIME_FINE, 4, t_ns_to_sample_time_fine(t_ns)),
        struct.pack(">HB3f", XDI_ACCELERATION, 12, *f_s),
        struct.pack(">HB3f", XDI_RATE_OF_TURN, 12, *w_s),
    ))
    return _xbus_message(MID_MTDATA2, data)


PACKET_BYTES = len(encode_imu_packet(0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0))
"""Bytes per encoded packet (47)."""


def link_utilisation(bytes_per_message: int, rate_hz: float, baud: int,
                     bits_per_byte: int = BITS_PER_BYTE_8N1) -> float:
    """Fraction of the serial line a stream uses: bytes * bits_per_byte * rate / baud."""
    return bytes_per_message * bits_per_byte * rate_hz / baud


def vnimu_ascii_sentence(mag_gauss: Sequence[float], accel_mps2: Sequence[float],
                         gyro_radps: Sequence[float], temp_c: float, pressure_kpa: float) -> bytes:
    """A VectorNav ASCII ``$VNIMU`` line with the field widths of the VN-100 User Manual's
    register 54 example (mag +xx.xxxx, accel +xx.xxx, gyro +xx.xxxxxx, temp +xx.x,
    pressure +xxx.xxx, 8-bit XOR checksum). Used only to show the ASCII output does not fit."""
    parts = ["VNIMU"]
    parts += [f"{v:+08.4f}" for v in mag_gauss]
    parts += [f"{v:+07.3f}" for v in accel_mps2]
    parts += [f"{v:+010.6f}" for v in gyro_radps]
    parts += [f"{temp_c:+05.1f}", f"{pressure_kpa:+08.3f}"]
    body = ",".join(parts)
    cs = 0
    for b in body.encode("ascii"):
        cs ^= b
    return f"${body}*{cs:02X}\r\n".encode("ascii")


class _Bad(Exception):
    def __init__(self, reason: str, detail: str = ""):
        super().__init__(reason, detail)
        self.reason = reason


def _vec3(xdi: int, payload: bytes) -> tuple[float, float, float]:
    fmt = xdi & 0x3
    if fmt == 0 and len(payload) == 12:
        return struct.unpack(">3f", payload)
    if fmt == 3 and len(payload) == 24:
        return struct.unpack(">3d", payload)
    if fmt == 1 and len(payload) == 12:
        x, y, z = (v / float(1 << 20) for v in struct.unpack(">3i", payload))
        return (x, y, z)
    if fmt in (0, 1, 3):
        raise _Bad("malformed_payload", f"XDI {xdi:04X} size {len(payload)}")
    raise _Bad("unsupported_format", f"XDI {xdi:04X}")


_STANDARD = struct.Struct(">HBHHBIHB3fHB3f")
_STANDARD_HEAD = (XDI_PACKET_COUNTER, 2, XDI_SAMPLE_TIME_FINE, 4, XDI_ACCELERATION, 12, XDI_RATE_OF_TURN, 12)
"""PacketCounter, SampleTimeFine, Acceleration and RateOfTurn (float32) in this order: the
general loop below gives the same packet; this reads it with one struct call."""


def decode_mtdata2(data: bytes, sensor_to_body=SENSOR_TO_BODY) -> ImuPacket:
    """Decode the DATA of one MTData2 message (raises ``ValueError`` subclasses on malformed
    payloads; ``ImuDecoder`` turns them into counted rejects). Unknown XDIs are skipped."""
    return _decode_mtdata2(data, _check_rotation(sensor_to_body))


def _decode_mtdata2(data: bytes, r) -> ImuPacket:
    """``decode_mtdata2`` with ``r`` already validated by ``_check_rotation``."""
    if len(data) == _STANDARD.size:  # the layout encode_imu_packet writes: one unpack
        (x1, s1, counter, x2, s2, stf, x3, s3, ax, ay, az, x4, s4, gx, gy, gz) = _STANDARD.unpack(data)
        if (x1, s1, x2, s2, x3, s3, x4, s4) == _STANDARD_HEAD:
            if not math.isfinite(ax + ay + az):  # float32 values: the sum cannot overflow
                raise _Bad("malformed_payload", "non-finite acceleration")
            if not math.isfinite(gx + gy + gz):
                raise _Bad("malformed_payload", "non-finite rate of turn")
            return ImuPacket(counter, stf, _apply(r, (ax, ay, az)), _apply(r, (gx, gy, gz)))
    i, n = 0, len(data)
    counter = stf = None
    acc = gyr = None
    while i < n:
        if i + 3 > n:
            raise _Bad("malformed_payload", "packet header cut")
        xdi = (data[i] << 8) | data[i + 1]
        size = data[i + 2]
        j = i + 3 + size
        if j > n:
            raise _Bad("malformed_payload", f"XDI {xdi:04X} size {size} overruns")
        payload = data[i + 3:j]
        group = xdi & 0xFFF0
        if group == XDI_PACKET_COUNTER:
            if size != 2:
                raise _Bad("malformed_payload", "PacketCounter size")
            counter = struct.unpack(">H", payload)[0]
        elif group == XDI_SAMPLE_TIME_FINE:
            if size != 4:
                raise _Bad("malformed_payload", "SampleTimeFine size")
            stf = struct.unpack(">I", payload)[0]
        elif (xdi & 0xFFF0) == (XDI_ACCELERATION & 0xFFF0):
            acc = _vec3(xdi, payload)
        elif (xdi & 0xFFF0) == (XDI_RATE_OF_TURN & 0xFFF0):
            gyr = _vec3(xdi, payload)
        i = j
    if acc is not None and not all(math.isfinite(v) for v in acc):
        raise _Bad("malformed_payload", "non-finite acceleration")
    if gyr is not None and not all(math.isfinite(v) for v in gyr):
        raise _Bad("malformed_payload", "non-finite rate of turn")
    return ImuPacket(counter, stf, None if acc is None else _apply(r, acc),
                     None if gyr is None else _apply(r, gyr))


class ImuDecoder:
    """Streaming decoder of an MTi byte stream into ``imu`` bus samples.

    ``feed(t_ns, chunk)`` returns the samples of every MTData2 message completed by this chunk,
    each stamped by the receive-time rule at ``baud``. The decoder hunts for ``FA FF``, waits
    for the announced length, checks the checksum, and on any failure advances one byte and
    hunts again, so a valid message next to (or inside the claimed span of) garbage is never
    lost. A message is accepted only if its checksum is right, its payload parses, and no
    valid MTData2 message starts inside its span (the 8-bit checksum passes 1 corrupt span in
    256; a packet cut just before its checksum byte, followed by the next packet, is the
    common case). ``flush()`` at the end of a stream releases what is still held.

    Counters (read-only ``counters``): ``bytes``, ``messages`` (valid MTData2 messages),
    ``samples``, ``other_messages`` (checksum-valid Xbus messages of another kind, not
    consumed), ``garbage_bytes`` (skipped while hunting), ``rejected`` and ``reject_<reason>``
    for ``IMU_REJECT_REASONS``, ``seq_gaps`` (packets missing according to the counter) and
    ``time_backwards`` (chunk times going back).
    """

    def __init__(self, source: str = "imu", *, baud: int = DEFAULT_BAUD,
                 sensor_to_body: Sequence[Sequence[float]] = SENSOR_TO_BODY,
                 bits_per_byte: int = BITS_PER_BYTE_8N1):
        if baud <= 0:
            raise ValueError(f"baud must be positive, got {baud}")
        self.source = source
        self.baud = int(baud)
        self.bits_per_byte = int(bits_per_byte)
        self.sensor_to_body = _check_rotation(sensor_to_body)
        self._buf = bytearray()
        self._base = 0  # stream offset of self._buf[0]
        self._chunk_ends: deque[tuple[int, int]] = deque()  # (stream offset after chunk, t_ns)
        self._last_counter: int | None = None
        self._last_t_ns: int | None = None
        self._counters = {"bytes": 0, "messages": 0, "samples": 0, "other_messages": 0,
                          "garbage_bytes": 0, "rejected": 0, "seq_gaps": 0,
                          "time_backwards": 0}
        for r in IMU_REJECT_REASONS:
            self._counters[f"reject_{r}"] = 0
        self.last_packet: ImuPacket | None = None

    @property
    def counters(self) -> Mapping[str, int]:
        return MappingProxyType(self._counters)

    def _reject(self, reason: str) -> None:
        self._counters["rejected"] += 1
        self._counters[f"reject_{reason}"] += 1

    def feed(self, t_ns: int, chunk: bytes) -> list[Sample]:
        return self.samples(self.feed_messages(t_ns, chunk))

    def flush(self) -> list[Sample]:
        """End of stream: decode what is left, treating headers whose bytes never arrived as
        garbage (so messages held behind a false header are released)."""
        return self.samples(self.flush_messages())

    def feed_messages(self, t_ns: int, chunk: bytes) -> list[tuple[int, dict[str, float], ImuPacket]]:
        """``feed`` before the samples are made: per accepted message ``(receive time [ns], bus
        fields, packet)``, for a caller that stamps the samples by another clock
        (``record.decode``: the device time); :meth:`samples` makes the samples."""
        c = self._counters
        c["bytes"] += len(chunk)
        if self._last_t_ns is not None and t_ns < self._last_t_ns:
            c["time_backwards"] += 1
        self._last_t_ns = t_ns
        self._buf += chunk
        self._chunk_ends.append((self._base + len(self._buf), int(t_ns)))
        return self._run(final=False)

    def flush_messages(self) -> list[tuple[int, dict[str, float], ImuPacket]]:
        """``flush`` as ``feed_messages`` gives its messages."""
        if not self._chunk_ends:
            return []
        return self._run(final=True)

    def samples(self, messages, times=None) -> list[Sample]:
        """The bus samples of ``feed_messages`` output, stamped by the receive-time rule or by
        ``times`` (one per message; None keeps the receive time)."""
        src = self.source
        if times is None:
            return [Sample(t, src, "imu", f) for t, f, _ in messages]  # (t_ns, source, kind, fields)
        return [Sample(t if tt is None else tt, src, "imu", f) for (t, f, _), tt in zip(messages, times)]

    def _run(self, final: bool) -> list[tuple[int, dict[str, float], ImuPacket]]:
        c = self._counters
        buf = self._buf
        r = self.sensor_to_body
        out: list[tuple[int, dict[str, float], ImuPacket]] = []
        i = 0
        n = len(buf)
        while True:
            k = buf.find(PREAMBLE, i)
            if k < 0:
                c["garbage_bytes"] += n - i
                i = n
                break
            c["garbage_bytes"] += k - i
            i = k
            status, mid, head, end = self._probe(buf, i, n)
            if status == "need_more":
                if head:
                    # The header claims bytes not yet here. A valid MTData2 message already
                    # complete inside the claimed span shows the header is false: skip it now
                    # rather than hold good messages back.
                    inner = self._inner_message(buf, i, n, n)
                    if inner > 0:
                        self._reject("overlapped")
                        i = inner
                        continue
                if final:
                    c["garbage_bytes"] += 1
                    i += 1
                    continue
                break
            if status == "not_header":
                c["garbage_bytes"] += 1
                i += 1
                continue
            if status != "ok":
                self._reject(status)
                i += 1
                continue
            if mid != MID_MTDATA2:
                # A checksum-valid message of another kind (an ack, an error) is not consumed:
                # its span is rescanned, so a false header that happens to pass the 8-bit
                # checksum cannot swallow the MTData2 messages inside its claimed length.
                c["other_messages"] += 1
                i += 1
                continue
            try:
                pkt = _decode_mtdata2(buf[i + head:end - 1], r)  # a copy: the buffer moves on
            except _Bad as e:
                self._reject(e.reason)
                i += 1  # same reasoning: never consume a span that does not parse
                continue
            inner = self._inner_message(buf, i, end, n)
            if inner == -1 and not final:
                break  # a header inside this span is not complete yet: decide later
            if inner > 0:
                # A valid MTData2 message starts inside this one's span: this one is a corrupt
                # span that passed the 8-bit checksum by chance (e.g. a packet cut before its
                # checksum byte, followed by the next packet). The inner message wins.
                self._reject("overlapped")
                i = inner
                continue
            c["messages"] += 1
            t_msg = self._time_of_byte(self._base + end - 1)
            i = end
            fields = self._fields(pkt)
            if fields is not None:
                out.append((t_msg, fields, pkt))
        del buf[:i]
        self._base += i
        while len(self._chunk_ends) > 1 and self._chunk_ends[0][0] <= self._base:
            self._chunk_ends.popleft()
        return out

    @staticmethod
    def _probe(buf: bytearray, i: int, n: int) -> tuple[str, int, int, int]:
        """Classify the bytes at ``buf[i]`` (a preamble): ("need_more"|"not_header"|
        "bad_length"|"bad_checksum"|"ok", MID, header length, end index (exclusive))."""
        if n - i < 4:
            return "need_more", 0, 0, 0
        if buf[i + 1] != BID_MASTER:
            return "not_header", 0, 0, 0
        mid, ln, head = buf[i + 2], buf[i + 3], 4
        if ln == 0xFF:
            if n - i < 6:
                return "need_more", mid, 0, 0
            ln, head = (buf[i + 4] << 8) | buf[i + 5], 6
            if ln > MAX_EXTENDED_LEN or ln < 0xFF:
                return "bad_length", mid, head, 0
        end = i + head + ln + 1
        if end > n:
            return "need_more", mid, head, end
        if sum(buf[i + 1:end]) & 0xFF:
            return "bad_checksum", mid, head, end
        return "ok", mid, head, end

    def _inner_message(self, buf: bytearray, i: int, end: int, n: int) -> int:
        """Index of a valid MTData2 message starting inside ``buf[i+1:end]`` (0 if none, -1 if
        one may start there but its bytes have not all arrived)."""
        sig = _MTDATA2_START
        j = buf.find(sig, i + 1, end + 2)
        while 0 <= j < end:
            status, _, head, end_j = self._probe(buf, j, n)
            if status == "need_more":
                return -1
            if status == "ok":
                try:
                    _decode_mtdata2(buf[j + head:end_j - 1], self.sensor_to_body)
                    return j
                except _Bad:
                    pass
            j = buf.find(sig, j + 1, end + 2)
        return 0

    def _time_of_byte(self, pos: int) -> int:
        """Receive-time rule for the byte at stream offset ``pos``: the time of the chunk holding
        it minus the wire time of the bytes after it in that chunk (a message that had to wait
        for later bytes, behind a false header, still gets its own chunk's time)."""
        for end, t_chunk in self._chunk_ends:
            if pos < end:
                return message_time_ns(t_chunk, end - 1 - pos, self.baud, self.bits_per_byte)
        end, t_chunk = self._chunk_ends[-1]
        return message_time_ns(t_chunk, 0, self.baud, self.bits_per_byte)

    def _fields(self, pkt: ImuPacket) -> dict[str, float] | None:
        """The bus fields of a packet (None: rejected, no IMU data); counts gaps and samples."""
        c = self._counters
        if pkt.specific_force_mps2 is None or pkt.angular_rate_radps is None:
            self._reject("no_imu_data")
            return None
        self.last_packet = pkt
        fx, fy, fz = pkt.specific_force_mps2
        wx, wy, wz = pkt.angular_rate_radps
        fields = {_FX: fx, _FY: fy, _FZ: fz, _WX: wx, _WY: wy, _WZ: wz}  # F_FIELDS, W_FIELDS
        if pkt.packet_counter is not None:
            fields["seq_counter"] = float(pkt.packet_counter)
            if self._last_counter is not None:
                gap = (pkt.packet_counter - self._last_counter - 1) & 0xFFFF
                if gap and gap < 0x8000:
                    c["seq_gaps"] += gap
            self._last_counter = pkt.packet_counter
        c["samples"] += 1
        return fields
