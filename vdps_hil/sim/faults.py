"""Fault injection for simulated drives: named, parameterised faults that make the sensors and
their wires misbehave the way real hardware does.

A fault is given as ``NAME`` or ``NAME:key=value,key=value`` (``--fault`` on the command line),
or as a table ``{name = "NAME", key = value}`` / the same string in a scenario's ``faults``
list. Times are simulation times [s]; ``duration_s = inf`` lasts to the end. Unknown names,
keys or bad values are one-line :class:`FaultError`.

=====================  =========================================================================
fault                  what the recording shows (and why it looks like that)
=====================  =========================================================================
``gnss_outage``        A tunnel: from ``t_s`` for ``duration_s`` the receiver has no fix. It keeps
                       its 5 Hz output, as u-blox/NovAtel/OxTS receivers do: GGA with quality 0,
                       no satellites, HDOP 99.9 and empty position/altitude; RMC with status V,
                       mode N and empty position/speed/course. The attitude sentence is not sent
                       (a multi-antenna GNSS compass has no attitude without signals). After the
                       tunnel the receiver reports a standalone fix (GGA quality 1, RMC mode A)
                       for ``reacquire_s`` before its configured quality (RTK) returns.
``gyro_spike``         A shock or an electrical glitch: ``amplitude_degps`` is added to the gyro
                       ``axis`` (sensor axes x/y/z) of every IMU sample in
                       [``t_s``, ``t_s + duration_s``).
``frozen_can_signal``  A stuck sensor behind a live ECU: catalogue field ``signal`` keeps the
                       value of its last sample before ``t_s`` for ``duration_s``; the frames keep
                       coming with their rolling counters running (the counter cannot reveal it).
``dropped_frames``     Frames lost on the way (bus errors, a receiver overrun): each CAN frame
                       of ``message`` (a DBC message name; empty = every message) in the window
                       is lost with probability ``fraction`` (seeded). The sender's counter has
                       advanced, so a decoder sees the gap in ``seq_counter``.
``serial_disconnect``  A loose connector: no byte of serial ``device`` (``imu`` or ``gnss``)
                       arrives in [``t_s``, ``t_s + duration_s``). The device keeps running, so a
                       message in flight is cut in the middle and the IMU packet counter / GNSS
                       UTC jump across the gap.
``clock_jump``         A device's clock steps by ``jump_s`` (either sign) at ``t_s`` and stays
                       stepped: ``imu`` -> the SampleTimeFine in the MTData2 packets; ``gnss`` ->
                       the UTC time in every sentence; ``can`` -> the receive time stamps of the
                       CAN frames (the interface's hardware clock; a backward jump makes
                       ``/raw/can/<bus>`` go back in time, counted by the writer).
=====================  =========================================================================

Faults act at the sensor or wire level only; what was injected is recorded under ``/truth/``
(events) and the ``truth.drive`` metadata, never in ``/raw/``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Iterable, Mapping

import numpy as np

from vdps_hil.units import NS_PER_S

__all__ = ["FaultError", "FaultParam", "Fault", "GnssOutage", "GyroSpike", "FrozenCanSignal",
           "DroppedFrames", "SerialDisconnect", "ClockJump", "REGISTRY", "parse_fault",
           "make_fault", "FaultSet", "SERIAL_DEVICES", "CLOCK_DEVICES"]

SERIAL_DEVICES = ("imu", "gnss")
CLOCK_DEVICES = ("imu", "gnss", "can")


class FaultError(ValueError):
    """An unknown fault, parameter or a bad value (one-line message)."""


@dataclass(frozen=True)
class FaultParam:
    """One fault parameter: name (unit suffix), default, meaning; ``choices`` for strings."""

    name: str
    default: float | str
    description: str
    choices: tuple[str, ...] | None = None
    lower: float = -math.inf
    upper: float = math.inf

    @property
    def is_text(self) -> bool:
        return isinstance(self.default, str)


def _s2ns(t_s: float) -> int:
    if math.isinf(t_s):
        return (1 << 62) if t_s > 0 else -(1 << 62)
    return int(round(t_s * NS_PER_S))


class Fault:
    """Base of every fault: ``name``, ``PARAMS`` and hooks the sensors call (no-ops here)."""

    name: ClassVar[str] = ""
    PARAMS: ClassVar[tuple[FaultParam, ...]] = ()

    def __init__(self, **params: Any):
        specs = {p.name: p for p in self.PARAMS}
        for k in params:
            if k not in specs:
                known = ", ".join(specs) or "none"
                raise FaultError(f"fault {self.name!r}: unknown parameter {k!r} (known: {known})")
        values: dict[str, float | str] = {}
        for p in self.PARAMS:
            v = params.get(p.name, p.default)
            if p.is_text:
                if not isinstance(v, str):
                    raise FaultError(f"fault {self.name!r}: {p.name} must be text, got {v!r}")
                if p.choices is not None and v not in p.choices:
                    raise FaultError(f"fault {self.name!r}: {p.name} must be one of "
                                     f"{', '.join(p.choices)}, got {v!r}")
            else:
                if isinstance(v, str):
                    try:
                        v = float(v)
                    except ValueError:
                        raise FaultError(f"fault {self.name!r}: {p.name} must be a number, got {v!r}") from None
                if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v):
                    raise FaultError(f"fault {self.name!r}: {p.name} must be a number, got {v!r}")
                v = float(v)
                if not p.lower <= v <= p.upper:
                    raise FaultError(f"fault {self.name!r}: {p.name} = {v:g} outside [{p.lower:g}, {p.upper:g}]")
            values[p.name] = v
        self._values = values
        self._validate()

    def _validate(self) -> None:
        """Subclasses raise FaultError for inconsistent values."""

    def __getattr__(self, key):
        try:
            return self.__dict__["_values"][key]
        except KeyError:
            raise AttributeError(key) from None

    @property
    def params(self) -> dict[str, float | str]:
        return dict(self._values)

    def spec(self) -> str:
        """The ``NAME:key=value,...`` form of this fault."""
        inner = ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                         for k, v in self._values.items())
        return f"{self.name}:{inner}" if inner else self.name

    def describe(self) -> dict:
        return {"name": self.name, **self._values}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.spec()})"

    # --- window -----------------------------------------------------------------------------
    @property
    def start_ns(self) -> int:
        return _s2ns(float(self._values.get("t_s", 0.0)))

    @property
    def end_ns(self) -> int:
        d = float(self._values.get("duration_s", math.inf))
        return _s2ns(float(self._values.get("t_s", 0.0)) + d)

    def active(self, t_ns: np.ndarray) -> np.ndarray:
        t = np.asarray(t_ns)
        return (t >= self.start_ns) & (t < self.end_ns)

    # --- hooks (sensor side) ------------------------------------------------------------------
    def bind(self, rng: np.random.Generator, dbc=None) -> None:
        """Called once by FaultSet with this fault's own random stream and the DBC."""

    def gnss_fix(self, t_ns: int) -> str | None:
        """``"lost"``, ``"reacquiring"`` or None (no opinion) at a GNSS epoch."""
        return None

    def imu_values(self, t_ns: np.ndarray, specific_force: np.ndarray, rate: np.ndarray) -> None:
        """Modify IMU samples (sensor axes) in place."""

    def can_values(self, message: str, fields: tuple[str, ...], t_ns: np.ndarray,
                   values: np.ndarray) -> None:
        """Modify the physical values of a CAN message's samples in place."""

    def can_keep(self, message: str, t_ns: np.ndarray) -> np.ndarray | None:
        """Mask of frames that reach the receiver (None = all)."""
        return None

    def serial_keep(self, device: str, arrival_ns: np.ndarray) -> np.ndarray | None:
        """Mask of bytes that arrive (None = all)."""
        return None

    def clock_offset_ns(self, device: str, t_ns: np.ndarray) -> np.ndarray | None:
        """Offset of the device's clock at true times t (None = none)."""
        return None


