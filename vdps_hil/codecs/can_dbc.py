"""The vdps chassis bus DBC (``dbc/vdps.dbc``) as the CAN codec sees it: message names and IDs,
per message its Sample kind, value signals (catalogue fields), rolling counter and CRC, and per
signal the integer range the codec enforces.

The DBC is read with cantools (never parsed by hand here), through the JSON cache of
``codecs.dbc_cache``: decoding a recording needs neither cantools nor python-can once the DBC
has been parsed (cantools is imported by the encoders and for layouts that do not compile).
The codec adds what a DBC cannot say: which catalogue fields a frame carries, the
rolling-counter and CRC rules (``codecs.can_e2e``), and how the simulator reproduces the wire
quantisation exactly (``codecs.can_encode``). The other modules of the codec:
``codecs.can_decode`` (the counting decoder) and ``codecs.can_busload`` (frame lengths, bus
load).

Messages (layout version 2; classic CAN 2.0A, 11-bit IDs, Intel byte order, 1 Mbit/s)
------------------------------------------------------------------------------------
Every sensor frame: byte 0 ``e2e_crc`` (CRC-8/SAE-J1850 over the data ID = CAN ID, then bytes
1..DLC-1; ``codecs.can_e2e``), bits 8..11 ``seq_counter`` (4 bits), the values after it.

=====  ======================  ========================  ===  ==========================================
ID     name                    rate                      DLC  value signals (start|length, scale, range)
=====  ======================  ========================  ===  ==========================================
0x080  VDPS_Warning            50 Hz + on level change   8    warning_crc 0|8; warning_counter 8|4;
                                                              warning_level 12|2 (0..3);
                                                              warning_status 14|2 (0..3);
                                                              warning_time_to_rollover_s 16|16 u
                                                              0.001 s, 0..65.534, raw 65535 = none;
                                                              warning_peak_roll_rad 32|16 s 1e-4,
                                                              +-3.1416; warning_ltr 48|16 s 1e-4, +-1
0x100  VDPS_WheelSpeedFront    1 kHz (Table 1)           6    wheel_speed_radps_1,2 16|16, 32|16 s
                                                              0.01 rad/s, -327.68..327.67
0x101  VDPS_WheelSpeedRear     1 kHz (Table 1)           6    wheel_speed_radps_3,4 (as front)
0x110  VDPS_Suspension         1 Hz (Table 1) or 1 kHz   8    susp_deflection_m_1..4 12|13, 25|13,
                               (profile table1-susp1k)        38|13, 51|13 s 4e-5 m, -0.16384..0.1638
0x120  VDPS_WheelTorqueFront   100 Hz (our choice)       5    wheel_torque_nm_1,2 12|14, 26|14 s 1 N m,
                                                              -8192..8191
0x121  VDPS_WheelTorqueRear    100 Hz (our choice)       5    wheel_torque_nm_3,4 (as front)
0x130  VDPS_SteerAngle         100 Hz (our choice)       4    steer_wheel_angle_rad 16|16 s 0.001 rad,
                                                              -12.567..12.567 (+-4 pi)
=====  ======================  ========================  ===  ==========================================

Resolutions against Table 1 noise: wheel speed 0.01 rad/s = 0.57 deg/s (noise 2 deg/s; the
quantisation error's standard deviation 0.01/sqrt(12) = 0.0029 rad/s adds 0.7 % to the noise
variance); suspension 0.04 mm (noise 1 mm: adds 0.01 % to the variance); torque 1 N m over
+-8192 N m. Wheel speeds and torques are split over two frames each so that every frame has room
for the CRC and the counter at these resolutions; the two torque frames carry the DBC attribute
``VdpsSampleGroup`` and decode into one sample of four torques (``codecs.can_decode``).

Versions: ``dbc/vdps.dbc`` is layout 2; ``dbc/vdps_v1.dbc`` (no sensor CRC, 8-bit counters, one
torque frame, suspension 2e-5 m) still decodes the recordings made with it: a recording names
the DBC it was made with by content hash (``hash.dbc.vdps``), and :func:`recorded_vdps_dbc` maps
that hash to the shipped version.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

from vdps_hil.bus.samples import FIELDS
from vdps_hil.codecs.dbc_cache import DbcDescription, load_description

DEFAULT_DBC_PATH = Path(__file__).resolve().parents[2] / "dbc" / "vdps.dbc"
"""The repository's chassis DBC (``dbc/vdps.dbc``, layout version 2)."""
LEGACY_DBC_PATHS = (DEFAULT_DBC_PATH.with_name("vdps_v1.dbc"),)
"""Earlier layouts of the chassis bus, kept so that their recordings still decode."""

