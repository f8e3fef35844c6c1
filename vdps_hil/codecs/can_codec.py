"""CAN codec for the vdps chassis bus (``dbc/vdps.dbc``): encoders, a counting decoder, the
DBC quantisation and the bus load.

The DBC is read with cantools (never parsed by hand here), through the JSON cache of
``codecs.dbc_cache``: decoding a recording needs neither cantools nor python-can once the DBC
has been parsed (cantools is imported by the encoders and for layouts that do not compile).
This module adds what a DBC cannot say: which catalogue fields a frame carries, the
rolling-counter and CRC rules, and how the simulator reproduces the wire quantisation exactly.

Signal scaling (DBC linear conversion)
--------------------------------------
::

    raw   = clamp(floor((x - offset) / scale + 1/2), raw_min, raw_max)      (encode)
    x_hat = raw * scale + offset                                          (decode)
    |x_hat - x| <= scale / 2     for  minimum <= x <= maximum

``raw_min = ceil((minimum - offset) / scale)``, ``raw_max = floor((maximum - offset) / scale)``
(the DBC range, itself inside the bit width). Encoders **clamp** a value outside the DBC range
to the range (a sensor saturates) and raise ``ValueError`` on NaN; :func:`quantize` returns
exactly ``decode(encode(x))``. The decoder **rejects** (counts, never raises) a frame whose
raw value lies outside ``[raw_min, raw_max]``.

================  =====================================  ============
symbol            meaning                                unit
================  =====================================  ============
x, x_hat          physical value, decoded value          field's unit
scale, offset     DBC factor and offset                  field's unit
raw               integer on the wire                    1
n                 data length code (payload bytes)       byte
C                 frame length on the wire               bit
f                 message rate                           Hz
R                 bit rate (1 Mbit/s)                    bit/s
U                 bus load                               1
================  =====================================  ============

Messages (classic CAN 2.0A, 11-bit IDs, Intel byte order, 1 Mbit/s)
-------------------------------------------------------------------
=====  ======================  ========================  ===  ==========================================
ID     name                    rate                      DLC  signals (start|length, scale, range)
=====  ======================  ========================  ===  ==========================================
0x080  VDPS_Warning            50 Hz + on level change   8    war  ning_crc 0|8; warning_counter 8|4;
                                                              warning_level 12|2 (0..3);
                                                              warning_status 14|2 (0..3);
                                                              warning_time_to_rollover_s 16|16 u
                                                              0.001 s, 0..65.534, raw 65535 = none;
                                                              warning_peak_roll_rad 32|16 s 1e-4,
                                                              +-3.1416; warning_ltr 48|16 s 1e-4, +-1
0x100  VDPS_WheelSpeedFront    1 kHz (Table 1)           5    whe  el_speed_radps_1,2 0|16, 16|16 s 0.01
                                                              rad/s, -327.68..327.67; seq_counter 32|8
0x101  VDPS_WheelSpeedRear     1 kHz (Table 1)           5    whe  el_speed_radps_3,4 (as front)
0x110  VDPS_Suspension         1 Hz (Table 1) or 1 kHz   8    sus  p_deflection_m_1..4 0|14, 14|14,
                               (profile table1-susp1k)        28|14, 42|14 s 2e-5 m, -0.16384..0.16382;
                                                              seq_counter 56|8
0x120  VDPS_WheelTorque        100 Hz (our choice)       8    whe  el_torque_nm_1..4 0|14 .. 42|14 s
                                                              1 N m, -8192..8191; seq_counter 56|8
0x130  VDPS_SteerAngle         100 Hz (our choice)       3    ste  er_wheel_angle_rad 0|16 s 0.001 rad,
                                                              -12.567..12.567 (+-4 pi); seq_counter 16|8
=====  ======================  ========================  ===  ==========================================

Resolutions against Table 1 noise: wheel speed 0.01 rad/s = 0.57 deg/s (noise 2 deg/s; the
quantisation error's standard deviation 0.01/sqrt(12) = 0.0029 rad/s adds 0.7 % to the noise
variance); suspension 0.02 mm (noise 1 mm). Wheel speeds are split over two frames so each
frame has room for the 8-bit counter at 0.01 rad/s.

Sequence counters and VDPS_Warning protection
---------------------------------------------
Every frame carries a rolling counter (8 bits ``seq_counter`` on sensor frames, 4 bits
``warning_counter`` on the warning), +1 per frame. Per message the decoder computes
``delta = (c - c_last) mod 2^bits``:

* sensor frames: ``delta = 0`` -> reject (``counter_repeat``: duplicated or stale frame);
  ``delta >= 1`` -> accept, ``lost_frames += delta - 1``. Once the frame period T has been
  learned (running mean of the gaps between consecutive frames), a gap dt longer than half a
  counter cycle is unwrapped: ``delta += 2^bits * round((dt / T - delta) / 2^bits)``, so a
  silence of several wraps is still counted frame by frame.
* VDPS_Warning (AUTOSAR-E2E-like): ``warning_crc`` (byte 0) must equal CRC-8/SAE-J1850 of bytes
  1..7, else reject (``crc_mismatch``; the counter of a corrupted frame is not trusted and not
  stored). Then ``delta = 0`` -> reject (``counter_repeat``); ``1 <= delta <= 3`` -> accept,
  ``lost_frames += delta - 1``; ``delta > 3`` -> reject (``counter_jump``), resynchronise on
  this counter, ``lost_frames += delta - 1`` (a lower bound).
* CRC-8/SAE-J1850: poly x^8+x^4+x^3+x^2+1 (0x1D), init 0xFF, no reflection, xorout 0xFF;
  check value over ASCII ``123456789`` = 0x4B (SAE J1850, AUTOSAR SWS CRC Library
  ``Crc_CalculateCRC8``, reveng catalogue CRC-8/SAE-J1850). Over the 8-byte frame it detects
  every 1- and 2-bit error (exhaustively tested); other corruptions pass with probability
  about 1/256 (3-bit errors: 198 of 41,664 patterns), so the counter and range checks stay.

Other rejects, each counted per message: ``dlc_mismatch`` (payload length != DBC DLC),
``out_of_range`` (raw outside the DBC range), ``undecodable`` (cantools could not decode).
Frames with an unknown ID are counted under ``bus/unknown_id`` (11-bit) or
``bus/unknown_id_extended`` (29-bit, none are defined); arguments that are not an ID/bytes
count as ``bus/malformed``.

Bus load (Table 1 rates, 1 Mbit/s)
----------------------------------
Frame length of a classic CAN frame with an 11-bit ID and n data bytes (SOF..CRC = 34 + 8n
bits are subject to stuffing, then CRC delimiter, ACK, EOF and 3 bits of intermission)::

    C_none  = 47 + 8 n                                   (no stuff bits)
    C_worst = 47 + 8 n + floor((34 + 8 n - 1) / 4)       (Davis, Burns, Bril, Lukkien 2007,
                                                          Real-Time Systems 35(3), eq. 2)
    U = sum_i f_i C_i / R

Typical: stuff bits counted exactly (:func:`frame_bits_stuffed`, CRC-15 included) on frames
carrying a 90 km/h drive of the paper's scenario (``tools/busload.py`` prints the table).
Warning frames sent on a level change add at most a few frames per event (not included).

==========================  ==============  =====================  =========  ==============
message (DLC n)             rate            C none / typ / worst   U table1   U table1-susp1k
                                            [bit]                  (worst)    (worst)
==========================  ==============  =====================  =========  ==============
0x080 VDPS_Warning (8)      50 Hz           111 / 120.6 / 135      0.68 %     0.68 %
0x100 VDPS_WheelSpeedFront  1000 Hz         87 / 92.4 / 105        10.50 %    10.50 %
0x101 VDPS_WheelSpeedRear   1000 Hz         87 / 91.3 / 105        10.50 %    10.50 %
0x110 VDPS_Suspension (8)   1 Hz / 1000 Hz  111 / 117.1 / 135      0.01 %     13.50 %
0x120 VDPS_WheelTorque (8)  100 Hz          111 / 117.2 / 135      1.35 %     1.35 %
0x130 VDPS_SteerAngle (3)   100 Hz          71 / 74.2 / 85         0.85 %     0.85 %
total, worst case                                                  23.89 %    37.38 %
total, typical (stuffed)                                           20.90 %    32.60 %
total, no stuff bits                                               19.79 %    30.87 %
==========================  ==============  =====================  =========  ==============

Even in the worst case with the suspension at 1 kHz the bus stays below 40 %, leaving room
for an IMU cluster or a car's own traffic on the same 1 Mbit/s bus.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Iterable, Mapping, Sequence

import numpy as np

from vdps_hil.bus.samples import FIELDS, Sample
from vdps_hil.codecs.dbc_cache import DbcDescription, load_description

if TYPE_CHECKING:
    import can

DEFAULT_DBC_PATH = Path(__file__).resolve().parents[2] / "dbc" / "vdps.dbc"
"""The repository's chassis DBC (``dbc/vdps.dbc``)."""