_T = FaultParam("t_s", 5.0, "start time [s]", lower=0.0)


class GnssOutage(Fault):
    """``gnss_outage``: no GNSS fix for ``duration_s`` from ``t_s`` (module table)."""

    name = "gnss_outage"
    PARAMS = (_T, FaultParam("duration_s", 5.0, "outage length [s]", lower=0.0),
              FaultParam("reacquire_s", 1.0, "standalone fix after the outage [s]", lower=0.0))

    def gnss_fix(self, t_ns: int) -> str | None:
        if self.start_ns <= t_ns < self.end_ns:
            return "lost"
        if self.end_ns <= t_ns < self.end_ns + _s2ns(self.reacquire_s):
            return "reacquiring"
        return None


class GyroSpike(Fault):
    """``gyro_spike``: ``amplitude_degps`` on one gyro axis over a short window."""

    name = "gyro_spike"
    PARAMS = (_T, FaultParam("duration_s", 0.002, "spike length [s]", lower=0.0),
              FaultParam("axis", "z", "gyro axis (sensor axes)", choices=("x", "y", "z")),
              FaultParam("amplitude_degps", 200.0, "added rate [deg/s]"))

    def imu_values(self, t_ns, specific_force, rate) -> None:
        m = self.active(t_ns)
        if m.any():
            rate[m, "xyz".index(self.axis)] += math.radians(self.amplitude_degps)


