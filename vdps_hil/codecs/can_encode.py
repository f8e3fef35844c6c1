"""Encoders of the vdps chassis bus (catalogue fields in SI -> payload bytes, :class:`Frame` or
``can.Message``, one rolling counter per message in ``VdpsCanEncoder``) and the DBC quantisation
they share with the simulator (``quantize``: exactly what ``decode(encode(x))`` returns).
Payloads are packed by the message's compiled layout (``codecs.dbc_compile``: cantools'
encoding byte for byte, without importing cantools); python-can is imported only to make a
``can.Message``.

Signal scaling (DBC linear conversion)
--------------------------------------
::

    raw   = clamp(floor((x - offset) / scale + 1/2), raw_min, raw_max)      (encode)
    x_hat = raw * scale + offset                                          (decode)
    |x_hat - x| <= scale / 2     for  minimum <= x <= maximum

``raw_min = ceil((minimum - offset) / scale)``, ``raw_max = floor((maximum - offset) / scale)``
(the DBC range, itself inside the bit width; ``codecs.can_dbc.SignalSpec``). Encoders
**clamp** a value outside the DBC range to the range (a sensor saturates) and raise
``ValueError`` on NaN; :func:`quantize` returns exactly ``decode(encode(x))``. The decoder
(``codecs.can_decode``) **rejects** (counts, never raises) a frame whose raw value lies
outside ``[raw_min, raw_max]``.

================  =====================================  ============
symbol            meaning                                unit
================  =====================================  ============
x, x_hat          physical value, decoded value          field's unit
scale, offset     DBC factor and offset                  field's unit
raw               integer on the wire                    1
================  =====================================  ============

``warning_time_to_rollover_s``: None/inf (or >= 65.535 s) encodes as raw 65535 =
``TTR_NONE_RAW`` ("no rollover predicted", decodes to +inf).
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.can_dbc import (
    STEER, SUSPENSION, TTR_FIELD, TTR_NONE_RAW, WARNING, WHEEL_SPEED_FRONT, WHEEL_SPEED_REAR,
    WHEEL_TORQUE_FRONT, WHEEL_TORQUE_REAR, SignalSpec, VdpsDbc, is_ttr, load_dbc,
)
from vdps_hil.codecs.can_e2e import e2e_crc

if TYPE_CHECKING:
    import can


# ---------------------------------------------------------------------------------------------
# Quantisation (shared by the encoders and quantize)
# ---------------------------------------------------------------------------------------------
def _to_raw(sig: SignalSpec, value) -> int:
    """Physical value -> clamped raw integer (see the module docstring). NaN -> ValueError."""
    if is_ttr(sig):
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
    if is_ttr(sig) and raw == TTR_NONE_RAW:
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
        if is_ttr(sig):
            return np.array([quantize(field_name, float(x), dbc) for x in v.ravel()]).reshape(v.shape)
        lo, hi = _phys_clip(sig)
        raw = np.clip(np.floor((np.clip(v, lo, hi) - sig.offset) / sig.scale + 0.5),
                      sig.raw_min, sig.raw_max)
        return raw * sig.scale + sig.offset
    return _from_raw(sig, _to_raw(sig, value))


# ---------------------------------------------------------------------------------------------
# Encoders
# ---------------------------------------------------------------------------------------------
class Frame:
    """A CAN frame as the encoders make it without python-can (``can.Message``'s attribute names:
    ``timestamp`` [s], ``arbitration_id``, ``is_extended_id``, ``dlc``, ``data``; a classic data
    frame: ``is_fd``, ``is_remote_frame``, ``is_error_frame`` False). The warning
    node returns these: a replay never imports python-can (with asammdf and pandas, about 0.4 s)
    for frames it only writes; :meth:`to_message` makes the ``can.Message`` a bus sends."""

    __slots__ = ("timestamp", "arbitration_id", "is_extended_id", "dlc", "data")
    is_fd = is_remote_frame = is_error_frame = False

    def __init__(self, timestamp: float, arbitration_id: int, dlc: int, data: bytes, is_extended_id: bool = False):
        self.timestamp, self.arbitration_id, self.dlc = timestamp, arbitration_id, dlc
        self.data, self.is_extended_id = data, is_extended_id

    def __repr__(self) -> str:
        return f"Frame(t={self.timestamp:.6f} id=0x{self.arbitration_id:X} data={self.data.hex()})"

    def to_message(self) -> can.Message:
        import can

        return can.Message(timestamp=self.timestamp, arbitration_id=self.arbitration_id,
                           is_extended_id=self.is_extended_id, dlc=self.dlc, data=self.data)


@functools.lru_cache(maxsize=256)
def _compiled(message):
    """The compiled layout of a DBC message description, or None (``codecs.dbc_compile``). The
    descriptions hash by identity; the cache holds them, so an id is never another's."""
    from vdps_hil.codecs.dbc_compile import NotCompilable, compile_message

    try:
        return compile_message(message)
    except NotCompilable:
        return None