DEFAULT_SOURCE = "can.vdps"

# --- message names and IDs (checked against the DBC at load time) ---
WARNING = "VDPS_Warning"
WHEEL_SPEED_FRONT = "VDPS_WheelSpeedFront"
WHEEL_SPEED_REAR = "VDPS_WheelSpeedRear"
SUSPENSION = "VDPS_Suspension"
WHEEL_TORQUE = "VDPS_WheelTorque"
STEER = "VDPS_SteerAngle"

SEQ_COUNTER = "seq_counter"
WARNING_COUNTER = "warning_counter"
WARNING_CRC = "warning_crc"
TTR_FIELD = "warning_time_to_rollover_s"
TTR_NONE_RAW = 65535
"""Raw ``warning_time_to_rollover_s`` meaning "no rollover predicted" (decodes to +inf)."""

WARNING_MAX_DELTA_COUNTER = 3
"""Largest accepted warning counter step (2 frames lost); larger jumps are rejected."""

RATE_PROFILES: dict[str, dict[str, float]] = {
    "table1": {WARNING: 50.0, WHEEL_SPEED_FRONT: 1000.0, WHEEL_SPEED_REAR: 1000.0,
               SUSPENSION: 1.0, WHEEL_TORQUE: 100.0, STEER: 100.0},
    "table1-susp1k": {WARNING: 50.0, WHEEL_SPEED_FRONT: 1000.0, WHEEL_SPEED_REAR: 1000.0,
                      SUSPENSION: 1000.0, WHEEL_TORQUE: 100.0, STEER: 100.0},
}
"""Message rates [Hz] of the two sensor profiles (Table 1; torque, steer, warning our choice)."""

