"""Signal maps: which frame and signal of a car's own DBC feeds which bus catalogue field.

A signal map (``configs/signalmaps/*.toml``, read with tomllib: nothing in it can execute) says,
per CAN bus, which message -- **by frame ID**, because real DBCs repeat message names -- and
which of its signals give which catalogue field (:mod:`vdps_hil.bus.samples`), with the unit of
the DBC value and an optional scale, offset, sign and transform. This module reads and checks
the map; ``adapters.signalmap_decoder`` applies it to the frames of a bus with its DBC.

Conversion of one mapped value (signals listed together are summed first)::

    x      = sum_j v_j                     v_j: DBC physical value of signal j [unit]
    y      = scale * x + offset            still in ``unit``
    y_SI   = U(unit -> field unit) * y     unit conversion; km/h or m/s to rad/s divides by
                                           the bus's rolling_radius_m (wheel linear speed ->
                                           spin rate, omega = v / r)
    z      = sign * T(y_SI)                T: transform, identity or ``heading_to_yaw``:
                                           psi = wrap(pi/2 - heading), heading clockwise from N

============  ============================================  =========
symbol        meaning                                       unit
============  ============================================  =========
v_j           DBC value of a signal (after DBC factor)      the map's ``unit``
scale,offset  map's linear correction                       1, unit
U             unit factor to the catalogue unit             -
r             rolling radius (``rolling_radius_m``)         m
sign          +1 or -1 (frame and sign conventions)         1
============  ============================================  =========

TOML layout::

    name = "toyota-rav4-2017"
    description = "..."
    [bus.pt]                       # one table per bus; the name matches ``--can pt=...``
    dbc = "vdps.dbc"               # optional: path relative to this file (``--dbc`` overrides)
    dbc_name = "toyota_new_mc_pt_generated.dbc"   # informational (checked by file name only)
    dbc_sha256 = "..."             # optional: warn when the DBC given differs from this one
    dbc_strict = false             # load with cantools strict=False (logged)
    channel = "can0"               # optional: in multi-channel logs decode only this channel
    rolling_radius_m = 0.35        # optional: for km/h or m/s -> rad/s wheel speeds
    decode_all = true              # decode unmapped DBC messages too (counts decode errors)
    codec = "vdps"                 # optional: decode with VdpsCanDecoder (dbc/vdps.dbc only)

    [[bus.pt.message]]
    frame_id = 0xAA                # required; extended = true for 29-bit IDs
    name = "WHEEL_SPEEDS"          # optional; checked against the DBC
    kind = "wheel_speed"           # the Sample kind
    checksum = "toyota"            # optional: a named checksum rule (CHECKSUMS)
    counter = "COUNTER"            # optional: a rolling counter signal (jumps are counted)
    valid_signal = "PositionValid" # optional: Sample.valid = (value != 0)
    signals = [ { signal = "WHEEL_SPEED_FL", field = "wheel_speed_radps_1", unit = "km/h" },
                { signal = ["STEER_ANGLE", "STEER_FRACTION"], field = "...", unit = "deg",
                  sign = -1, scale = 1.0, offset = 0.0, transform = "heading_to_yaw" } ]

"""

from __future__ import annotations

import hashlib
import logging
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping

from vdps_hil.bus.samples import FIELDS

__all__ = ["SignalMap", "BusMap", "MessageRule", "SignalRule", "SignalMapError",
           "load_signalmap", "CHECKSUMS", "TRANSFORMS", "CODECS", "SIGNALMAP_DIR", "convert_unit"]

log = logging.getLogger(__name__)

SIGNALMAP_DIR = Path(__file__).resolve().parents[2] / "configs" / "signalmaps"


class SignalMapError(ValueError):
    """A signal map or its DBC cannot be used (one line naming the file and the problem)."""


# --- units ----------------------------------------------------------------------------------

_ALIASES = {
    "": "1", "-": "1", "1": "1", "none": "1", "unit": "1", "%": "%",
    "rad": "rad", "deg": "deg", "degree": "deg", "degrees": "deg", "°": "deg",
    "rad/s": "rad/s", "deg/s": "deg/s", "°/s": "deg/s", "dps": "deg/s", "rpm": "rpm",
    "m/s": "m/s", "km/h": "km/h", "kph": "km/h", "kmh": "km/h", "mph": "mph", "kn": "kn",
    "m/s^2": "m/s^2", "m/s2": "m/s^2", "m/s²": "m/s^2", "g": "g",
    "m": "m", "mm": "mm", "cm": "cm", "km": "km",
    "n m": "N m", "nm": "N m", "n.m": "N m", "n*m": "N m",
    "pa": "Pa", "kpa": "kPa", "mpa": "MPa", "bar": "bar", "mbar": "mbar", "psi": "psi",
    "degc": "degC", "°c": "degC", "c": "degC", "s": "s", "ms": "ms",
}

