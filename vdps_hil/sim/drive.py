"""The drive writer: the truth simulator plus the sensor models, on the real wire formats, into an
MCAP recording with the project's layout (``record.schemas``).

Topics written
--------------
==========================  =================================================================
``/raw/can/<bus>``          every chassis CAN frame (``dbc/vdps.dbc``: wheel speeds front/rear,
                            suspension, wheel torque, steering) with rolling counters, stamped at
                            reception (``sim.wire``: ID-ordered burst after each sampling instant)
``/raw/serial/imu``         Xsens MTData2 bytes (921600 Bd) as read chunks (5 ms windows)
``/raw/serial/gnss``        NMEA GGA, RMC and the profile's attitude sentence (115200 Bd) as read
                            chunks
``/truth/state``            the simulator's 100 Hz truth snapshot (``sim.simulator``)
``/truth/events``           rollover events (tip-up, point of no return; at the snapshot that
                            detected them) and fault start/end (at their times)
==========================  =================================================================

Metadata records: ``vdps.recording`` (layout, tool, DBC hash and ``source = vdps sim``: nothing
about the scenario, effects or faults) and ``truth.drive`` / ``truth.summary`` (scenario,
vehicle, effects with their parameters, faults, profile, seed, the IMU's drawn calibration
errors, the ENU origin; the summary at the end). Nothing under ``/raw/`` carries an effect name,
a fault name or a truth value: the raw documents hold only the schema's keys, and their channel
metadata only bus/device, baud and format.

Processing runs in blocks of ``block_s`` simulated seconds: the simulator steps (a step hook
records the truth every sensor needs), then each sensor samples the block vectorised, the
faults act, the messages are encoded (``sim.wire``) and written. CAN frames that would be
received after the block's end wait for the next block, so each topic stays in time order
(unless a ``clock_jump`` makes a device's clock go back). At the end everything measured by the
last step is delivered (the logger runs until the devices have sent it).

Sinks: the same sensor path feeds any :class:`~vdps_hil.sim.sinks.DriveSink`. ``Drive.run(output)``
uses :class:`~vdps_hil.sim.sinks.RecordingSink` (the recording above); ``Drive.start(sink)`` returns
a :class:`~vdps_hil.sim.session.DriveSession` that a caller steps block by block (``advance``),
e.g. the HIL bench
(``vdps_hil.hil``), whose sink puts the frames and read chunks on a live CAN bus and
pseudo-terminals at their times, paced to the wall clock, while an ECU acts on the simulator
through ``session.sim.set_input_override``. For one seed and block length the sink receives
the same output whichever sink it is.
"""

from __future__ import annotations

import math
import os
import time
from typing import IO, Any, Iterable, Mapping

from vdps_hil.codecs.can_dbc import DEFAULT_DBC_PATH, VdpsDbc, load_dbc
from vdps_hil.model.effects import EffectConfigError, EffectSet, effects_from_names
from vdps_hil.model.params import Vehicle, VehicleFileError, load_vehicle
from vdps_hil.record import schemas as S
from vdps_hil.record.writer import RecordingWriter
from vdps_hil.units import NS_PER_S

from .faults import FaultError, FaultSet
from .profiles import ProfileError, SensorProfile, load_profile
from .scenarios import Scenario, load_scenario
from .session import DriveSession, DriveSummary
from .signals import ScenarioError
from .sinks import DriveSink, RecordingSink
from .truth_backends import TruthBackendError, truth_backend

__all__ = ["Drive", "DriveError", "parse_effect_spec", "DEFAULT_PROFILE", "DEFAULT_BUS", "CONFIG_ERRORS", "MAX_DURATION_S"]

MAX_DURATION_S = 86400.0
"""Longest drive the simulator takes (a day; the one-hour drives of tools/make_long_drive.py are
well inside): a longer one is a mistyped option, not a test drive."""

DEFAULT_PROFILE = "table1-susp1k"
"""Default sensor profile: Table 1 with the suspension at 1 kHz (see its file for why)."""
DEFAULT_BUS = "vdps"
"""Logical CAN bus name (``/raw/can/vdps``; the signal map ``configs/signalmaps/vdps.toml``)."""


class DriveError(ValueError):
    """A drive that cannot be set up (one-line message)."""


CONFIG_ERRORS = (DriveError, ScenarioError, ProfileError, FaultError, EffectConfigError, VehicleFileError,
                 TruthBackendError)
"""Exceptions that mean a bad configuration (one line for the user)."""


def parse_effect_spec(spec: str) -> tuple[str, dict[str, float]]:
    """``NAME`` or ``NAME:param=value,...`` -> (name, {param: value})."""
    name, _, rest = str(spec).strip().partition(":")
    params: dict[str, float] = {}
    if rest.strip():
        for item in rest.split(","):
            k, eq, v = item.partition("=")
            if not eq or not k.strip():
                raise DriveError(f"effect {name!r}: bad parameter {item!r} (expected param=value)")
            try:
                params[k.strip()] = float(v)
            except ValueError:
                raise DriveError(f"effect {name!r}: {k.strip()} must be a number, got {v.strip()!r}") from None
    if not name:
        raise DriveError(f"bad effect {spec!r}: expected NAME or NAME:param=value,...")
    return name, params