REJECT_REASONS = ("dlc_mismatch", "undecodable", "out_of_range", "crc_mismatch",
                  "counter_repeat", "counter_jump")
"""Per-message reject counters (each rejected frame increments exactly one)."""


class DbcError(ValueError):
    """The DBC cannot be used by this codec (one-line message naming the file and the problem)."""


# ---------------------------------------------------------------------------------------------
# CRC-8/SAE-J1850
# ---------------------------------------------------------------------------------------------
CRC8_POLY = 0x1D
CRC8_INIT = 0xFF
CRC8_XOROUT = 0xFF


def _crc8_table(poly: int) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        reg = byte
        for _ in range(8):
            reg = ((reg << 1) ^ poly) & 0xFF if reg & 0x80 else (reg << 1) & 0xFF
        table.append(reg)
    return tuple(table)


_CRC8_TABLE = _crc8_table(CRC8_POLY)


def crc8_j1850(data: bytes | bytearray | memoryview) -> int:
    """CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, MSB first, xorout 0xFF); ``b"123456789"`` -> 0x4B."""
    reg = CRC8_INIT
    for b in bytes(data):
        reg = _CRC8_TABLE[reg ^ b]
    return reg ^ CRC8_XOROUT


# ---------------------------------------------------------------------------------------------
# The DBC as this codec sees it
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class SignalSpec:
    """One DBC signal with the integer range the codec enforces."""

    name: str
    start_bit: int
    length_bits: int
    is_signed: bool
    scale: float
    offset: float
    minimum: float
    maximum: float
    raw_min: int
    raw_max: int
    unit: str
    signal: object  # the codecs.dbc_cache SignalDescription

    @property
    def resolution(self) -> float:
        return abs(self.scale)


@dataclass(frozen=True, slots=True)
class MessageSpec:
    """One DBC message: ID, DLC, Sample kind, rate and its value/counter/CRC signals."""

    name: str
    frame_id: int
    dlc: int
    kind: str
    cycle_time_ms: int | None
    values: tuple[SignalSpec, ...]  # catalogue fields carried (counter and CRC excluded)
    counter: SignalSpec
    crc: SignalSpec | None
    message: object  # the codecs.dbc_cache MessageDescription (encode/decode: cantools')

    @property
    def field_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.values)