# --- message names and IDs (checked against the DBC at load time) ---
WARNING = "VDPS_Warning"
WHEEL_SPEED_FRONT = "VDPS_WheelSpeedFront"
WHEEL_SPEED_REAR = "VDPS_WheelSpeedRear"
SUSPENSION = "VDPS_Suspension"
WHEEL_TORQUE_FRONT = "VDPS_WheelTorqueFront"
WHEEL_TORQUE_REAR = "VDPS_WheelTorqueRear"
WHEEL_TORQUE = "VDPS_WheelTorque"
"""The single torque frame of layout 1 (``dbc/vdps_v1.dbc``)."""
STEER = "VDPS_SteerAngle"

SEQ_COUNTER = "seq_counter"
WARNING_COUNTER = "warning_counter"
WARNING_CRC = "warning_crc"
TTR_FIELD = "warning_time_to_rollover_s"
TTR_NONE_RAW = 65535
"""Raw ``warning_time_to_rollover_s`` meaning "no rollover predicted" (decodes to +inf)."""


class DbcError(ValueError):
    """The DBC cannot be used by this codec (one-line message naming the file and the problem)."""


# ---------------------------------------------------------------------------------------------
# The DBC as this codec sees it
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class SignalSpec:
    """One DBC signal with the integer range the codec enforces: ``raw_min = ceil((minimum -
    offset) / scale)``, ``raw_max = floor((maximum - offset) / scale)`` (the DBC range, itself
    inside the bit width)."""

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


def is_ttr(sig: SignalSpec) -> bool:
    """Whether ``sig`` is ``warning_time_to_rollover_s`` (raw ``TTR_NONE_RAW`` = +inf)."""
    return sig.name == TTR_FIELD


@dataclass(frozen=True, slots=True)
class MessageSpec:
    """One DBC message: ID, DLC, Sample kind, rate and its value/counter/CRC signals;
    ``data_id``: the E2E data ID its CRC covers first (the CAN ID for sensor frames with a CRC,
    None for VDPS_Warning and frames without a CRC); ``group``: its ``VdpsSampleGroup`` (the
    messages of one group decode into one sample; "" none)."""

    name: str
    frame_id: int
    dlc: int
    kind: str
    cycle_time_ms: int | None
    values: tuple[SignalSpec, ...]  # catalogue fields carried (counter and CRC excluded)
    counter: SignalSpec
    crc: SignalSpec | None
    message: object  # the codecs.dbc_cache MessageDescription (encode/decode: cantools')
    data_id: int | None = None
    group: str = ""

    @property
    def is_sensor(self) -> bool:
        """A frame the simulator sends (every message but VDPS_Warning)."""
        return self.kind != "warning"

    @property
    def field_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.values)


class VdpsDbc:
    """The loaded DBC (its cached description; ``db``: the cantools database, parsed when asked
    for) plus the per-message specs this codec needs.

    ``VdpsDbc(path)`` raises :class:`DbcError` (one line) if the file is unreadable or breaks a
    rule the codec relies on: standard IDs, a ``VdpsKind`` attribute per message, exactly one
    counter signal (``seq_counter`` or ``warning_counter``), value signals named after catalogue
    fields, a CRC signal (if any) filling byte 0, integer signals (no float signals), 1-8 data
    bytes, and (``codecs.dbc_cache``) finite non-zero scales.
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
        if m.is_extended_frame or m.is_fd or m.is_container or not 1 <= m.length <= 8:
            self._fail(f"{m.name}: only classic CAN frames (11-bit IDs, 1-8 data bytes) are "
                       f"supported (DLC {m.length})")
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
        data_id = m.frame_id if crc is not None and kind != "warning" else None
        return MessageSpec(m.name, m.frame_id, m.length, str(kind), m.cycle_time, values,
                           counters[0], crc, m, data_id, str(m.attributes.get("VdpsSampleGroup", "")))


def recorded_vdps_dbc(metadata: Mapping[str, str]) -> Path | None:
    """The shipped chassis DBC a recording was made with, from its ``vdps.recording`` metadata
    (``hash.dbc.vdps`` = ``sha256:<hex>`` of the DBC's bytes): a legacy layout's path when the
    hash is one of ``LEGACY_DBC_PATHS``, else None (decode with the current layout)."""
    want = str(metadata.get("hash.dbc.vdps", ""))
    return _legacy_by_hash().get(want) if want.startswith("sha256:") else None


@lru_cache(maxsize=1)
def _legacy_by_hash() -> dict[str, Path]:
    """``sha256:<hex>`` of each readable ``LEGACY_DBC_PATHS`` file -> its path (hashed once)."""
    import hashlib

    out = {}
    for p in LEGACY_DBC_PATHS:
        try:
            out["sha256:" + hashlib.sha256(p.read_bytes()).hexdigest()] = p
        except OSError:
            continue
    return out


@lru_cache(maxsize=8)
def _load_cached(path: str) -> VdpsDbc:
    return VdpsDbc(path)


def load_dbc(path: str | Path | None = None) -> VdpsDbc:
    """The codec view of a DBC (cached per resolved path); default ``dbc/vdps.dbc``."""
    return _load_cached(str(Path(path).resolve() if path is not None else DEFAULT_DBC_PATH))