class FrozenCanSignal(Fault):
    """``frozen_can_signal``: a CAN field holds its last value before ``t_s``."""

    name = "frozen_can_signal"
    PARAMS = (FaultParam("signal", "wheel_speed_radps_1", "catalogue field carried on CAN"), _T,
              FaultParam("duration_s", 5.0, "how long [s]", lower=0.0))

    def bind(self, rng, dbc=None) -> None:
        self._held: float | None = None
        if dbc is not None and self.signal not in dbc.field_signal:
            known = ", ".join(sorted(f for f, (m, _) in dbc.field_signal.items() if m.is_sensor))
            raise FaultError(f"fault {self.name!r}: signal {self.signal!r} is not carried by a "
                             f"sensor message of {dbc.path.name} (known: {known})")

    def can_values(self, message, fields, t_ns, values) -> None:
        if self.signal not in fields:
            return
        col = fields.index(self.signal)
        t = np.asarray(t_ns)
        before = np.flatnonzero(t < self.start_ns)
        if before.size:
            self._held = float(values[before[-1], col])
        m = self.active(t)
        if m.any():
            if getattr(self, "_held", None) is None:
                self._held = float(values[np.flatnonzero(m)[0], col])
            values[m, col] = self._held


class DroppedFrames(Fault):
    """``dropped_frames``: each frame lost with probability ``fraction`` (seeded)."""

    name = "dropped_frames"
    PARAMS = (FaultParam("fraction", 0.01, "probability that a frame is lost", lower=0.0, upper=1.0),
              FaultParam("message", "", "DBC message name (empty: every message)"),
              FaultParam("t_s", 0.0, "start time [s]", lower=0.0),
              FaultParam("duration_s", math.inf, "how long [s]", lower=0.0))

    def bind(self, rng, dbc=None) -> None:
        self._rng = rng
        if (dbc is not None and self.message
                and (self.message not in dbc.messages or not dbc.messages[self.message].is_sensor)):
            known = ", ".join(n for n, s in dbc.messages.items() if s.is_sensor)
            raise FaultError(f"fault {self.name!r}: unknown message {self.message!r} (known: {known})")

    def can_keep(self, message, t_ns) -> np.ndarray | None:
        if self.message and message != self.message:
            return None
        t = np.asarray(t_ns)
        u = self._rng.random(t.size)  # drawn for every frame: the stream does not depend on the window
        return ~(self.active(t) & (u < self.fraction))


class SerialDisconnect(Fault):
    """``serial_disconnect``: no byte of ``device`` arrives in the window."""

    name = "serial_disconnect"
    PARAMS = (FaultParam("device", "imu", "serial device", choices=SERIAL_DEVICES), _T,
              FaultParam("duration_s", 2.0, "how long [s]", lower=0.0))

    def serial_keep(self, device, arrival_ns) -> np.ndarray | None:
        if device != self.device:
            return None
        return ~self.active(arrival_ns)


class ClockJump(Fault):
    """``clock_jump``: the device clock steps by ``jump_s`` at ``t_s``."""

    name = "clock_jump"
    PARAMS = (FaultParam("device", "imu", "whose clock", choices=CLOCK_DEVICES), _T,
              FaultParam("jump_s", 1.0, "step of the clock [s] (either sign)", lower=-86400.0, upper=86400.0))

    def clock_offset_ns(self, device, t_ns) -> np.ndarray | None:
        if device != self.device:
            return None
        t = np.asarray(t_ns)
        return np.where(t >= self.start_ns, np.int64(_s2ns(self.jump_s)), np.int64(0))


