"""The simulated ECU: it receives ``VDPS_Warning`` on the bench's CAN bus, trusts a frame only
when its CRC, counter and status say so, watches for the warning to stop arriving, and (with
``react``) cuts the drive torque and brakes through the simulator's input port.

Reception (``dbc/vdps.dbc``, checks of :class:`~vdps_hil.codecs.can_decode.VdpsCanDecoder`)
-------------------------------------------------------------------------------------------
* CRC-8/SAE-J1850 over bytes 1..7 must equal byte 0, else the frame is rejected
  (``crc_mismatch``);
* the 4-bit counter must advance by 1..3 (``counter_repeat`` for 0, ``counter_jump`` beyond);
* ``warning_status`` must be 0 (valid); frames with another status are counted ``not_valid``
  and never acted on;
* timeout: when no accepted frame came for ``timeout_s`` (default 0.1 s = 5 periods of the
  50 Hz warning) the link counts as lost (``timeouts`` counts each loss once): the last level is
  forgotten until a new accepted frame arrives. A loss after an intervention has started does
  not release the brakes (fail-safe: an intervention is latched).

Intervention (``--react``)
--------------------------
The first accepted frame with ``warning_level >= trigger_level`` (default 2, "warning") at
bench time t_w starts an intervention that lasts to the end of the run::

    t_a   = t_w + delay_s                                   actuation start (dead time)
    p(t)  = clip((t - t_a) / rise_time_s, 0, 1)             brake pressure, fraction of full
    T_b,i = max(T_b,i,driver, p(t) T_full)                  brake torque, every wheel i
    T_d,i = 0                      for t >= t_a             drive torque cut (cut_drive_torque)

Stated actuator dynamics (defaults): dead time ``delay_s`` = 100 ms (CAN reception, ECU cycle
and hydraulic dead time); brake pressure rises linearly from 0 to full in ``rise_time_s`` =
300 ms (a pressure build-up rate of 1/0.3 of full per second, as an ESC pump's); full brake
torque ``brake_torque_full_nm`` = 2500 N m per wheel on all four wheels (a mid-size SUV's
disc brakes at about 100 bar: 4 x 2500 N m / 0.36 m = 27.8 kN, 1.18 g on the 2400 kg SUV, so
the wheels can lock -- no ABS is modelled); steering is left to the driver.

Time: every time here is the bench's simulated time axis (``hil.pacing``), so the ECU acts
at the right simulated instant at any ``--speed``. The simulator calls :meth:`Ecu.override`
at every integration step (``Simulator.set_input_override``); frames reach the ECU between
the bench's simulation blocks, which run ahead of the wall clock by less than ``delay_s``, so
an actuation is never scheduled in the simulator's past (``late_actuations`` counts it if it
ever were: then the actuation starts at the first step not yet computed).

Symbols: t bench time [s]; T_b brake torque [N m], T_d drive torque [N m], p pressure fraction
[-].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vdps_hil.codecs.can_dbc import WARNING
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.model.core import Inputs
from vdps_hil.units import NS_PER_S

__all__ = ["ActuatorConfig", "WarningMonitor", "Ecu", "TRIGGER_LEVEL"]

TRIGGER_LEVEL = 2
"""``warning_level`` that starts an intervention (2 = "warning", ``prediction.warning``)."""


@dataclass(frozen=True)
class ActuatorConfig:
    """The ECU's reaction (module docstring); SI units."""

    delay_s: float = 0.1
    rise_time_s: float = 0.3
    brake_torque_full_nm: float = 2500.0
    cut_drive_torque: bool = True
    trigger_level: int = TRIGGER_LEVEL
    timeout_s: float = 0.1

    def __post_init__(self):
        if not (self.delay_s >= 0.1):
            raise ValueError(f"delay_s must be >= 0.1 s (a real actuator's dead time), got {self.delay_s}")
        for name in ("rise_time_s", "brake_torque_full_nm", "timeout_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        if self.trigger_level not in (1, 2, 3):
            raise ValueError("trigger_level must be 1, 2 or 3")

    @property
    def brake_rate_nmps(self) -> float:
        """Brake torque build-up rate per wheel [N m/s]."""
        return self.brake_torque_full_nm / self.rise_time_s


class WarningMonitor:
    """Reception checks of the module docstring. ``feed(t_ns, msg) -> dict | None`` (the
    accepted frame's fields with ``t_ns``), ``check(t_ns) -> bool`` (True when the link has just
    timed out)."""

    def __init__(self, timeout_s: float = 0.1):
        self.decoder = VdpsCanDecoder(source="ecu")
        self.timeout_ns = int(round(timeout_s * NS_PER_S))
        self.last_ok_ns: int | None = None
        self.timed_out = False
        self.timeouts = 0
        self.not_valid = 0
        self.other_frames = 0
        self.last: dict | None = None

    def feed(self, t_ns: int, msg) -> dict | None:
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            self.other_frames += 1
            return None
        samples = self.decoder.decode(int(t_ns), msg.arbitration_id, bytes(msg.data[:msg.dlc]), False)
        if not samples:
            return None
        s = samples[0]
        if s.kind != "warning":
            self.other_frames += 1
            return None
        if not s.valid:
            self.not_valid += 1
            return None
        self.last_ok_ns = int(t_ns)
        self.timed_out = False
        self.last = {"t_ns": int(t_ns), **s.fields}
        return self.last

    def check(self, t_ns: int) -> bool:
        if self.timed_out or self.last_ok_ns is None:
            return False
        if t_ns - self.last_ok_ns > self.timeout_ns:
            self.timed_out = True
            self.timeouts += 1
            self.last = None
            return True
        return False

    @property
    def rejected(self) -> dict[str, int]:
        c = self.decoder.counters[WARNING]
        return {k: int(c[k]) for k in ("crc_mismatch", "counter_repeat", "counter_jump", "out_of_range",
                                       "dlc_mismatch", "undecodable")}

    def counters(self) -> dict:
        c = self.decoder.counters[WARNING]
        return {"accepted": int(c["accepted"]), "lost_frames": int(c["lost_frames"]), **self.rejected,
                "not_valid": self.not_valid, "timeouts": self.timeouts, "other_frames": self.other_frames}


@dataclass
class _State:
    t_trigger_ns: int | None = None
    t_act_ns: int | None = None
    level_at_trigger: int = 0
    events: list = field(default_factory=list)


class Ecu:
    """The simulated ECU (module docstring).

    ``on_frame(t_ns, msg)`` for every frame the bench's CAN bus delivers to it; ``poll(t_ns)``
    between frames (timeouts); ``attach(sim)`` installs :meth:`override` as the simulator's
    input override (only with ``react``). ``summary()``: what it saw and did."""

    def __init__(self, config: ActuatorConfig | None = None, react: bool = False):
        self.config = config or ActuatorConfig()
        self.react = bool(react)
        self.monitor = WarningMonitor(self.config.timeout_s)
        self._st = _State()
        self._sim_t_ns = 0
        self.late_actuations = 0
        self.first_warning_ns: int | None = None
        self.max_level = 0

    def attach(self, sim) -> None:
        if self.react:
            sim.set_input_override(self.override)
        self._sim = sim

    @property
    def triggered(self) -> bool:
        return self._st.t_trigger_ns is not None

    @property
    def actuation_start_ns(self) -> int | None:
        return self._st.t_act_ns

    @property
    def events(self) -> list[dict]:
        return list(self._st.events)

    def on_frame(self, t_ns: int, msg) -> None:
        f = self.monitor.feed(t_ns, msg)
        if f is None:
            return
        level = int(f["warning_level"])
        self.max_level = max(self.max_level, level)
        if level >= self.config.trigger_level and self.first_warning_ns is None:
            self.first_warning_ns = int(t_ns)
            self._st.events.append({"kind": "warning_received", "t_s": t_ns / NS_PER_S, "level": level})
        if self.react and level >= self.config.trigger_level and self._st.t_trigger_ns is None:
            st = self._st
            st.t_trigger_ns = int(t_ns)
            st.level_at_trigger = level
            t_act = int(t_ns) + int(round(self.config.delay_s * NS_PER_S))
            sim = getattr(self, "_sim", None)
            if sim is not None and sim.t_ns > t_act:  # the simulator is already past it
                self.late_actuations += 1
                t_act = sim.t_ns
            st.t_act_ns = t_act
            st.events.append({"kind": "intervention", "t_s": t_ns / NS_PER_S,
                              "actuation_t_s": t_act / NS_PER_S,
                              "full_brake_t_s": t_act / NS_PER_S + self.config.rise_time_s})

    def poll(self, t_ns: int) -> None:
        if self.monitor.check(t_ns):
            self._st.events.append({"kind": "warning_timeout", "t_s": t_ns / NS_PER_S})

    def brake_fraction(self, t_s: float) -> float:
        """p(t) of the module docstring (0 before the actuation)."""
        t_act = self._st.t_act_ns
        if t_act is None:
            return 0.0
        return min(max((t_s - t_act / NS_PER_S) / self.config.rise_time_s, 0.0), 1.0)

    def override(self, t_s: float, u: Inputs) -> Inputs:
        """The simulator's input override: the driver's inputs, or the intervention's."""
        t_act = self._st.t_act_ns
        if t_act is None or t_s * NS_PER_S < t_act - 1:
            return u
        c = self.config
        p = self.brake_fraction(t_s)
        tb = p * c.brake_torque_full_nm
        drive = (0.0, 0.0, 0.0, 0.0) if c.cut_drive_torque else u.wheel_torque_nm
        brake = tuple(max(b, tb) for b in u.brake_torque_nm)
        return Inputs(u.steer_wheel_angle_rad, drive, brake)

    def summary(self) -> dict:
        st, c = self._st, self.config
        return {"react": self.react,
                "actuator": {"delay_s": c.delay_s, "rise_time_s": c.rise_time_s,
                             "brake_torque_full_nm_per_wheel": c.brake_torque_full_nm,
                             "brake_rate_nmps_per_wheel": c.brake_rate_nmps,
                             "cut_drive_torque": c.cut_drive_torque, "trigger_level": c.trigger_level,
                             "timeout_s": c.timeout_s},
                "first_warning_t_s": None if self.first_warning_ns is None else self.first_warning_ns / NS_PER_S,
                "max_level": self.max_level,
                "intervention_t_s": None if st.t_trigger_ns is None else st.t_trigger_ns / NS_PER_S,
                "actuation_t_s": None if st.t_act_ns is None else st.t_act_ns / NS_PER_S,
                "full_brake_t_s": None if st.t_act_ns is None else st.t_act_ns / NS_PER_S + c.rise_time_s,
                "late_actuations": self.late_actuations,
                "frames": self.monitor.counters(), "events": self.events}
