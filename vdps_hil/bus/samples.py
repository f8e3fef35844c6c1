"""Bus samples and the one catalogue of bus field names.

A :class:`Sample` is what every adapter, decoder and the simulator's sensor models publish and
what the estimator consumes: a set of catalogue fields (SI values) measured at one instant by
one source. Names carry their unit; the catalogue below is the only place they are defined.

Frames and signs follow :mod:`vdps_hil.conventions`: body axes ISO 8855 (x forward, y left,
z up), wheels/corners 1..4 = FL, FR, RR, RL, pitch nose-up positive, roll right-side-down
positive, yaw CCW from East.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping


@dataclass(frozen=True, slots=True)
class FieldSpec:
    name: str
    unit: str
    description: str


def _wheel(stem: str, unit_suffix: str, unit: str, desc: str) -> list[FieldSpec]:
    return [FieldSpec(f"{stem}_{unit_suffix}_{i}", unit, f"{desc}, wheel {i} ({w})")
            for i, w in zip(range(1, 5), ("FL", "FR", "RR", "RL"))]


def _axes(stem: str, unit_suffix: str, unit: str, desc: str) -> list[FieldSpec]:
    return [FieldSpec(f"{stem}_{unit_suffix}_{a}", unit, f"{desc}, body {a} axis") for a in "xyz"]


_SPECS: list[FieldSpec] = [
    # --- CAN: chassis sensors (dbc/vdps.dbc) ---
    *_wheel("wheel_speed", "radps", "rad/s", "Wheel spin rate from the tachometer (positive rolling forward)"),
    *_wheel("wheel_torque", "nm", "N m", "Drive/brake torque applied to the wheel (positive driving)"),
    FieldSpec("steer_wheel_angle_rad", "rad", "Steering wheel angle, positive to the left (CCW)"),
    *_wheel("susp_deflection", "m", "m", "Suspension deflection from design ride height, compression positive"),
    # --- IMU (serial, or an ESC cluster on CAN) ---
    *_axes("specific_force", "mps2", "m/s^2", "Accelerometer specific force (a - g)"),
    *_axes("angular_rate", "radps", "rad/s", "Gyroscope angular rate"),
    FieldSpec("imu_temperature_c", "degC", "IMU temperature"),
    # --- GNSS position/velocity (NMEA GGA/RMC/VTG) ---
    FieldSpec("gnss_lat_deg", "deg", "WGS-84 latitude"),
    FieldSpec("gnss_lon_deg", "deg", "WGS-84 longitude"),
    FieldSpec("gnss_alt_m", "m", "Altitude above mean sea level (GGA)"),
    FieldSpec("gnss_geoid_sep_m", "m", "Geoid separation (GGA)"),
    FieldSpec("gnss_fix_quality", "1", "GGA fix quality (0 invalid, 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float)"),
    FieldSpec("gnss_num_sats", "1", "Satellites used"),
    FieldSpec("gnss_hdop", "1", "Horizontal dilution of precision"),
    FieldSpec("gnss_pos_sigma_h_m", "m", "Horizontal position standard deviation (configured or reported)"),
    FieldSpec("gnss_pos_sigma_v_m", "m", "Vertical position standard deviation (configured or reported)"),
    FieldSpec("gnss_speed_mps", "m/s", "Speed over ground"),
    FieldSpec("gnss_course_rad", "rad", "Course over ground as a paper yaw (CCW from East)"),
    # --- GNSS attitude (multi-antenna: PASHR, HPR, PTNL AVR, HDT/THS) ---
    FieldSpec("gnss_yaw_rad", "rad", "Absolute yaw psi_g (CCW from East)"),
    FieldSpec("gnss_pitch_rad", "rad", "Absolute pitch theta_g (nose up positive)"),
    FieldSpec("gnss_roll_rad", "rad", "Absolute roll phi_g (right side down positive)"),
    FieldSpec("gnss_yaw_sigma_rad", "rad", "Yaw standard deviation"),
    FieldSpec("gnss_pitch_sigma_rad", "rad", "Pitch standard deviation"),
    FieldSpec("gnss_roll_sigma_rad", "rad", "Roll standard deviation"),
    # --- ESC cluster / powertrain extras (real cars) ---
    FieldSpec("vehicle_speed_mps", "m/s", "Vehicle reference speed reported by the car"),
    FieldSpec("engine_torque_nm", "N m", "Engine torque reported by the car"),
    FieldSpec("brake_pressure_pa", "Pa", "Brake master cylinder pressure"),
    # --- device health ---
    FieldSpec("seq_counter", "1", "Device sequence counter (detects lost messages)"),
    # --- rollover warning (VDPS_Warning, read back by the ECU) ---
    FieldSpec("warning_level", "1", "0 none, 1 caution, 2 warning, 3 imminent"),
    FieldSpec("warning_time_to_rollover_s", "s", "Predicted time to the point of no return"),
    FieldSpec("warning_peak_roll_rad", "rad", "Predicted peak roll relative to the road"),
    FieldSpec("warning_ltr", "1", "Predicted peak load transfer ratio (-1..1)"),
    FieldSpec("warning_status", "1", "0 valid, 1 not converged, 2 sensor missing, 3 fault"),
    FieldSpec("warning_counter", "1", "Rolling counter 0..15"),
]

FIELDS: dict[str, FieldSpec] = {s.name: s for s in _SPECS}
"""The field catalogue: name -> spec. The only allowed bus field names."""


def field_spec(name: str) -> FieldSpec:
    try:
        return FIELDS[name]
    except KeyError:
        raise KeyError(f"unknown bus field {name!r} (not in vdps_hil.bus.samples.FIELDS)") from None


def check_fields(names) -> None:
    """Raise KeyError naming the first name that is not in the catalogue."""
    for n in names:
        field_spec(n)


def wheel_fields(stem_with_unit: str) -> tuple[str, str, str, str]:
    """``wheel_fields('wheel_speed_radps')`` -> the four per-wheel names in wheel order."""
    return tuple(f"{stem_with_unit}_{i}" for i in range(1, 5))  # type: ignore[return-value]


def axis_fields(stem_with_unit: str) -> tuple[str, str, str]:
    return tuple(f"{stem_with_unit}_{a}" for a in "xyz")  # type: ignore[return-value]


_NEW_DICT = object()  # Sample's default for ``fields``: a new dict


@dataclass(frozen=True, slots=True, init=False)
class Sample:
    """One measurement set from one source at one instant.

    ``t_ns``: monotonic integer nanoseconds, the time the quantity was measured (orders samples).
    ``wall_time_ns``: UTC nanoseconds (MCAP log_time); 0 when unknown.
    ``source``: the logical source, e.g. ``can.vdps``, ``gnss``, ``imu``.
    ``kind``: what the sample is (``wheel_speed``, ``imu``, ``gnss_pos``, ``gnss_att`` ...), used
    to route it to an observation model.
    ``fields``: catalogue name -> SI value. ``valid``: False when the source flagged it (kept so
    the gap is visible, never silently dropped).
    """

    t_ns: int
    source: str
    kind: str
    fields: Mapping[str, float] = field(default_factory=dict)
    wall_time_ns: int = 0
    valid: bool = True

    def __init__(self, t_ns: int, source: str, kind: str, fields: Mapping[str, float] = _NEW_DICT,
                 wall_time_ns: int = 0, valid: bool = True):
        # what the dataclass's own __init__ did (each slot set, ``fields`` a new dict by default,
        # t_ns checked) with the slots' setters fetched once instead of object.__setattr__ by
        # name per field: half the cost of a sample (each decoded frame and packet makes one)
        if not isinstance(t_ns, int):
            raise TypeError(f"t_ns must be int nanoseconds, got {type(t_ns).__name__}")
        _set_t_ns(self, t_ns)
        _set_source(self, source)
        _set_kind(self, kind)
        _set_fields(self, {} if fields is _NEW_DICT else fields)
        _set_wall_time_ns(self, wall_time_ns)
        _set_valid(self, valid)

    def __reduce__(self):
        # pickled as its constructor call (the dataclass default sets each slot by name, twice
        # as slow to load): ``vdps replay --jobs 2`` sends every decoded sample between processes
        return (Sample, (self.t_ns, self.source, self.kind, self.fields, self.wall_time_ns, self.valid))

    def get(self, name: str, default: float = math.nan) -> float:
        return self.fields.get(name, default)

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "wall_time_ns": self.wall_time_ns, "source": self.source,
                "kind": self.kind, "valid": self.valid,
                "fields": {k: (None if (isinstance(v, float) and not math.isfinite(v)) else v)
                           for k, v in self.fields.items()}}

    @classmethod
    def from_json(cls, d: Mapping) -> "Sample":
        return cls(t_ns=int(d["t_ns"]), wall_time_ns=int(d.get("wall_time_ns", 0)),
                   source=str(d["source"]), kind=str(d["kind"]), valid=bool(d.get("valid", True)),
                   fields={k: (math.nan if v is None else float(v)) for k, v in d["fields"].items()})


_set_t_ns, _set_source, _set_kind, _set_fields, _set_wall_time_ns, _set_valid = (
    Sample.__dict__[n].__set__ for n in ("t_ns", "source", "kind", "fields", "wall_time_ns", "valid"))