def _pack(message, raw: Mapping[str, int]) -> bytes:
    """``message.encode(raw, scaling=False, strict=True)``: by the compiled layout when the
    message compiles, ``raw`` names exactly its signals and every value passes cantools' strict
    range check (``minimum - |scale| 1e-6 <= raw * scale + offset <= maximum + |scale| 1e-6``);
    otherwise (or when a value passes the range but not its bit field) by cantools, which then
    raises its own error (or accepts a value-table entry outside the range, a check the cached
    description cannot make)."""
    comp = _compiled(message)
    if comp is not None and len(raw) == len(comp.names):
        try:
            vals = [raw[n] for n in comp.names]
        except KeyError:
            vals = None
        if vals is not None and all(map(_in_range, message.signals, vals)):
            try:
                return comp.pack(vals)
            except ValueError:  # a range wider than the bit field: cantools' own error
                pass
    return bytes(message.encode(dict(raw), scaling=False, strict=True))


def _in_range(signal, raw) -> bool:
    conv = signal.conversion
    x = conv.raw_to_scaled(raw, decode_choices=False)
    tol = abs(conv.scale) * 1e-6
    return ((signal.minimum is None or x >= signal.minimum - tol)
            and (signal.maximum is None or x <= signal.maximum + tol))


def pack_fields(message_name: str, fields: Mapping[str, float], counter: int, *,
                dbc: VdpsDbc | None = None) -> bytes:
    """The payload of message ``message_name`` for catalogue ``fields`` (SI values): every value
    field of the message must be present (``KeyError`` otherwise); values are clamped to the
    DBC range (NaN -> ``ValueError``); ``counter`` is taken modulo 2^bits; the CRC (if the
    message has one) is computed here. Packed by the compiled layout (``codecs.dbc_compile``),
    byte for byte what cantools' encoder writes (tested), without importing cantools."""
    dbc = dbc or load_dbc()
    spec = dbc.messages[message_name]
    raw = {sig.name: _to_raw(sig, fields[sig.name]) for sig in spec.values}
    raw[spec.counter.name] = int(counter) % (1 << spec.counter.length_bits)
    if spec.crc is not None:
        raw[spec.crc.name] = 0
    data = _pack(spec.message, raw)
    if spec.crc is not None:
        data = bytes([e2e_crc(data, spec.data_id)]) + data[1:]
    return data


def encode_frame(message_name: str, fields: Mapping[str, float], counter: int, *, t_ns: int = 0,
                 dbc: VdpsDbc | None = None) -> Frame:
    """:func:`pack_fields` as a :class:`Frame` (``timestamp`` = ``t_ns`` / 1e9 s)."""
    dbc = dbc or load_dbc()
    spec = dbc.messages[message_name]
    return Frame(t_ns / 1e9, spec.frame_id, spec.dlc, pack_fields(message_name, fields, counter, dbc=dbc))


