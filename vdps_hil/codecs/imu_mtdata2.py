"""One Xsens MTi (100-series, e.g. MTi-300) binary Xbus ``MTData2`` message both ways: the message
layout, ``encode_imu_packet`` (what the MTi sends) and ``decode_mtdata2`` (DATA -> ``ImuPacket``
in the body frame). The byte stream, with its message hunting and receive times, is
``codecs.imu_decoder``.

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
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Sequence

from vdps_hil.codecs.framing import BITS_PER_BYTE_8N1

PREAMBLE = 0xFA
BID_MASTER = 0xFF
MID_MTDATA2 = 0x36
MTDATA2_START = bytes((PREAMBLE, BID_MASTER, MID_MTDATA2))  # how an MTData2 message begins
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


def check_rotation(r: Sequence[Sequence[float]]) -> tuple[tuple[int, int, int], ...]:
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


def apply_transpose(r, v) -> tuple:
    """r^T @ v, term by term (floats, or numpy arrays element-wise: ``sim.wire`` packs whole
    columns with it, so its signed zeros are the encoder's)."""
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
    r = check_rotation(sensor_to_body)
    f_s, w_s = apply_transpose(r, f), apply_transpose(r, w)
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


class MtData2Error(Exception):
    """A malformed MTData2 payload; ``reason`` is one of ``imu_decoder.IMU_REJECT_REASONS``."""

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
        raise MtData2Error("malformed_payload", f"XDI {xdi:04X} size {len(payload)}")
    raise MtData2Error("unsupported_format", f"XDI {xdi:04X}")


_STANDARD = struct.Struct(">HBHHBIHB3fHB3f")
_STANDARD_HEAD = (XDI_PACKET_COUNTER, 2, XDI_SAMPLE_TIME_FINE, 4, XDI_ACCELERATION, 12, XDI_RATE_OF_TURN, 12)
"""PacketCounter, SampleTimeFine, Acceleration and RateOfTurn (float32) in this order: the
general loop below gives the same packet; this reads it with one struct call."""


def decode_mtdata2(data: bytes, sensor_to_body=SENSOR_TO_BODY) -> ImuPacket:
    """Decode the DATA of one MTData2 message (raises ``MtData2Error`` on malformed payloads;
    ``ImuDecoder`` turns them into counted rejects). Unknown XDIs are skipped."""
    return decode_mtdata2_rotated(data, check_rotation(sensor_to_body))


def decode_mtdata2_rotated(data: bytes, r) -> ImuPacket:
    """``decode_mtdata2`` with ``r`` already validated by ``check_rotation``."""
    if len(data) == _STANDARD.size:  # the layout encode_imu_packet writes: one unpack
        (x1, s1, counter, x2, s2, stf, x3, s3, ax, ay, az, x4, s4, gx, gy, gz) = _STANDARD.unpack(data)
        if (x1, s1, x2, s2, x3, s3, x4, s4) == _STANDARD_HEAD:
            if not math.isfinite(ax + ay + az):  # float32 values: the sum cannot overflow
                raise MtData2Error("malformed_payload", "non-finite acceleration")
            if not math.isfinite(gx + gy + gz):
                raise MtData2Error("malformed_payload", "non-finite rate of turn")
            return ImuPacket(counter, stf, _apply(r, (ax, ay, az)), _apply(r, (gx, gy, gz)))
    i, n = 0, len(data)
    counter = stf = None
    acc = gyr = None
    while i < n:
        if i + 3 > n:
            raise MtData2Error("malformed_payload", "packet header cut")
        xdi = (data[i] << 8) | data[i + 1]
        size = data[i + 2]
        j = i + 3 + size
        if j > n:
            raise MtData2Error("malformed_payload", f"XDI {xdi:04X} size {size} overruns")
        payload = data[i + 3:j]
        group = xdi & 0xFFF0
        if group == XDI_PACKET_COUNTER:
            if size != 2:
                raise MtData2Error("malformed_payload", "PacketCounter size")
            counter = struct.unpack(">H", payload)[0]
        elif group == XDI_SAMPLE_TIME_FINE:
            if size != 4:
                raise MtData2Error("malformed_payload", "SampleTimeFine size")
            stf = struct.unpack(">I", payload)[0]
        elif (xdi & 0xFFF0) == (XDI_ACCELERATION & 0xFFF0):
            acc = _vec3(xdi, payload)
        elif (xdi & 0xFFF0) == (XDI_RATE_OF_TURN & 0xFFF0):
            gyr = _vec3(xdi, payload)
        i = j
    if acc is not None and not all(math.isfinite(v) for v in acc):
        raise MtData2Error("malformed_payload", "non-finite acceleration")
    if gyr is not None and not all(math.isfinite(v) for v in gyr):
        raise MtData2Error("malformed_payload", "non-finite rate of turn")
    return ImuPacket(counter, stf, None if acc is None else _apply(r, acc),
                     None if gyr is None else _apply(r, gyr))