# unit -> (dimension, factor to the SI unit of that dimension)
_UNITS: dict[str, tuple[str, float]] = {
    "1": ("1", 1.0), "%": ("1", 0.01),
    "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180.0),
    "rad/s": ("rate", 1.0), "deg/s": ("rate", math.pi / 180.0), "rpm": ("rate", math.pi / 30.0),
    "m/s": ("speed", 1.0), "km/h": ("speed", 1.0 / 3.6), "mph": ("speed", 0.44704),
    "kn": ("speed", 1852.0 / 3600.0),
    "m/s^2": ("accel", 1.0), "g": ("accel", 9.80665),
    "m": ("length", 1.0), "mm": ("length", 1e-3), "cm": ("length", 1e-2), "km": ("length", 1e3),
    "N m": ("torque", 1.0),
    "Pa": ("pressure", 1.0), "kPa": ("pressure", 1e3), "MPa": ("pressure", 1e6),
    "bar": ("pressure", 1e5), "mbar": ("pressure", 1e2), "psi": ("pressure", 6894.757293168),
    "degC": ("temperature", 1.0), "s": ("time", 1.0), "ms": ("time", 1e-3),
}


def _norm_unit(u: str) -> str:
    key = str(u).strip()
    return _ALIASES.get(key.lower(), key)


def convert_unit(from_unit: str, to_unit: str, rolling_radius_m: float | None = None
                 ) -> float:
    """Factor taking a value in ``from_unit`` to ``to_unit``; a speed to a spin rate divides
    by ``rolling_radius_m``. Raises SignalMapError when the units are unknown or
    incompatible."""
    a, b = _norm_unit(from_unit), _norm_unit(to_unit)
    if a not in _UNITS:
        raise SignalMapError(f"unknown unit {from_unit!r} (known: {', '.join(sorted(_UNITS))})")
    if b not in _UNITS:
        raise SignalMapError(f"unknown unit {to_unit!r}")
    (da, fa), (db, fb) = _UNITS[a], _UNITS[b]
    if da == db:
        return fa / fb
    if da == "speed" and db == "rate":
        if not rolling_radius_m or rolling_radius_m <= 0:
            raise SignalMapError(f"{from_unit} -> {to_unit} needs rolling_radius_m on the bus")
        return fa / rolling_radius_m / fb
    raise SignalMapError(f"cannot convert {from_unit!r} to {to_unit!r}")


def _heading_to_yaw(h_rad: float) -> float:
    psi = math.pi / 2.0 - h_rad
    return (psi + math.pi) % (2.0 * math.pi) - math.pi


TRANSFORMS: dict[str, Callable[[float], float]] = {
    "": lambda v: v,
    "heading_to_yaw": _heading_to_yaw,
}
"""Named transforms applied after the unit conversion (input already in SI)."""


# --- checksums ------------------------------------------------------------------------------

def _toyota_checksum(frame_id: int, data: bytes) -> bool:
    """Toyota/opendbc: last byte = (id_low + id_high + length + sum(other bytes)) mod 256."""
    if len(data) < 1:
        return False
    s = (frame_id & 0xFF) + ((frame_id >> 8) & 0xFF) + len(data) + sum(data[:-1])
    return (s & 0xFF) == data[-1]


def _vdps_crc8(frame_id: int, data: bytes) -> bool:
    """dbc/vdps.dbc VDPS_Warning: byte 0 = CRC-8/SAE-J1850 of bytes 1..7."""
    from vdps_hil.codecs.can_e2e import crc8_j1850

    return len(data) >= 2 and crc8_j1850(data[1:]) == data[0]


def _vdps_e2e(frame_id: int, data: bytes) -> bool:
    """dbc/vdps.dbc sensor frames (layout 2): byte 0 = CRC-8/SAE-J1850 of the data ID (the CAN
    ID, low byte then high byte) and bytes 1..DLC-1 (``codecs.can_e2e.e2e_crc``)."""
    from vdps_hil.codecs.can_e2e import e2e_crc

    return len(data) >= 2 and e2e_crc(data, frame_id) == data[0]


CHECKSUMS: dict[str, Callable[[int, bytes], bool]] = {
    "toyota": _toyota_checksum,
    "vdps_crc8": _vdps_crc8,
    "vdps_e2e": _vdps_e2e,
}
"""Named checksum rules: ``(frame_id, data) -> ok``."""


