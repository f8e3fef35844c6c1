"""Scenarios: a drive fully specified in one TOML file (``configs/scenarios/<name>.toml``).

A scenario names its vehicle (truth file, default ``sedan-truth``), the road plane, the wind,
the effects switched on (magnitudes: effect defaults < vehicle ``[effects]`` < the scenario's
``[effect_params.<name>]``), the initial state, the duration and the inputs: an open-loop
schedule per input channel and/or a closed-loop driver (``[driver]``, see
:mod:`vdps_hil.sim.driver`); a channel given in ``[inputs]`` overrides the driver's.

File layout (all keys optional unless marked; unknown keys are one-line errors)::

    name = "paper"                       # required, equals the file stem
    description = "..."
    vehicle = "sedan-truth"
    duration_s = 15.0                    # required
    effects = ["magic_formula_tire"]
    stop_at_point_of_no_return = false
    [effect_params.magic_formula_tire]   # overrides of effect parameters
    [road]    bank_deg = 2.0   grade_deg = -2.0          # bank > 0 right edge low; grade < 0 downhill
    [wind]    enu_mps = [0.0, 0.0, 0.0]
    [initial] speed_mps = 25.0  heading_deg = 0.0  east_m = 0.0  north_m = 0.0
    [inputs]  <channel> = <signal>       # channels: steer_wheel_angle_rad, wheel_torque_nm_1..4,
                                         #           brake_torque_nm_1..4
    [driver]  ...                        # see driver.DriverSpec

Signals: see :mod:`vdps_hil.sim.signals` (const, sine, sweep, points, step; hold_from_s, then).

Loading uses :mod:`tomllib` only (no code execution); errors are one line
(:class:`ScenarioError`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from vdps_hil.model.core import Env, Inputs
from vdps_hil.model.effects import EffectConfigError, EffectSet, effects_from_names
from vdps_hil.model.params import CONFIG_DIR, Vehicle, VehicleFileError, load_vehicle

from .driver import make_driver, validate_driver_spec
from .faults import FaultError, parse_fault
from .signals import ScenarioError, build_signal, read_number

SCENARIO_DIR = CONFIG_DIR / "scenarios"

CHANNELS: tuple[str, ...] = ("steer_wheel_angle_rad",
                             *(f"wheel_torque_nm_{i}" for i in range(1, 5)),
                             *(f"brake_torque_nm_{i}" for i in range(1, 5)))


# ---------------------------------------------------------------------- scenario
_TOP_KEYS = {"name", "description", "vehicle", "duration_s", "effects", "effect_params",
             "stop_at_point_of_no_return", "road", "wind", "initial", "inputs", "driver", "notes",
             "faults"}


@dataclass(frozen=True)
class Scenario:
    """A parsed scenario (see the module docstring). ``raw`` is the TOML document."""

    name: str
    description: str
    vehicle_name: str
    duration_s: float
    effect_names: tuple[str, ...]
    effect_params: Mapping[str, Mapping[str, float]]
    bank_rad: float
    grade_rad: float
    wind_enu_mps: tuple[float, float, float]
    initial_speed_mps: float
    initial_heading_rad: float
    initial_east_m: float
    initial_north_m: float
    signals: Mapping[str, Callable[[float], float]]
    driver_spec: Mapping[str, Any] | None
    stop_at_point_of_no_return: bool
    path: str = ""
    raw: Mapping[str, Any] = field(default_factory=dict, repr=False)

    @property
    def vehicle(self) -> Vehicle:
        try:
            return load_vehicle(self.vehicle_name, "truth")
        except VehicleFileError as e:
            raise ScenarioError(f"scenario {self.name!r}: {e}") from None

    def env(self) -> Env:
        return Env(self.bank_rad, self.grade_rad, self.wind_enu_mps)

    def effect_set(self, vehicle: Vehicle | None = None, extra: tuple[str, ...] = ()) -> EffectSet:
        """The scenario's effects (plus ``extra`` names) with magnitudes from the vehicle's
        ``[effects]`` table and the scenario's ``[effect_params]``."""
        vehicle = vehicle or self.vehicle
        names = list(self.effect_names) + [n for n in extra if n not in self.effect_names]
        try:
            return effects_from_names(names, vehicle.effects, self.effect_params)
        except EffectConfigError as e:
            raise ScenarioError(f"scenario {self.name!r}: {e}") from None

    def scheduled_inputs(self, t_s: float, base: Inputs | None = None) -> Inputs:
        """The open-loop inputs at t (channels not in the schedule from ``base`` or zero)."""
        b = base or _ZERO_INPUTS
        sig = self.signals
        steer = sig["steer_wheel_angle_rad"](t_s) if "steer_wheel_angle_rad" in sig else b.steer_wheel_angle_rad
        tq = tuple(sig[f"wheel_torque_nm_{i}"](t_s) if f"wheel_torque_nm_{i}" in sig else b.wheel_torque_nm[i - 1]
                   for i in range(1, 5))
        br = tuple(max(0.0, sig[f"brake_torque_nm_{i}"](t_s)) if f"brake_torque_nm_{i}" in sig else b.brake_torque_nm[i - 1]
                   for i in range(1, 5))
        return _inputs(steer, tq, br)

    def schedule_function(self) -> Callable[[float, Inputs | None], Inputs]:
        """A fast ``fn(t, base=None) -> Inputs`` equal to :meth:`scheduled_inputs`."""
        sig = self.signals
        s_fn = sig.get("steer_wheel_angle_rad")
        t_fns = tuple(sig.get(f"wheel_torque_nm_{i}") for i in range(1, 5))
        b_fns = tuple(sig.get(f"brake_torque_nm_{i}") for i in range(1, 5))
        no_brakes = all(f is None for f in b_fns)
        all_t = all(f is not None for f in t_fns)
        t1, t2, t3, t4 = t_fns
        zero4 = (0.0, 0.0, 0.0, 0.0)

        def fn(t, base=None):
            b = base or _ZERO_INPUTS
            steer = s_fn(t) if s_fn is not None else b.steer_wheel_angle_rad
            if all_t:
                tq = (t1(t), t2(t), t3(t), t4(t))
            else:
                tq = tuple(f(t) if f is not None else b.wheel_torque_nm[k] for k, f in enumerate(t_fns))
            if no_brakes:
                br = b.brake_torque_nm if base is not None else zero4
            else:
                br = tuple(max(0.0, f(t)) if f is not None else b.brake_torque_nm[k] for k, f in enumerate(b_fns))
            return _inputs(steer, tq, br)

        return fn

    def input_source(self, model, env: Env):
        """``source(t, x) -> Inputs`` for the simulator: the driver (if any) with the scheduled
        channels replacing its outputs."""
        sched = self.schedule_function()
        if self.driver_spec is None:
            return lambda t, x: sched(t)
        driver = make_driver(self.driver_spec, model, env, self, where=f"scenario {self.name!r} [driver]")
        if not self.signals:
            return driver
        return lambda t, x: sched(t, driver(t, x))