class VdpsDbc:
    """The loaded DBC (its cached description; ``db``: the cantools database, parsed when asked
    for) plus the per-message specs this codec needs.

    ``VdpsDbc(path)`` raises :class:`DbcError` (one line) if the file is unreadable or breaks a
    rule the codec relies on: standard IDs, a ``VdpsKind`` attribute per message, exactly one
    counter signal (``seq_counter`` or ``warning_counter``), value signals named after catalogue
    fields, a CRC signal (if any) filling byte 0, integer signals (no float signals).
    """

    def __init__(self, path: str | Path | None = None):
        self.path = Path(path) if path is not None else DEFAULT_DBC_PATH
        try:
            self.description: DbcDescription = load_description(self.path, strict=True)
        except Exception as e:  # OSError, cantools' several types; one line for the user
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise DbcError(f"{self.path}: cannot load DBC: {msg}") from None
        baud = self.description.attributes.get("Baudrate")
        self.bitrate_bps = int(baud) if baud is not None else 1_000_000
        specs = [self._message_spec(m) for m in self.description.messages]
        self.messages: Mapping[str, MessageSpec] = MappingProxyType({s.name: s for s in specs})
        self.by_id: Mapping[int, MessageSpec] = MappingProxyType({s.frame_id: s for s in specs})
        field_to: dict[str, tuple[MessageSpec, SignalSpec]] = {}
        for spec in specs:
            for sig in spec.values:
                if sig.name in field_to:
                    raise DbcError(f"{self.path}: field {sig.name} carried by two messages")
                field_to[sig.name] = (spec, sig)
        self.field_signal: Mapping[str, tuple[MessageSpec, SignalSpec]] = MappingProxyType(field_to)

    @property
    def db(self):
        """The cantools database (imports cantools and parses the DBC on first use)."""
        return self.description.cantools()

    def _fail(self, what: str):
        raise DbcError(f"{self.path}: {what}")

    def _signal_spec(self, m, s) -> SignalSpec:
        if s.is_float or s.is_multiplexer or s.multiplexer_ids:
            self._fail(f"{m.name}.{s.name}: float and multiplexed signals are not supported")
        scale, offset = float(s.scale), float(s.offset)
        lo_bits = -(1 << (s.length - 1)) if s.is_signed else 0
        hi_bits = (1 << (s.length - 1)) - 1 if s.is_signed else (1 << s.length) - 1
        lo = s.minimum if s.minimum is not None else lo_bits * scale + offset
        hi = s.maximum if s.maximum is not None else hi_bits * scale + offset
        a = (lo - offset) / scale
        b = (hi - offset) / scale
        a, b = min(a, b), max(a, b)
        raw_min = max(lo_bits, math.ceil(a - 1e-9))
        raw_max = min(hi_bits, math.floor(b + 1e-9))
        if raw_min > raw_max:
            self._fail(f"{m.name}.{s.name}: empty range")
        return SignalSpec(s.name, s.start, s.length, s.is_signed, scale, offset, float(lo),
                          float(hi), raw_min, raw_max, s.unit or "", s)

    def _message_spec(self, m) -> MessageSpec:
        if m.is_extended_frame or m.is_fd or m.is_container:
            self._fail(f"{m.name}: only classic CAN frames with 11-bit IDs are supported")
        kind = m.attributes.get("VdpsKind", "")
        if not kind:
            self._fail(f"{m.name}: missing message attribute VdpsKind")
        sigs = [self._signal_spec(m, s) for s in m.signals]
        counters = [s for s in sigs if s.name in (SEQ_COUNTER, WARNING_COUNTER)]
        if len(counters) != 1 or counters[0].is_signed or counters[0].scale != 1.0:
            self._fail(f"{m.name}: needs exactly one unsigned counter signal "
                       f"({SEQ_COUNTER} or {WARNING_COUNTER})")
        crcs = [s for s in sigs if s.name.endswith("_crc")]
        crc = crcs[0] if crcs else None
        if len(crcs) > 1 or (crc and (crc.start_bit, crc.length_bits, crc.is_signed) != (0, 8, False)):
            self._fail(f"{m.name}: a CRC signal must be one unsigned 8-bit signal at bit 0")
        values = tuple(s for s in sigs if s is not counters[0] and s is not crc)
        for s in values:
            if s.name not in FIELDS:
                self._fail(f"{m.name}.{s.name}: not a bus field catalogue name")
        return MessageSpec(m.name, m.frame_id, m.length, str(kind), m.cycle_time, values,
                           counters[0], crc, m)


@lru_cache(maxsize=8)
def _load_cached(path: str) -> VdpsDbc:
    return VdpsDbc(path)


def load_dbc(path: str | Path | None = None) -> VdpsDbc:
    """The codec view of a DBC (cached per resolved path); default ``dbc/vdps.dbc``."""
    return _load_cached(str(Path(path).resolve() if path is not None else DEFAULT_DBC_PATH))


# ---------------------------------------------------------------------------------------------
# Quantisation (shared by encoders, quantize and the decoder)
# ---------------------------------------------------------------------------------------------
def _is_ttr(sig: SignalSpec) -> bool:
    return sig.name == TTR_FIELD


def _to_raw(sig: SignalSpec, value) -> int:
    """Physical value -> clamped raw integer (see the module docstring). NaN -> ValueError."""
    if _is_ttr(sig):
        if value is None or not math.isfinite(value):
            return TTR_NONE_RAW
        if value < 0.0:
            raise ValueError(f"{sig.name} must be >= 0 s or inf/None (no rollover), got {value}")
        v = min(float(value), sig.maximum + sig.scale)  # keeps the division finite
        raw = math.floor((v - sig.offset) / sig.scale + 0.5)
        return TTR_NONE_RAW if raw >= TTR_NONE_RAW else raw
    v = float(value)
    if math.isnan(v):
        raise ValueError(f"{sig.name}: cannot encode NaN")
    lo, hi = _phys_clip(sig)
    raw = math.floor((min(max(v, lo), hi) - sig.offset) / sig.scale + 0.5)
    return min(max(raw, sig.raw_min), sig.raw_max)


def _phys_clip(sig: SignalSpec) -> tuple[float, float]:
    """A physical interval one step wider than the raw range: clipping to it first keeps
    ``(x - offset) / scale`` finite without changing any clamped result."""
    a = sig.raw_min * sig.scale + sig.offset
    b = sig.raw_max * sig.scale + sig.offset
    step = abs(sig.scale)
    return min(a, b) - step, max(a, b) + step


def _from_raw(sig: SignalSpec, raw: int) -> float:
    """Raw integer -> physical value via the DBC conversion (cantools' ``raw_to_scaled``
    arithmetic, ``codecs.dbc_cache``; TTR sentinel -> +inf)."""
    if _is_ttr(sig) and raw == TTR_NONE_RAW:
        return math.inf
    return float(sig.signal.conversion.raw_to_scaled(raw, decode_choices=False))