def encode_fields(message_name: str, fields: Mapping[str, float], counter: int, *, t_ns: int = 0,
                  dbc: VdpsDbc | None = None) -> can.Message:
    """Encode catalogue ``fields`` (SI values) into message ``message_name`` as a ``can.Message``
    (:func:`pack_fields`'s rules). ``timestamp`` = ``t_ns`` / 1e9 s.
    """
    return encode_frame(message_name, fields, counter, t_ns=t_ns, dbc=dbc).to_message()


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
                         ) -> tuple[can.Message, can.Message]:
    """Four wheel torques [N m] (FL, FR, RR, RL, positive driving) -> (VDPS_WheelTorqueFront,
    VDPS_WheelTorqueRear)."""
    f = _four("wheel_torque_nm", wheel_torque_nm)
    return (encode_fields(WHEEL_TORQUE_FRONT, f, counter, t_ns=t_ns),
            encode_fields(WHEEL_TORQUE_REAR, f, counter, t_ns=t_ns))


def encode_suspension(susp_deflection_m: Sequence[float], counter: int, *, t_ns: int = 0
                      ) -> can.Message:
    """Four suspension deflections [m] (FL, FR, RR, RL, compression positive) -> VDPS_Suspension."""
    return encode_fields(SUSPENSION, _four("susp_deflection_m", susp_deflection_m), counter,
                         t_ns=t_ns)


def encode_steer(steer_wheel_angle_rad: float, counter: int, *, t_ns: int = 0) -> can.Message:
    """Steering wheel angle [rad], positive left -> VDPS_SteerAngle."""
    return encode_fields(STEER, {"steer_wheel_angle_rad": steer_wheel_angle_rad}, counter, t_ns=t_ns)


def warning_frame(level: int, time_to_rollover_s: float | None, peak_roll_rad: float, ltr: float,
                  status: int, counter: int, *, t_ns: int = 0, dbc: VdpsDbc | None = None) -> Frame:
    """VDPS_Warning as a :class:`Frame`, CRC-8/SAE-J1850 over bytes 1..7.

    ``level`` and ``status`` must be integers 0..3 (``ValueError`` otherwise);
    ``time_to_rollover_s`` None/inf (or >= 65.535 s) = no rollover predicted, negative ->
    ``ValueError``; ``peak_roll_rad`` clamped to +-3.1416 rad, ``ltr`` to [-1, 1];
    ``counter`` taken modulo 16.
    """
    for name, v in (("level", level), ("status", status)):
        if isinstance(v, bool) or int(v) != v or not 0 <= int(v) <= 3:
            raise ValueError(f"warning {name} must be an integer 0..3, got {v!r}")
    return encode_frame(WARNING, {"warning_level": int(level),
                                  TTR_FIELD: time_to_rollover_s,
                                  "warning_peak_roll_rad": peak_roll_rad,
                                  "warning_ltr": ltr,
                                  "warning_status": int(status)}, counter, t_ns=t_ns, dbc=dbc)


def encode_warning(level: int, time_to_rollover_s: float | None, peak_roll_rad: float, ltr: float,
                   status: int, counter: int, *, t_ns: int = 0) -> can.Message:
    """:func:`warning_frame` as a ``can.Message``."""
    return warning_frame(level, time_to_rollover_s, peak_roll_rad, ltr, status, counter, t_ns=t_ns).to_message()


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
            if spec.is_sensor and all(f in sample.fields for f in spec.field_names):
                out.append(encode_fields(name, sample.fields, self._next[name], t_ns=sample.t_ns,
                                         dbc=self._dbc))
                self._next[name] += 1
        if not out:
            raise ValueError(f"sample of kind {sample.kind!r} fills no sensor message of the DBC")
        return out

    def warning_frame(self, level: int, time_to_rollover_s: float | None, peak_roll_rad: float,
                      ltr: float, status: int, *, t_ns: int = 0) -> Frame:
        """VDPS_Warning with this encoder's counter, as a :class:`Frame` (:func:`warning_frame`)."""
        f = warning_frame(level, time_to_rollover_s, peak_roll_rad, ltr, status, self._next[WARNING],
                          t_ns=t_ns, dbc=self._dbc)
        self._next[WARNING] += 1
        return f

    def warning(self, level: int, time_to_rollover_s: float | None, peak_roll_rad: float,
                ltr: float, status: int, *, t_ns: int = 0) -> can.Message:
        return self.warning_frame(level, time_to_rollover_s, peak_roll_rad, ltr, status, t_ns=t_ns).to_message()