_ZERO_INPUTS = Inputs()


def _inputs(steer, tq, br) -> Inputs:
    u = object.__new__(Inputs)
    object.__setattr__(u, "steer_wheel_angle_rad", float(steer))
    object.__setattr__(u, "wheel_torque_nm", tq)
    object.__setattr__(u, "brake_torque_nm", br)
    return u


def _table(doc: Mapping, key: str, allowed: set[str], where: str) -> dict:
    t = doc.get(key, {})
    if not isinstance(t, Mapping):
        raise ScenarioError(f"{where}: [{key}] must be a table")
    unknown = sorted(set(t) - allowed)
    if unknown:
        raise ScenarioError(f"{where}[{key}]: unknown key {unknown[0]!r}")
    return dict(t)


def parse_scenario(text: str, origin: str = "<string>") -> Scenario:
    """Parse a scenario TOML document; one-line ScenarioError on any problem."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{origin}: malformed TOML: {e}") from None
    unknown = sorted(set(doc) - _TOP_KEYS)
    if unknown:
        raise ScenarioError(f"{origin}: unknown key {unknown[0]!r}")
    name = doc.get("name")
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"{origin}: missing name")
    dur = read_number(doc, "duration_s", origin)
    if dur <= 0:
        raise ScenarioError(f"{origin}.duration_s: must be positive")
    effects = doc.get("effects", [])
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise ScenarioError(f"{origin}.effects: expected a list of effect names")
    eparams = doc.get("effect_params", {})
    if not isinstance(eparams, Mapping) or not all(isinstance(v, Mapping) for v in eparams.values()):
        raise ScenarioError(f"{origin}[effect_params]: expected tables of parameters")
    road = _table(doc, "road", {"bank_deg", "grade_deg"}, origin)
    wind = _table(doc, "wind", {"enu_mps"}, origin)
    init = _table(doc, "initial", {"speed_mps", "heading_deg", "east_m", "north_m"}, origin)
    inputs = _table(doc, "inputs", set(CHANNELS), origin)
    w = wind.get("enu_mps", [0.0, 0.0, 0.0])
    if not (isinstance(w, list) and len(w) == 3):
        raise ScenarioError(f"{origin}[wind].enu_mps: expected 3 numbers")
    wv = tuple(read_number({"w": e}, "w", f"{origin}[wind].enu_mps") for e in w)
    signals = {ch: build_signal(spec, f"{origin}[inputs].{ch}") for ch, spec in inputs.items()}
    driver = doc.get("driver")
    if driver is not None and not isinstance(driver, Mapping):
        raise ScenarioError(f"{origin}[driver]: must be a table")
    stop = doc.get("stop_at_point_of_no_return", False)
    if not isinstance(stop, bool):
        raise ScenarioError(f"{origin}.stop_at_point_of_no_return: expected true or false")
    sc = Scenario(
        name=name, description=str(doc.get("description", "")),
        vehicle_name=str(doc.get("vehicle", "sedan-truth")), duration_s=dur,
        effect_names=tuple(effects), effect_params={k: dict(v) for k, v in eparams.items()},
        bank_rad=math.radians(read_number(road, "bank_deg", f"{origin}[road]", 0.0)),
        grade_rad=math.radians(read_number(road, "grade_deg", f"{origin}[road]", 0.0)),
        wind_enu_mps=wv,
        initial_speed_mps=read_number(init, "speed_mps", f"{origin}[initial]", 0.0),
        initial_heading_rad=math.radians(read_number(init, "heading_deg", f"{origin}[initial]", 0.0)),
        initial_east_m=read_number(init, "east_m", f"{origin}[initial]", 0.0),
        initial_north_m=read_number(init, "north_m", f"{origin}[initial]", 0.0),
        signals=signals, driver_spec=dict(driver) if driver is not None else None,
        stop_at_point_of_no_return=stop, path=origin, raw=doc)
    # faults (sensor-level, applied by sim.drive): validate now, one-line errors at load time
    faults = doc.get("faults", [])
    if not isinstance(faults, list):
        raise ScenarioError(f"{origin}.faults: expected a list of fault specs")
    for spec in faults:
        try:
            parse_fault(spec)
        except FaultError as e:
            raise ScenarioError(f"{origin}.faults: {e}") from None
    # validate effect names and parameters now (one-line errors at load time)
    from vdps_hil.model.effects import REGISTRY
    for n in sc.effect_names:
        if n not in REGISTRY:
            raise ScenarioError(f"{origin}: unknown effect {n!r} (known: {', '.join(REGISTRY)})")
    try:
        effects_from_names(sc.effect_names, {}, sc.effect_params)
    except EffectConfigError as e:
        raise ScenarioError(f"{origin}: {e}") from None
    if driver is not None:
        validate_driver_spec(driver, f"{origin}[driver]")
    return sc


def scenario_names() -> list[str]:
    """The scenarios shipped in configs/scenarios/."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A scenario by name (``configs/scenarios/<name>.toml``) or path."""
    p = Path(name_or_path)
    if p.suffix != ".toml":
        p = SCENARIO_DIR / f"{name_or_path}.toml"
        if not p.exists():
            raise ScenarioError(f"unknown scenario {str(name_or_path)!r} (known: {', '.join(scenario_names())})")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"cannot read scenario file {p}: {e.__class__.__name__}") from None
    sc = parse_scenario(text, str(p))
    if sc.name != p.stem:
        raise ScenarioError(f"{p}: name {sc.name!r} differs from the file name {p.stem!r}")
    return sc