def quantize(field_name: str, value, dbc: VdpsDbc | None = None):
    """What ``decode(encode(value))`` returns for catalogue field ``field_name``.

    Works on a float or a numpy array (element-wise, same arithmetic). Values outside the DBC
    range come back clamped to it; NaN raises ``ValueError``. For
    ``warning_time_to_rollover_s``, inf/None/>= 65.535 s give inf.
    """
    dbc = dbc or load_dbc()
    try:
        _, sig = dbc.field_signal[field_name]
    except KeyError:
        raise KeyError(f"field {field_name!r} is not carried by {dbc.path.name}") from None
    if isinstance(value, np.ndarray):
        v = np.asarray(value, dtype=float)
        if np.isnan(v).any():
            raise ValueError(f"{field_name}: cannot quantise NaN")
        if _is_ttr(sig):
            return np.array([quantize(field_name, float(x), dbc) for x in v.ravel()]).reshape(v.shape)
        lo, hi = _phys_clip(sig)
        raw = np.clip(np.floor((np.clip(v, lo, hi) - sig.offset) / sig.scale + 0.5),
                      sig.raw_min, sig.raw_max)
        return raw * sig.scale + sig.offset
    return _from_raw(sig, _to_raw(sig, value))


# ---------------------------------------------------------------------------------------------
# Encoders
# ---------------------------------------------------------------------------------------------
def encode_fields(message_name: str, fields: Mapping[str, float], counter: int, *, t_ns: int = 0,
                  dbc: VdpsDbc | None = None) -> can.Message:
    """Encode catalogue ``fields`` (SI values) into message ``message_name`` as a ``can.Message``.

    Every value field of the message must be present (``KeyError`` otherwise); values are
    clamped to the DBC range (NaN -> ``ValueError``). ``counter`` is taken modulo 2^bits. The CRC
    (if the message has one) is computed here. ``timestamp`` = ``t_ns`` / 1e9 s.
    """
    dbc = dbc or load_dbc()
    spec = dbc.messages[message_name]
    raw = {sig.name: _to_raw(sig, fields[sig.name]) for sig in spec.values}
    raw[spec.counter.name] = int(counter) % (1 << spec.counter.length_bits)
    if spec.crc is not None:
        raw[spec.crc.name] = 0
    data = bytearray(spec.message.encode(raw, scaling=False, strict=True))
    if spec.crc is not None:
        data[0] = crc8_j1850(data[1:])
    import can

    return can.Message(timestamp=t_ns / 1e9, arbitration_id=spec.frame_id, is_extended_id=False,
                       dlc=spec.dlc, data=bytes(data))


def encode_wheel_speed_front(wheel_speed_radps_1: float, wheel_speed_radps_2: float, counter: int,
                             *, t_ns: int = 0) -> can.Message:
    return encode_fields(WHEEL_SPEED_FRONT, {"wheel_speed_radps_1": wheel_speed_radps_1,
                                             "wheel_speed_radps_2": wheel_speed_radps_2},
                         counter, t_ns=t_ns)


def encode_wheel_speed_rear(wheel_speed_radps_3: float, wheel_speed_radps_4: float, counter: int,
                            *, t_ns: int = 0) -> can.Message:
    return encode_fields(WHEEL_SPEED_REAR, {"wheel_speed_radps_3": wheel_speed_radps_3,
                                            "wheel_speed_radps_4": wheel_speed_radps_4},
                         counter, t_ns=t_ns)


def _four(name: str, values: Sequence[float]) -> dict[str, float]:
    if len(values) != 4:
        raise ValueError(f"{name}: need 4 values in wheel order FL, FR, RR, RL, got {len(values)}")
    return {f"{name}_{i + 1}": float(v) for i, v in enumerate(values)}


def encode_wheel_speeds(wheel_speed_radps: Sequence[float], counter: int, *, t_ns: int = 0
                        ) -> tuple[can.Message, can.Message]:
    """Four wheel spin rates [rad/s] (FL, FR, RR, RL) -> (front frame, rear frame)."""
    f = _four("wheel_speed_radps", wheel_speed_radps)
    return (encode_fields(WHEEL_SPEED_FRONT, f, counter, t_ns=t_ns),
            encode_fields(WHEEL_SPEED_REAR, f, counter, t_ns=t_ns))


def encode_wheel_torques(wheel_torque_nm: Sequence[float], counter: int, *, t_ns: int = 0
                         ) -> can.Message:
    """Four wheel torques [N m] (FL, FR, RR, RL, positive driving) -> VDPS_WheelTorque."""
    return encode_fields(WHEEL_TORQUE, _four("wheel_torque_nm", wheel_torque_nm), counter, t_ns=t_ns)


def encode_suspension(susp_deflection_m: Sequence[float], counter: int, *, t_ns: int = 0
                      ) -> can.Message:
    """Four suspension deflections [m] (FL, FR, RR, RL, compression positive) -> VDPS_Suspension."""
    return encode_fields(SUSPENSION, _four("susp_deflection_m", susp_deflection_m), counter,
                         t_ns=t_ns)