# --- the map --------------------------------------------------------------------------------

@dataclass(frozen=True)
class SignalRule:
    signals: tuple[str, ...]
    field: str
    unit: str
    factor: float  # scale * U (unit conversion, radius) folded
    offset_si: float  # offset * U
    sign: float
    transform: str

    def value(self, vals: Mapping[str, Any]) -> float | None:
        x = 0.0
        for s in self.signals:
            v = vals.get(s)
            if v is None:
                return None
            x += float(v)
        y = self.sign * TRANSFORMS[self.transform](self.factor * x + self.offset_si)
        return y


@dataclass(frozen=True)
class MessageRule:
    frame_id: int
    is_extended: bool
    name: str
    kind: str
    rules: tuple[SignalRule, ...]
    checksum: str = ""
    counter: str = ""
    valid_signal: str = ""


@dataclass(frozen=True)
class BusMap:
    name: str
    dbc: Path | None
    dbc_name: str
    dbc_sha256: str
    dbc_strict: bool
    channel: str | None
    rolling_radius_m: float | None
    decode_all: bool
    messages: Mapping[tuple[int, bool], MessageRule]
    codec: str = ""

    def fields(self) -> set[str]:
        return {r.field for m in self.messages.values() for r in m.rules}


@dataclass(frozen=True)
class SignalMap:
    name: str
    description: str
    path: Path | None
    sha256: str
    buses: Mapping[str, BusMap] = field(default_factory=dict)
    text: str = ""

    def bus(self, name: str) -> BusMap | None:
        """The map of bus ``name``; with a single bus in the map, that one for any name."""
        if name in self.buses:
            return self.buses[name]
        if len(self.buses) == 1:
            only = next(iter(self.buses.values()))
            log.info("signal map %s: bus %r not named in the map, using its only bus %r",
                     self.name, name, only.name)
            return only
        return None


_TOP_KEYS = {"name", "description", "bus"}
_BUS_KEYS = {"dbc", "dbc_name", "dbc_sha256", "dbc_strict", "channel", "rolling_radius_m",
             "decode_all", "codec", "message"}

CODECS = ("", "vdps")
"""``codec`` values of a bus: "" (generic SignalMapDecoder) or "vdps" (VdpsCanDecoder)."""
_MSG_KEYS = {"frame_id", "extended", "name", "kind", "checksum", "counter", "valid_signal",
             "signals"}
_SIG_KEYS = {"signal", "field", "unit", "scale", "offset", "sign", "transform"}


def _check_keys(where: str, d: Mapping, allowed: set[str]) -> None:
    extra = set(d) - allowed
    if extra:
        raise SignalMapError(f"{where}: unknown key(s) {', '.join(sorted(extra))} "
                             f"(allowed: {', '.join(sorted(allowed))})")


