"""Sensor sets: which sensors a car has and how its recording feeds the estimator, for the replay
(``vdps replay --sensorset``, or inferred from the recording) and the real-car studies.

A named set (``configs/sensorsets/NAME.toml``, read with tomllib: data only) gives the
``SensorSet`` of the EKF (IMU kind, GNSS kind, suspension, wheel speeds), the ``kind_map`` from
recorded sample kinds to the pipeline's (e.g. the RAV4 signal map's ``esc_imu`` -> ``imu``), the
measurement noise and latencies of the pipeline, the EKF's IMU noise figures and the sample
nodes the set asks for before the pipeline (``[calibration]``: ``ZeroRateCalibration``, the gyro
bias learned at standstill). ``infer_sensor_set`` derives the set from the catalogue fields a
recording (or a signal map) carries.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.ekf_config import EkfConfig, SensorSet
from vdps_hil.estimation.pipeline_config import Latencies, PipelineConfig
from vdps_hil.model.params import CONFIG_DIR

__all__ = ["SENSORSET_DIR", "SensorSetError", "SensorSetConfig", "parse_sensorset", "load_sensorset",
           "infer_sensor_set", "KindMap", "not_used_note", "ZeroRateCalibration"]

SENSORSET_DIR = CONFIG_DIR / "sensorsets"


# ------------------------------------------------------------------------------ sensor sets
class SensorSetError(ValueError):
    """A sensor-set file that cannot be used (one line)."""


@dataclass(frozen=True)
class SensorSetConfig:
    """A named sensor set (``configs/sensorsets/NAME.toml``): which sensors exist
    (``SensorSet``), which recorded sample kinds feed which pipeline kinds (``kind_map``, e.g. the
    RAV4 signal map's ``esc_imu`` -> ``imu``), measurement noise and latencies of the pipeline,
    and the EKF's IMU noise figures. ``pipeline_config()`` builds the ``PipelineConfig``."""

    name: str
    description: str
    sensors: SensorSet
    kind_map: Mapping[str, str]
    ekf: Mapping[str, float]
    pipeline: Mapping[str, float]
    latencies: Latencies
    calibration: Mapping[str, float] = field(default_factory=dict)
    source: str = ""

    def calibration_nodes(self, vehicle=None) -> list:
        """Sample-stream nodes the set asks for before the pipeline (``[calibration]``):
        ``zero_rate = true`` -> ``ZeroRateCalibration`` (standstill from GNSS speed, or wheel
        speeds with the vehicle's rolling radius)."""
        c = dict(self.calibration)
        if not c.pop("zero_rate", False):
            return []
        r = vehicle.tire.rolling_radius_m if (vehicle is not None and self.sensors.wheel_speeds) else None
        return [ZeroRateCalibration(rolling_radius_m=r, **c)]

    def pipeline_config(self, *, estimate_road: bool | None = None, observability_window_s: float | None = 10.0,
                        output_period_s: float = 0.0, latencies: Latencies | None = None,
                        **overrides) -> PipelineConfig:
        ekf = EkfConfig(sensors=self.sensors, estimate_road=estimate_road, **dict(self.ekf))
        kw = dict(self.pipeline)
        kw.update(overrides)
        return PipelineConfig(ekf=ekf, latencies=self.latencies if latencies is None else latencies,
                              observability_window_s=observability_window_s, output_period_s=output_period_s, **kw)

    def with_sensors(self, **changes) -> "SensorSetConfig":
        """The same set with some sensors changed (``SensorSet`` fields), e.g. ``gnss="none"``."""
        return dataclasses.replace(self, sensors=dataclasses.replace(self.sensors, **changes),
                                   name=self.name + "+" + ",".join(f"{k}={v}" for k, v in sorted(changes.items())))


_EKF_KEYS = {"gravity_mps2", "imu_rate_hz", "accel_noise_mps2", "gyro_noise_radps", "accel_model_psd",
             "gyro_model_psd", "substitute_accel_sigma_mps2", "substitute_gyro_sigma_radps", "substitute_corr_time_s",
             "road_angle_rw", "gate_probability", "history_s", "max_step_s", "gyro_bias_sigma_radps",
             "accel_bias_sigma_mps2", "gyro_bias_rw", "accel_bias_rw", "wheel_scale_sigma", "wheel_scale_rw"}
_PIPE_KEYS = {"predict_period_s", "gnss_pos_sigma_h_m", "gnss_pos_sigma_v_m", "gnss_att_sigma_rad",
              "gnss_speed_sigma_mps", "gnss_course_min_speed_mps", "susp_sigma_m", "init_course_sigma_rad",
              "init_level_sigma_rad", "wheel_speed_sigma_mps", "wheel_speed_period_s", "wheel_speed_window_s",
              "wheel_outlier_mps", "wheel_outlier_rel", "wheel_accel_gate_mps2", "wheel_accel_sigma_s",
              "wheel_long_stiffness_n", "nhc_period_s", "nhc_sigma_lat_mps", "nhc_sigma_vert_mps",
              "nhc_slip_rad_per_mps2", "nhc_point_sigma_m", "reacquire_after_gated", "reacquire_velocity_sigma_mps"}
_PIPE_INT_KEYS = {"reacquire_after_gated"}
_LAT_KEYS = {"imu_s", "gnss_s", "suspension_s", "wheel_s", "gnss_vel_s"}
_SENSOR_KEYS = {"imu", "gnss", "suspension", "wheel_speeds"}
_CAL_KEYS = {"speed_still_mps", "min_still_s", "max_age_s"}
_EKF_BOOL_KEYS = {"use_gnss_velocity", "gyro_bias", "accel_bias", "wheel_speed", "wheel_scale_state", "nonholonomic"}


MAX_FIGURE = 1e6
"""Largest magnitude of a sensor-set number (noise figures, rates, periods, latencies in SI):
the shipped sets stay below 1e3; 1e300 passed the finite check and overflowed in the filter."""


def _finite(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SensorSetError(f"{where}: expected a finite number, got {v!r}")
    if abs(v) > MAX_FIGURE:
        raise SensorSetError(f"{where}: expected a number of magnitude at most {MAX_FIGURE:g}, got {v!r}")
    return float(v)


def parse_sensorset(text: str, origin: str = "<string>") -> SensorSetConfig:
    """Parse a sensor-set TOML (tomllib: data only). Keys: ``name``, ``description``,
    ``[sensors]`` (SensorSet fields), ``[kind_map]`` (recorded kind -> pipeline kind),
    ``[ekf]`` (EkfConfig noise figures; angles in degrees where the key ends in ``_deg``/
    ``_degps``), ``[pipeline]`` (PipelineConfig noise figures), ``[latencies]``."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SensorSetError(f"{origin}: malformed TOML: {e}") from None
    allowed = {"name", "description", "sensors", "kind_map", "ekf", "pipeline", "latencies", "calibration"}
    unknown = sorted(set(doc) - allowed)
    if unknown:
        raise SensorSetError(f"{origin}: unknown key {unknown[0]!r}")
    s = doc.get("sensors", {})
    if not isinstance(s, dict) or set(s) - _SENSOR_KEYS:
        raise SensorSetError(f"{origin}[sensors]: keys are {sorted(_SENSOR_KEYS)}")
    try:
        sensors = SensorSet(**s)
    except (TypeError, ValueError) as e:
        raise SensorSetError(f"{origin}[sensors]: {e}") from None
    km = doc.get("kind_map", {})
    if not isinstance(km, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in km.items()):
        raise SensorSetError(f"{origin}[kind_map]: expected recorded kind = \"pipeline kind\"")

    def section(name, keys):
        t = doc.get(name, {})
        if not isinstance(t, dict):
            raise SensorSetError(f"{origin}[{name}]: expected a table")
        out = {}
        for k, v in t.items():
            if name == "ekf" and k in _EKF_BOOL_KEYS:
                if not isinstance(v, bool):
                    raise SensorSetError(f"{origin}[ekf].{k}: expected true or false")
                out[k] = v
                continue
            base = k
            conv = 1.0
            if k.endswith("_deg"):
                base, conv = k[:-4] + "_rad", math.pi / 180.0
            elif k.endswith("_degps"):
                base, conv = k[:-6] + "_radps", math.pi / 180.0
            if base not in keys:
                raise SensorSetError(f"{origin}[{name}]: unknown key {k!r}")
            if name == "pipeline" and k in _PIPE_INT_KEYS:
                if isinstance(v, bool) or not isinstance(v, int):
                    raise SensorSetError(f"{origin}[{name}].{k}: expected an integer")
                out[k] = v
                continue
            out[base] = _finite(v, f"{origin}[{name}].{k}") * conv
        return out

    ekf = section("ekf", _EKF_KEYS)
    pipe = section("pipeline", _PIPE_KEYS)
    lat = section("latencies", _LAT_KEYS)
    cal_t = doc.get("calibration", {})
    if not isinstance(cal_t, dict):
        raise SensorSetError(f"{origin}[calibration]: expected a table")
    cal: dict = {}
    for k, v in cal_t.items():
        if k == "zero_rate":
            if not isinstance(v, bool):
                raise SensorSetError(f"{origin}[calibration].zero_rate: expected true or false")
            cal[k] = v
        elif k in _CAL_KEYS:
            cal[k] = _finite(v, f"{origin}[calibration].{k}")
            if cal[k] <= 0:
                raise SensorSetError(f"{origin}[calibration].{k}: must be positive")
        else:
            raise SensorSetError(f"{origin}[calibration]: unknown key {k!r}")
    try:
        EkfConfig(sensors=sensors, **ekf)
        PipelineConfig(**pipe)
        lats = Latencies(**lat)
    except (TypeError, ValueError) as e:
        raise SensorSetError(f"{origin}: {e}") from None
    return SensorSetConfig(str(doc.get("name", Path(origin).stem)), str(doc.get("description", "")), sensors,
                           dict(km), ekf, pipe, lats, cal, origin)


def load_sensorset(name_or_path) -> SensorSetConfig:
    """``configs/sensorsets/NAME.toml`` or a path."""
    p = Path(name_or_path)
    if p.suffix != ".toml" and not p.exists():
        p = SENSORSET_DIR / f"{name_or_path}.toml"
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise SensorSetError(f"cannot read sensor set {p}: {e.__class__.__name__}: {e}") from None
    return parse_sensorset(text, str(p))


def infer_sensor_set(fields_by_kind: Mapping[str, Iterable[str]]) -> tuple[SensorSet, dict[str, str]]:
    """The sensor set a recording (or a signal map) provides, from the catalogue fields per
    sample kind: (SensorSet, kind_map). A kind carrying all six IMU axes is a ``6axis`` IMU; one
    with only x/y specific force and z rate (an ESC cluster) is ``esc3`` and is mapped to the
    pipeline's ``imu``; GNSS attitude fields make it ``multi_antenna``; ``gnss_pos`` alone
    ``single_antenna``. Raises SensorSetError when there is no IMU at all (the EKF's input)."""
    six = {f"specific_force_mps2_{a}" for a in "xyz"} | {f"angular_rate_radps_{a}" for a in "xyz"}
    esc = {"specific_force_mps2_x", "specific_force_mps2_y", "angular_rate_radps_z"}
    kinds = {k: set(v) for k, v in fields_by_kind.items()}
    kind_map: dict[str, str] = {}
    imu = None
    for name, needed in (("6axis", six), ("esc3", esc)):  # the first kind with all six axes, else the ESC's three
        k = next((k for k, f in kinds.items() if needed <= f), None)
        if k is not None:
            imu = name
            if k != "imu":
                kind_map[k] = "imu"
            break
    if imu is None:
        raise SensorSetError("no IMU: no sample kind carries specific force x/y and yaw rate")
    all_fields = set().union(*kinds.values()) if kinds else set()
    if {"gnss_roll_rad", "gnss_pitch_rad", "gnss_yaw_rad"} & all_fields:
        gnss = "multi_antenna"
    elif "gnss_lat_deg" in all_fields:
        gnss = "single_antenna"
    else:
        gnss = "none"
    susp = all(f"susp_deflection_m_{i}" in all_fields for i in range(1, 5))
    wheels = all(f"wheel_speed_radps_{i}" in all_fields for i in range(1, 5))
    return SensorSet(imu=imu, gnss=gnss, suspension=susp, wheel_speeds=wheels), kind_map


class KindMap:
    """A sensor set's ``kind_map`` applied to samples: ``kind_map(sample)`` is the sample with its
    recorded kind renamed to the pipeline's (``esc_imu`` -> ``imu``), or None for a sample of a
    kind the map feeds from another recorded kind. A recording may hold a sensor the set does not
    name: the comma2k19 RAV4 imported with its phone IMU (kind ``imu``) as well as the car's ESC
    cluster (``esc_imu``), which ``rav4-can-ublox`` maps to ``imu``. Passed on, the two IMUs'
    samples would interleave on the estimator's one IMU input, each with its own mounting and
    axes; the set names the ESC, so the phone's samples are left out and counted in ``dropped``
    (``"source/kind"`` -> samples; :func:`not_used_note` says it in one line). Kinds the map
    neither renames nor feeds pass unchanged."""

    __slots__ = ("map", "dropped", "joined", "_fed", "_join", "_alt")

    ALTITUDE_MAX_AGE_NS = 2_000_000_000
    """How old a ``gnss_alt`` sample may be to complete a ``gnss_pos`` one (1 Hz frames: the
    epoch's own or the one before)."""

    def __init__(self, kind_map: Mapping[str, str] | None = None, join_altitude: bool = False):
        self.map = dict(kind_map or {})
        self._fed = frozenset(self.map.values()) - frozenset(self.map)
        self.dropped: dict[str, int] = {}
        self._join = bool(join_altitude)
        self._alt = None  # (t_ns, altitude, its sigma) of the newest gnss_alt sample
        self.joined = 0

    @classmethod
    def of(cls, sensor_set: Mapping | None) -> "KindMap":
        """The map a sensor-set description (``pipeline.configure.system_config``'s) asks for: its
        ``kind_map``, and the altitude join when it says ``gnss_altitude`` (None: an empty map)."""
        d = sensor_set or {}
        return cls(d.get("kind_map"), join_altitude="gnss_altitude" in d)

    def __bool__(self) -> bool:
        return bool(self.map) or self._join

    def __call__(self, s):
        k = s.kind
        if self._join and k in ("gnss_alt", "gnss_pos"):
            s = self._altitude(s)
            if s is None:
                return None
            k = s.kind
        to = self.map.get(k)
        if to is not None:
            return type(s)(s.t_ns, s.source, to, s.fields, s.wall_time_ns, s.valid)
        if k in self._fed:
            key = f"{s.source}/{k}"
            self.dropped[key] = self.dropped.get(key, 0) + 1
            return None
        return s

    def _altitude(self, s):
        """``join_altitude``: a receiver that sends its altitude in a frame of its own (the
        CANedge's GNSS, ``configs/signalmaps/canedge_gnss_imu``: kinds ``gnss_pos`` without an
        altitude and ``gnss_alt``) has each ``gnss_pos`` completed with the newest altitude and its
        sigma, at most ``ALTITUDE_MAX_AGE_NS`` old (counted in ``joined``); the ``gnss_alt``
        samples are taken in (None). The estimator refuses a fix without an altitude."""
        f = s.fields
        if s.kind == "gnss_alt":
            alt = f.get("gnss_alt_m", math.nan)
            if math.isfinite(alt):
                self._alt = (s.t_ns, alt, f.get("gnss_pos_sigma_v_m", math.nan))
            return None
        if math.isfinite(f.get("gnss_alt_m", math.nan)) or self._alt is None \
                or abs(s.t_ns - self._alt[0]) > self.ALTITUDE_MAX_AGE_NS:
            return s
        extra = {"gnss_alt_m": self._alt[1]}
        if math.isfinite(self._alt[2]) and "gnss_pos_sigma_v_m" not in f:
            extra["gnss_pos_sigma_v_m"] = self._alt[2]
        self.joined += 1
        return type(s)(s.t_ns, s.source, s.kind, {**f, **extra}, s.wall_time_ns, s.valid)


def not_used_note(not_used: Mapping[str, int] | None, kind_map: Mapping[str, str] | None) -> str | None:
    """The line saying which samples a :class:`KindMap` left out (``"source/kind"`` -> count, as
    a replay's ``sensor_set.not_used``) and what the set feeds instead, or None when none was."""
    if not not_used:
        return None
    fed = ", ".join(f"{k} from {src}" for src, k in sorted((kind_map or {}).items()))
    left = ", ".join(f"{key} ({n} samples)" for key, n in sorted(not_used.items()))
    return f"not used: {left}: the sensor set feeds {fed}"


# ------------------------------------------------------------------------------ calibration
_GYRO = ("angular_rate_radps_x", "angular_rate_radps_y", "angular_rate_radps_z")


class ZeroRateCalibration:
    """Gyro bias from standstill, applied to later IMU samples (a pure node: ``process(sample)
    -> sample``, causal: only samples before t enter the bias used at t).

    The EKF of eq 7 has no IMU bias states; a MEMS gyro's turn-on bias (the rtklibexplorer IMU:
    0.17 deg/s about z) then drives the yaw away from the course by degrees (measured: 5-11 deg
    on that drive) and ruins dead reckoning through GNSS outages. While the car stands still the
    true rate is zero, so the mean gyro reading is the bias::

        b = (1 / N) sum_{k in standstill} w_k,      w_used = w - b

    Standstill: the newest GNSS speed (``gnss_vel``, at most ``max_age_s`` old) or the mean wheel
    speed r w (``wheel_speed``, with ``rolling_radius_m``) below ``speed_still_mps``, for at least
    ``min_still_s`` without interruption (samples of the first ``min_still_s`` of a stop are
    held back until the stop qualifies). A stop ends the moment a speed above the threshold
    arrives. Counters: ``still_samples``, ``corrected``, ``stops``."""

    def __init__(self, speed_still_mps: float = 0.1, min_still_s: float = 2.0, max_age_s: float = 0.5,
                 rolling_radius_m: float | None = None, imu_kind: str = "imu"):
        self.speed_still_mps = float(speed_still_mps)
        self.min_still_ns = int(round(min_still_s * 1e9))
        self.max_age_ns = int(round(max_age_s * 1e9))
        self.rolling_radius_m = rolling_radius_m
        self.imu_kind = imu_kind
        self._speed = None  # (t_ns, speed)
        self._still_since = None
        self._pending: list[list[float]] = []
        self._qualified = False
        self._sum = np.zeros(3)
        self._n = 0
        self.counters = {"still_samples": 0, "corrected": 0, "stops": 0}

    @property
    def bias_radps(self) -> tuple[float, float, float] | None:
        """The current bias estimate (None before the first qualifying stop)."""
        return None if self._n == 0 else tuple((self._sum / self._n).tolist())

    def _speed_update(self, t_ns: int, v: float) -> None:
        self._speed = (t_ns, v)
        if v >= self.speed_still_mps:
            self._still_since = None
            self._qualified = False
            self._pending.clear()
        elif self._still_since is None:
            self._still_since = t_ns

    def process(self, s: Sample) -> Sample:
        """Watch speeds, learn the bias at standstill, return IMU samples with it removed."""
        k = s.kind
        if k == "gnss_vel":
            v = s.fields.get("gnss_speed_mps", math.nan)
            if math.isfinite(v) and s.valid:
                self._speed_update(s.t_ns, v)
            return s
        if k == "wheel_speed" and self.rolling_radius_m is not None:
            w = [s.fields.get(f"wheel_speed_radps_{i}", math.nan) for i in range(1, 5)]
            if all(math.isfinite(x) for x in w) and s.valid:
                self._speed_update(s.t_ns, abs(sum(w)) / 4.0 * self.rolling_radius_m)
            return s
        if k != self.imu_kind:
            return s
        w = [s.fields.get(n, math.nan) for n in _GYRO]
        fresh = self._speed is not None and s.t_ns - self._speed[0] <= self.max_age_ns
        if fresh and self._still_since is not None and s.valid and math.isfinite(w[2]):
            self._pending.append([x if math.isfinite(x) else 0.0 for x in w])
            if s.t_ns - self._still_since >= self.min_still_ns:
                if not self._qualified:
                    self._qualified = True
                    self.counters["stops"] += 1
                self._sum += np.sum(self._pending, axis=0)
                self._n += len(self._pending)
                self.counters["still_samples"] += len(self._pending)
                self._pending.clear()
        b = self.bias_radps
        if b is None:
            return s
        f = dict(s.fields)
        for n, bi in zip(_GYRO, b):
            if n in f and math.isfinite(f[n]):
                f[n] = f[n] - bi
        self.counters["corrected"] += 1
        return dataclasses.replace(s, fields=f)