def encode_steer(steer_wheel_angle_rad: float, counter: int, *, t_ns: int = 0) -> can.Message:
    """Steering wheel angle [rad], positive left -> VDPS_SteerAngle."""
    return encode_fields(STEER, {"steer_wheel_angle_rad": steer_wheel_angle_rad}, counter, t_ns=t_ns)


def encode_warning(level: int, time_to_rollover_s: float | None, peak_roll_rad: float, ltr: float,
                   status: int, counter: int, *, t_ns: int = 0) -> can.Message:
    """VDPS_Warning with CRC-8/SAE-J1850 over bytes 1..7.

    ``level`` and ``status`` must be integers 0..3 (``ValueError`` otherwise);
    ``time_to_rollover_s`` None/inf (or >= 65.535 s) = no rollover predicted, negative ->
    ``ValueError``; ``peak_roll_rad`` clamped to +-3.1416 rad, ``ltr`` to [-1, 1];
    ``counter`` taken modulo 16.
    """
    for name, v in (("level", level), ("status", status)):
        if isinstance(v, bool) or int(v) != v or not 0 <= int(v) <= 3:
            raise ValueError(f"warning {name} must be an integer 0..3, got {v!r}")
    return encode_fields(WARNING, {"warning_level": int(level),
                                   TTR_FIELD: time_to_rollover_s,
                                   "warning_peak_roll_rad": peak_roll_rad,
                                   "warning_ltr": ltr,
                                   "warning_status": int(status)}, counter, t_ns=t_ns)


class VdpsCanEncoder:
    """Keeps one rolling counter per message (as a sender does) and encodes samples.

    ``frames(sample)`` returns one frame per sensor message whose value fields are all in the
    sample (a 4-wheel ``wheel_speed`` sample gives the front and the rear frame), with each
    message's counter advanced by one; ``ValueError`` if the sample fills no message.
    ``warning(...)`` sends VDPS_Warning with its own counter (see :func:`encode_warning`).
    """

    def __init__(self, dbc: VdpsDbc | None = None):
        self._dbc = dbc or load_dbc()
        self._next = {name: 0 for name in self._dbc.messages}

    def frames(self, sample: Sample) -> list[can.Message]:
        out = []
        for name, spec in self._dbc.messages.items():
            if spec.crc is None and all(f in sample.fields for f in spec.field_names):
                out.append(encode_fields(name, sample.fields, self._next[name], t_ns=sample.t_ns,
                                         dbc=self._dbc))
                self._next[name] += 1
        if not out:
            raise ValueError(f"sample of kind {sample.kind!r} fills no sensor message of the DBC")
        return out

    def warning(self, level: int, time_to_rollover_s: float | None, peak_roll_rad: float,
                ltr: float, status: int, *, t_ns: int = 0) -> can.Message:
        msg = encode_warning(level, time_to_rollover_s, peak_roll_rad, ltr, status,
                             self._next[WARNING], t_ns=t_ns)
        self._next[WARNING] += 1
        return msg


# ---------------------------------------------------------------------------------------------
# Decoder
# ---------------------------------------------------------------------------------------------
class _SeqState:
    __slots__ = ("last", "t_ns", "period_ns")

    def __init__(self):
        self.last: int | None = None
        self.t_ns: int | None = None
        self.period_ns: float | None = None


class _DecodePlan:
    """A message's decoding precomputed (``codecs.dbc_compile``; cantools when the layout is not
    compilable): signal indexes of the CRC, counter and ``warning_status``, and per value signal
    (field, index, scale, offset, is the TTR sentinel field); ``checks``: (index, raw_min,
    raw_max) of the value signals whose DBC range is narrower than their bits can hold (the
    compiled raw values lie inside the bits: a full-width range needs no check). The scaled
    value is ``float(raw * scale + offset)`` with the conversion's own scale and offset, which
    is what cantools' ``raw_to_scaled`` computes (:func:`_from_raw`; tested on every raw
    value). ``modulus``: of the rolling counter."""

    __slots__ = ("spec", "compiled", "names", "crc", "counter", "counter_name", "status", "values",
                 "checks", "modulus")

    def __init__(self, spec: MessageSpec):
        from vdps_hil.codecs.dbc_compile import NotCompilable, compile_message

        self.spec = spec

        try:
            self.compiled = compile_message(spec.message)
        except NotCompilable:
            self.compiled = None
        self.names = tuple(s.name for s in spec.message.signals)
        idx = {n: i for i, n in enumerate(self.names)}
        self.crc = idx[spec.crc.name] if spec.crc is not None else -1
        self.counter = idx[spec.counter.name]
        self.counter_name = spec.counter.name
        self.status = idx.get("warning_status", -1) if spec.crc is not None else -1
        self.modulus = 1 << spec.counter.length_bits
        vals, checks = [], []
        for sig in spec.values:
            conv = sig.signal.conversion
            conv = getattr(conv, "_conversion", conv)  # named values: the numeric conversion
            vals.append((sig.name, idx[sig.name], conv.scale, conv.offset, _is_ttr(sig)))
            half = 1 << (sig.length_bits - 1)
            full = (-half, half - 1) if sig.is_signed else (0, 2 * half - 1)
            if self.compiled is None or (sig.raw_min, sig.raw_max) != full:
                checks.append((idx[sig.name], sig.raw_min, sig.raw_max))
        self.values = tuple(vals)
        self.checks = tuple(checks)