REGISTRY: dict[str, type[Fault]] = {c.name: c for c in (
    GnssOutage, GyroSpike, FrozenCanSignal, DroppedFrames, SerialDisconnect, ClockJump)}
"""Fault name -> class. Add your own: ``REGISTRY[MyFault.name] = MyFault``."""


def make_fault(name: str, **params: Any) -> Fault:
    try:
        cls = REGISTRY[name]
    except KeyError:
        raise FaultError(f"unknown fault {name!r} (known: {', '.join(REGISTRY)})") from None
    return cls(**params)


def parse_fault(spec: str | Mapping[str, Any] | Fault) -> Fault:
    """A fault from ``NAME[:key=value,...]``, a mapping with ``name``, or a Fault."""
    if isinstance(spec, Fault):
        return spec
    if isinstance(spec, Mapping):
        d = dict(spec)
        name = d.pop("name", None)
        if not isinstance(name, str):
            raise FaultError(f"a fault table needs a name (known: {', '.join(REGISTRY)})")
        return make_fault(name, **d)
    if not isinstance(spec, str) or not spec.strip():
        raise FaultError(f"bad fault {spec!r}: expected NAME or NAME:key=value,...")
    name, _, rest = spec.strip().partition(":")
    params: dict[str, str] = {}
    if rest.strip():
        for item in rest.split(","):
            key, eq, value = item.partition("=")
            if not eq or not key.strip():
                raise FaultError(f"fault {name!r}: bad parameter {item!r} (expected key=value)")
            if key.strip() in params:
                raise FaultError(f"fault {name!r}: parameter {key.strip()!r} given twice")
            params[key.strip()] = value.strip()
    return make_fault(name.strip(), **params)


class FaultSet:
    """The faults of one drive and the dispatch of the sensor hooks to them.

    ``FaultSet(faults, seed, dbc)`` parses and binds every fault (fault i gets its own random
    stream from the drive seed, so adding a fault never changes another's draws)."""

    def __init__(self, faults: Iterable[str | Mapping | Fault] = (), seed: int = 0, dbc=None):
        self.faults: tuple[Fault, ...] = tuple(parse_fault(f) for f in faults)
        for i, f in enumerate(self.faults):
            ss = np.random.SeedSequence(int(seed), spawn_key=(0xFA017, i))
            f.bind(np.random.default_rng(ss), dbc)

    def __len__(self) -> int:
        return len(self.faults)

    def __iter__(self):
        return iter(self.faults)

    def describe(self) -> list[dict]:
        return [f.describe() for f in self.faults]

    def gnss_fix_state(self, t_ns: int) -> str:
        """``"ok"``, ``"lost"`` (any outage wins) or ``"reacquiring"``."""
        state = "ok"
        for f in self.faults:
            s = f.gnss_fix(t_ns)
            if s == "lost":
                return "lost"
            if s == "reacquiring":
                state = s
        return state

    def imu_values(self, t_ns, specific_force, rate) -> None:
        for f in self.faults:
            f.imu_values(t_ns, specific_force, rate)

    def can_values(self, message, fields, t_ns, values) -> None:
        for f in self.faults:
            f.can_values(message, fields, t_ns, values)

    def can_keep(self, message, t_ns) -> np.ndarray | None:
        keep = None
        for f in self.faults:
            m = f.can_keep(message, t_ns)
            if m is not None:
                keep = m if keep is None else keep & m
        return keep

    def serial_keep_fn(self, device: str):
        """A ``keep(arrival_ns) -> mask`` for SerialLink, or None when no fault concerns it."""
        if not any(isinstance(f, SerialDisconnect) and f.device == device for f in self.faults):
            return None

        def keep(arrival_ns):
            m = np.ones(len(arrival_ns), dtype=bool)
            for f in self.faults:
                k = f.serial_keep(device, arrival_ns)
                if k is not None:
                    m &= k
            return m
        return keep

    def clock_offset_ns(self, device: str, t_ns) -> np.ndarray | None:
        out = None
        for f in self.faults:
            o = f.clock_offset_ns(device, t_ns)
            if o is not None:
                out = o if out is None else out + o
        return out