def _num(where: str, v, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SignalMapError(f"{where}: {what} must be a finite number, got {v!r}")
    return float(v)


def _signal_rule(where: str, d: Mapping, radius: float | None) -> SignalRule:
    if not isinstance(d, Mapping):
        raise SignalMapError(f"{where}: each signal entry must be a table")
    _check_keys(where, d, _SIG_KEYS)
    sig = d.get("signal")
    sigs = (sig,) if isinstance(sig, str) else tuple(sig) if isinstance(sig, list) else ()
    if not sigs or not all(isinstance(s, str) and s for s in sigs):
        raise SignalMapError(f"{where}: 'signal' must be a name or a list of names")
    fld = d.get("field")
    if not isinstance(fld, str) or fld not in FIELDS:
        raise SignalMapError(f"{where}: field {fld!r} is not in the bus catalogue "
                             "(vdps_hil.bus.samples.FIELDS)")
    unit = d.get("unit", "")
    if not isinstance(unit, str):
        raise SignalMapError(f"{where}: unit must be text")
    scale = _num(where, d.get("scale", 1.0), "scale")
    if scale == 0.0:  # every value would map to the offset: a constant, not a measurement
        raise SignalMapError(f"{where}: scale must not be 0")
    offset = _num(where, d.get("offset", 0.0), "offset")
    sign = _num(where, d.get("sign", 1), "sign")
    if sign not in (1.0, -1.0):
        raise SignalMapError(f"{where}: sign must be 1 or -1")
    transform = d.get("transform", "")
    if not isinstance(transform, str) or transform not in TRANSFORMS:
        raise SignalMapError(f"{where}: unknown transform {transform!r} "
                             f"(known: {', '.join(t for t in TRANSFORMS if t)})")
    try:
        u = convert_unit(unit, FIELDS[fld].unit, radius)
    except SignalMapError as e:
        raise SignalMapError(f"{where}: {e}") from None
    return SignalRule(sigs, fld, unit, scale * u, offset * u, sign, transform)


def _parse(doc: Mapping, path: Path | None, text: str) -> SignalMap:
    where0 = str(path) if path else "signal map"
    _check_keys(where0, doc, _TOP_KEYS)
    buses_doc = doc.get("bus")
    if not isinstance(buses_doc, Mapping) or not buses_doc:
        raise SignalMapError(f"{where0}: no [bus.<name>] table")
    buses = {}
    for bname, b in buses_doc.items():
        where = f"{where0} [bus.{bname}]"
        if not isinstance(b, Mapping):
            raise SignalMapError(f"{where}: must be a table")
        _check_keys(where, b, _BUS_KEYS)
        radius = b.get("rolling_radius_m")
        if radius is not None:
            radius = _num(where, radius, "rolling_radius_m")
            if radius <= 0:
                raise SignalMapError(f"{where}: rolling_radius_m must be positive")
        dbc = b.get("dbc")
        if dbc is not None:
            if not isinstance(dbc, str):
                raise SignalMapError(f"{where}: dbc must be a path")
            dbc = ((path.parent / dbc) if path is not None else Path(dbc)).resolve()
        channel = b.get("channel")
        codec = b.get("codec", "")
        if not isinstance(codec, str) or codec not in CODECS:
            raise SignalMapError(f"{where}: unknown codec {codec!r} (known: vdps)")
        msgs: dict[tuple[int, bool], MessageRule] = {}
        messages = b.get("message", [])
        if not isinstance(messages, list):
            raise SignalMapError(f"{where}: 'message' must be a list of tables ([[bus.NAME.message]])")
        for i, m in enumerate(messages):
            mw = f"{where} message #{i + 1}"
            if not isinstance(m, Mapping):
                raise SignalMapError(f"{mw}: must be a table")
            _check_keys(mw, m, _MSG_KEYS)
            fid = m.get("frame_id")
            if isinstance(fid, bool) or not isinstance(fid, int) or fid < 0 or fid > 0x1FFFFFFF:
                raise SignalMapError(f"{mw}: frame_id must be an integer ID (e.g. 0xAA)")
            ext = bool(m.get("extended", fid > 0x7FF))
            kind = m.get("kind")
            if not isinstance(kind, str) or not kind:
                raise SignalMapError(f"{mw}: kind is required (e.g. 'wheel_speed')")
            cks = m.get("checksum", "")
            if cks and (not isinstance(cks, str) or cks not in CHECKSUMS):
                raise SignalMapError(f"{mw}: unknown checksum {cks!r} "
                                     f"(known: {', '.join(CHECKSUMS)})")
            sigs = m.get("signals", [])
            if not isinstance(sigs, list) or not sigs:
                raise SignalMapError(f"{mw}: 'signals' must be a non-empty list")
            rules = tuple(_signal_rule(f"{mw} signal #{j + 1}", s, radius)
                          for j, s in enumerate(sigs))
            key = (fid, ext)
            if key in msgs:
                raise SignalMapError(f"{mw}: frame 0x{fid:X} mapped twice")
            msgs[key] = MessageRule(fid, ext, str(m.get("name", "")), kind, rules,
                                    str(cks), str(m.get("counter", "")),
                                    str(m.get("valid_signal", "")))
        buses[str(bname)] = BusMap(
            str(bname), dbc, str(b.get("dbc_name", "")), str(b.get("dbc_sha256", "")),
            bool(b.get("dbc_strict", True)), None if channel is None else str(channel), radius,
            bool(b.get("decode_all", True)), MappingProxyType(msgs), str(codec))
    name = doc.get("name", path.stem if path else "signalmap")
    return SignalMap(str(name), str(doc.get("description", "")), path,
                     hashlib.sha256(text.encode()).hexdigest(), MappingProxyType(buses), text)


def load_signalmap(path: str | os.PathLike) -> SignalMap:
    """Read and check a signal map (a bare name such as ``rav4`` is looked up in
    ``configs/signalmaps/``). Raises SignalMapError (one line)."""
    p = Path(path)
    if not p.suffix and not p.exists():
        p = SIGNALMAP_DIR / f"{p.name}.toml"
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise SignalMapError(f"signal map {path}: cannot read: "
                             f"{getattr(e, 'strerror', None) or e}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SignalMapError(f"signal map {p}: malformed TOML: {e}") from None
    return _parse(doc, p, text)