class VdpsCanDecoder:
    """Decode chassis frames into :class:`Sample` objects, counting every reject.

    ``decode(t_ns, arbitration_id, data, is_extended_id=False)`` returns ``[Sample]`` for an
    accepted frame and ``[]`` for a rejected one; it never raises on frame content. Samples
    carry catalogue fields (SI) plus ``seq_counter`` (sensor frames) or ``warning_counter``;
    kinds come from the DBC attribute ``VdpsKind`` (``wheel_speed``, ``wheel_torque``,
    ``steer``, ``suspension``, ``warning``). A warning with ``warning_status != 0`` is returned
    with ``valid=False``. Rules and counters: module docstring.
    """

    def __init__(self, dbc_path: str | Path | None = None, *, source: str = DEFAULT_SOURCE,
                 max_delta_counter: int = WARNING_MAX_DELTA_COUNTER):
        self._dbc = load_dbc(dbc_path)
        self._source = source
        self._max_delta = int(max_delta_counter)
        self._by_id = dict(self._dbc.by_id)
        self._bus = {"unknown_id": 0, "unknown_id_extended": 0, "malformed": 0}
        self._counts = {name: dict.fromkeys(("accepted", "lost_frames") + REJECT_REASONS, 0)
                        for name in self._dbc.messages}
        self._seq = {name: _SeqState() for name in self._dbc.messages}
        self._plan = {aid: _DecodePlan(spec) for aid, spec in self._by_id.items()}

    @property
    def dbc(self) -> VdpsDbc:
        return self._dbc

    @property
    def counters(self) -> Mapping[str, Mapping[str, int]]:
        """Read-only snapshot: ``{"bus": {unknown_id, unknown_id_extended, malformed},
        <message name>: {accepted, lost_frames, dlc_mismatch, undecodable, out_of_range,
        crc_mismatch, counter_repeat, counter_jump}}``."""
        snap = {"bus": MappingProxyType(dict(self._bus))}
        snap.update({k: MappingProxyType(dict(v)) for k, v in self._counts.items()})
        return MappingProxyType(snap)

    @property
    def total_rejected(self) -> int:
        """All rejected frames (unknown IDs, malformed and per-message rejects)."""
        return sum(self._bus.values()) + sum(c[r] for c in self._counts.values()
                                             for r in REJECT_REASONS)

    def reset_sequence(self) -> None:
        """Forget the counter history (e.g. after a bus restart); counts are kept."""
        self._seq = {name: _SeqState() for name in self._dbc.messages}

    def decode_message(self, msg: can.Message, t_ns: int | None = None) -> list[Sample]:
        """Decode a python-can message (``t_ns`` defaults to its timestamp)."""
        if msg.is_error_frame or msg.is_remote_frame:
            self._bus["malformed"] += 1
            return []
        t = t_ns if t_ns is not None else int(round(msg.timestamp * 1e9))
        return self.decode(t, msg.arbitration_id, bytes(msg.data[:msg.dlc]), msg.is_extended_id)

    def decode(self, t_ns: int, arbitration_id: int, data: bytes,
               is_extended_id: bool = False) -> list[Sample]:
        try:
            t_ns = int(t_ns)
            aid = int(arbitration_id)
            payload = bytes(data)
        except (TypeError, ValueError, OverflowError):
            self._bus["malformed"] += 1
            return []
        return self.decode_frame(t_ns, aid, payload, bool(is_extended_id))

    def decode_frame(self, t_ns: int, aid: int, payload: bytes, is_extended_id: bool) -> list[Sample]:
        """``decode`` of a frame whose fields already have their types (int, int, bytes, bool),
        e.g. parsed from a recording: no conversions."""
        plan = None if is_extended_id else self._plan.get(aid)
        if plan is None:
            self._bus["unknown_id_extended" if is_extended_id else "unknown_id"] += 1
            return []
        spec = plan.spec
        counts = self._counts[spec.name]
        if len(payload) != spec.dlc:
            counts["dlc_mismatch"] += 1
            return []
        if plan.compiled is not None:
            raw = plan.compiled.raw(payload)
        else:
            try:
                d = spec.message.decode(payload, decode_choices=False, scaling=False)
                raw = [d[n] for n in plan.names]
            except Exception:  # cantools' DecodeError and friends: count, never raise
                counts["undecodable"] += 1
                return []
        if plan.crc >= 0 and crc8_j1850(payload[1:]) != raw[plan.crc]:
            counts["crc_mismatch"] += 1
            return []
        c = raw[plan.counter]
        reason = self._check_counter(plan, c, t_ns, counts)
        if reason is not None:
            counts[reason] += 1
            return []
        for i, lo, hi in plan.checks:
            if not lo <= raw[i] <= hi:
                counts["out_of_range"] += 1
                return []
        fields: dict[str, float] = {}
        for name, i, scale, offset, ttr in plan.values:
            r = raw[i]
            fields[name] = math.inf if ttr and r == TTR_NONE_RAW else float(r * scale + offset)
        fields[plan.counter_name] = float(c)
        counts["accepted"] += 1
        valid = plan.status < 0 or raw[plan.status] == 0
        return [Sample(t_ns, self._source, spec.kind, fields, 0, valid)]  # positional: the hot path

    def _check_counter(self, plan: _DecodePlan, c: int, t_ns: int, counts: dict) -> str | None:
        spec = plan.spec
        st = self._seq[spec.name]
        modulus = plan.modulus
        if st.last is None:
            st.last, st.t_ns = c, t_ns
            return None
        delta = (c - st.last) % modulus
        dt = t_ns - st.t_ns
        if spec.crc is not None:  # E2E-protected: repeat and big jumps are rejected
            if delta == 0:
                return "counter_repeat"
            counts["lost_frames"] += delta - 1
            st.last, st.t_ns = c, t_ns
            return "counter_jump" if delta > self._max_delta else None
        if st.period_ns and dt > 0 and dt / st.period_ns > modulus / 2:
            wraps = round((dt / st.period_ns - delta) / modulus)
            delta += modulus * max(wraps, 0)
        if delta == 0:
            return "counter_repeat"
        if delta == 1 and dt > 0:
            st.period_ns = float(dt) if st.period_ns is None else st.period_ns + (dt - st.period_ns) / 16
        counts["lost_frames"] += delta - 1
        st.last, st.t_ns = c, t_ns
        return None