class Drive:
    """One simulated drive (module docstring).

    Parameters: ``scenario`` (a Scenario or a name/path), ``profile`` (a SensorProfile or a name;
    default ``table1-susp1k``), ``seed``, ``vehicle`` (a truth Vehicle or file; default the
    scenario's), ``effects`` (extra effect specs ``NAME[:param=value,...]`` on top of the
    scenario's), ``faults`` (fault specs, see ``sim.faults``; the scenario's ``faults`` list, if
    the scenario file has one, comes first), ``duration_s`` (default the scenario's), ``bus``
    (CAN bus name), ``read_period_s`` (serial read window), ``block_s`` (processing block),
    ``dbc`` (path; default ``dbc/vdps.dbc``), ``truth`` (a truth backend spec,
    ``sim.truth_backends``: default our simulator; ``commonroad-mb:1`` brings its own vehicle, so
    ``vehicle`` is refused with it) and ``flat_road`` (that backend's option for a banked or
    graded scenario).

    ``run(output)`` writes the recording (a path or a binary stream) and returns a
    :class:`DriveSummary`.
    """

    def __init__(self, scenario: Scenario | str, *, profile: SensorProfile | str = DEFAULT_PROFILE,
                 seed: int = 0, vehicle: Vehicle | str | None = None, effects: Iterable[str] = (),
                 faults: Iterable[Any] = (), duration_s: float | None = None, bus: str = DEFAULT_BUS,
                 read_period_s: float = 0.005, block_s: float = 0.5, dbc: str | os.PathLike | None = None,
                 truth: str | None = None, flat_road: bool = False):
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        self.profile = profile if isinstance(profile, SensorProfile) else load_profile(profile)
        self.seed = int(seed)
        self.truth = truth_backend(truth, flat_road=flat_road)
        if self.truth is None and flat_road:
            raise DriveError("flat_road applies to a truth backend with a flat road only (--truth)")
        if self.truth is not None and vehicle is not None:
            raise DriveError(f"--vehicle does not apply with --truth {self.truth.spec}: the backend brings its vehicle")
        if vehicle is None:
            vehicle = self.scenario.vehicle if self.truth is None else self.truth.vehicle
        elif not isinstance(vehicle, Vehicle):
            vehicle = load_vehicle(vehicle, "truth")
        self.vehicle = vehicle
        self.effect_set = self._effects(list(effects))
        self.truth_notes: list[str] = []
        if self.truth is not None:
            self.effect_set, self.truth_notes = self.truth.prepare(self.scenario, self.effect_set)
        dur = self.scenario.duration_s if duration_s is None else float(duration_s)
        if not (dur > 0 and math.isfinite(dur)):
            raise DriveError(f"duration must be a positive number of seconds, got {duration_s!r}")
        if dur > MAX_DURATION_S:
            raise DriveError(f"duration must be at most {MAX_DURATION_S:g} s (a day of driving), got {dur:g}")
        self.duration_s = dur
        S.check_name("bus", bus)
        self.bus = bus
        if not read_period_s > 0 or not block_s > 0:
            raise DriveError("read_period_s and block_s must be positive")
        self.read_period_ns = int(round(read_period_s * NS_PER_S))
        self.block_s = float(block_s)
        self.dbc_path = DEFAULT_DBC_PATH if dbc is None else dbc
        self.dbc: VdpsDbc = load_dbc(dbc)
        scenario_faults = self.scenario.raw.get("faults", []) if isinstance(self.scenario.raw, Mapping) else []
        if not isinstance(scenario_faults, list):
            raise DriveError(f"scenario {self.scenario.name!r}: faults must be a list")
        self.fault_specs = [*scenario_faults, *faults]
        """The fault specs of the drive (the scenario's first); each session builds its FaultSet."""
        self.faults = FaultSet(self.fault_specs, seed=self.seed, dbc=self.dbc)  # checked now

    def _effects(self, specs: list[str]) -> EffectSet:
        sc = self.scenario
        names = list(sc.effect_names)
        params: dict[str, dict[str, float]] = {k: dict(v) for k, v in sc.effect_params.items()}
        for spec in specs:
            name, p = parse_effect_spec(spec)
            if name not in names:
                names.append(name)
            if p:
                params.setdefault(name, {}).update(p)
        effects = effects_from_names(names, self.vehicle.effects, params)
        for e in effects:
            e.check_plausible()
        return effects

    def run(self, output: str | os.PathLike | IO[bytes], progress=None) -> DriveSummary:
        """Write the drive to a recording (a path or a binary stream) and return its summary;
        ``progress(simulated_s, duration_s)`` after each block (a progress bar's callback)."""
        wall0 = time.perf_counter()
        writer = RecordingWriter(output, metadata={"source": "vdps sim"},
                                 content_hashes={"dbc.vdps": self.dbc_path},
                                 sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
        sink = RecordingSink(writer)
        try:
            session = self.start(sink)
            end_s = session.end_ns / 1e9
            while session.advance():
                if progress is not None:
                    progress(session.t_ns / 1e9, end_s)
            summary = session.summary(output, wall0)
            sink.metadata("truth.summary", summary.to_json())
        finally:
            writer.close()
        summary.wall_time_s = time.perf_counter() - wall0
        summary.messages = dict(writer.stats.messages)
        return summary

    def start(self, sink: DriveSink) -> DriveSession:
        """Set up a drive whose output goes to ``sink`` and return the session that steps it
        (``advance``); the simulator is ``session.sim`` (input override, state). Fresh sensor,
        fault and simulator state per call: two sessions of one Drive with the same seed produce
        the same output."""
        return DriveSession(self, sink)