# ---------------------------------------------------------------------------------------------
# Frame length and bus load
# ---------------------------------------------------------------------------------------------
def frame_bits(dlc: int, *, stuffing: str = "worst") -> int:
    """Bits on the wire of a classic CAN frame with an 11-bit ID and ``dlc`` data bytes,
    interframe space included: ``stuffing="none"`` -> 47 + 8 n, ``"worst"`` -> plus
    floor((34 + 8 n - 1) / 4) stuff bits."""
    if not 0 <= dlc <= 8:
        raise ValueError(f"classic CAN DLC must be 0..8, got {dlc}")
    base = 47 + 8 * dlc
    if stuffing == "none":
        return base
    if stuffing == "worst":
        return base + (34 + 8 * dlc - 1) // 4
    raise ValueError(f"stuffing must be 'none' or 'worst', got {stuffing!r}")


def _can_crc15(bits: Iterable[int]) -> int:
    reg = 0
    for b in bits:
        nxt = b ^ ((reg >> 14) & 1)
        reg = (reg << 1) & 0x7FFF
        if nxt:
            reg ^= 0x4599
    return reg


def frame_bits_stuffed(arbitration_id: int, data: bytes) -> int:
    """Exact bits on the wire (stuff bits counted, interframe space included) of a classic data
    frame with an 11-bit ID: SOF, ID, RTR, IDE, r0, DLC, data and CRC-15 (poly 0x4599) are
    stuffed (a complementary bit after 5 equal bits, the stuff bit starting the next run)."""
    if not 0 <= arbitration_id < 0x800 or len(data) > 8:
        raise ValueError("frame_bits_stuffed: 11-bit ID and at most 8 data bytes")
    bits = [0] + [(arbitration_id >> (10 - i)) & 1 for i in range(11)] + [0, 0, 0]
    bits += [(len(data) >> (3 - i)) & 1 for i in range(4)]
    for byte in data:
        bits += [(byte >> (7 - i)) & 1 for i in range(8)]
    crc = _can_crc15(bits)
    bits += [(crc >> (14 - i)) & 1 for i in range(15)]
    stuff, run, prev = 0, 0, None
    for b in bits:
        if b == prev:
            run += 1
        else:
            prev, run = b, 1
        if run == 5:
            stuff += 1
            prev, run = 1 - b, 1  # the stuff bit (complement) starts the next run
    return len(bits) + 10 + 3 + stuff


def bus_load(rates_hz: Mapping[str, float], *, stuffing: str = "worst",
             dbc: VdpsDbc | None = None, bits_per_frame: Mapping[str, float] | None = None
             ) -> dict[str, float]:
    """Bus load U = sum f_i C_i / R per message and ``"total"`` (fractions of 1).

    ``bits_per_frame`` (message -> C) overrides the formula, e.g. with measured stuffed lengths.
    """
    dbc = dbc or load_dbc()
    out = {}
    for name, f in rates_hz.items():
        c = (bits_per_frame[name] if bits_per_frame is not None
             else frame_bits(dbc.messages[name].dlc, stuffing=stuffing))
        out[name] = f * c / dbc.bitrate_bps
    out["total"] = sum(out.values())
    return out
