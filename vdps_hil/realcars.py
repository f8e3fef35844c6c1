"""Real cars, real sensor sets: readers for the real drives in ``../shared/data/real``, named sensor
sets, the pipeline run on what a car actually has, reference comparisons and baselines.

Data flow::

    real recording --tools/convert_*.py--> candump / NMEA text / MTi capture --vdps import-->
    MCAP --decode--> Sample stream --(kind_map, gnss-denied windows)--> EstimatorPipeline
    --> Track --(antenna lever arm)--> errors against the reference; baselines on the side

This module holds the parts the converters, the tests and ``tools/real_cars.py`` share: reading
the publishers' formats (comma2k19 numpy arrays, RTKLIB ``.pos``, the rtklibexplorer IMU ``.csv``
with its RTKLIB time-tag file), turning converted files back into samples through the project's
own adapters (``record.importer.build_adapters``: the code path of ``vdps import``), sensor sets
from config (``configs/sensorsets/*.toml``), running the pipeline, and the comparisons.

Frames, signs and symbols (``vdps_hil.conventions``)
-----------------------------------------------------
==============  ======  ===========================================================================
symbol          unit    meaning
==============  ======  ===========================================================================
p, v            m, m/s  CG position / velocity in ENU {g} (EKF states)
l_ant           m       antenna lever arm from the CG, body axes x fwd, y left, z up (model file)
p_ant, v_ant    m, m/s  antenna position / velocity: p + C^T l_ant, v + C^T (w x l_ant)
C               -       C_g^v of eq 1 from the EKF's (phi_g, theta_g, psi_g)
speed           m/s     |v_h| = hypot(v_E, v_N) (horizontal)
course          rad     atan2(v_N, v_E): direction of travel as a paper yaw (CCW from East)
t_s             s       time on the drive's clock (comma2k19: device boot seconds; RTKLIB: GPST
                        seconds since 1970-01-01 without leap seconds, ``gpst_to_unix``)
==============  ======  ===========================================================================

Publisher mounting (rtklibexplorer drive 0708)
----------------------------------------------
The publisher states the IMU orientation [180, 0, 180] deg plus a misalignment
[0, -6.79, 5.35] deg (roll, pitch, yaw) to a body frame x forward, y right, z down, and applies
them as f_b,FRD = C(e) f_imu with Groves' ``Euler_to_CTM``::

    C(phi, theta, psi) = [[ c_t c_p,                 c_t s_p,                 -s_t   ],
                          [-c_f s_p + s_f s_t c_p,   c_f c_p + s_f s_t s_p,   s_f c_t],
                          [ s_f s_p + c_f s_t c_p,  -s_f c_p + c_f s_t s_p,   c_f c_t]]

Our body frame is x forward, y left, z up (T = diag(1, -1, -1) from FRD) and the pipeline applies
f_b = C_gv(r)^T f_s with C_gv of eq 1 and r = the model file's ``imu_rotation_rpy_rad``, so
C_gv(r) = (T C(e))^T; ``publisher_mounting_rpy`` solves for r (theta = asin C_gv[0, 2],
psi = atan2(C_gv[0, 1], C_gv[0, 0]), phi = atan2(C_gv[1, 2], C_gv[2, 2])). Lever arms
(forward, right, down) from the publisher's system origin become (x, -y, -z) from our CG, which
the model file takes to be that origin (an estimate: the car's CG is not published).
"""

from __future__ import annotations

import bisect
import calendar
import dataclasses
import math
import struct
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.ekf_config import EkfConfig, SensorSet
from vdps_hil.model.frames import dcm_gv
from vdps_hil.estimation.estimates import Estimate, Innovation
from vdps_hil.estimation.pipeline import EstimatorPipeline
from vdps_hil.estimation.pipeline_config import Latencies, PipelineConfig
from vdps_hil.geodesy import EnuOrigin, ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from vdps_hil.model.frames import dcm_gv
from vdps_hil.model.params import CONFIG_DIR
from vdps_hil.units import GRAVITY_MPS2, wrap_pi

__all__ = [
    "COMMA_SEGMENT", "RTKLIB_DRIVE", "SENSORSET_DIR", "OPENPILOT_RAV4", "GnssFixes", "ImuSeries", "Reference",
    "RtkSolution", "TimeTag", "CaptureStats", "SensorSetConfig", "SensorSetError", "Track", "RunResult",
    "OutageError", "SteerResponseFit", "ZeroRateCalibration", "gpst_to_unix", "unix_to_gpst", "gpst_minus_utc_s",
    "read_comma_ublox", "read_comma_phone_imu", "read_comma_reference", "read_rtklib_pos", "read_timetag",
    "read_rtklib_imu", "publisher_mounting_rpy", "groves_ctm", "nmea_fix_lines", "mti_capture", "load_samples",
    "parse_sensorset", "load_sensorset", "infer_sensor_set", "run_pipeline", "track_from_estimates", "gnss_denied",
    "outage_windows", "outage_errors", "summarize_outages", "speed_course_errors", "dead_reckoning",
    "constant_velocity", "interp_angle", "velocity_lag", "estimate_lag", "series", "steer_signals",
    "steer_response_fit", "understeer_gradient",
]

COMMA_SEGMENT = "comma2k19_rav4_2018-08-02_seg40"
RTKLIB_DRIVE = "rtklibexplorer_drive_0708"
SENSORSET_DIR = CONFIG_DIR / "sensorsets"

_NS = 1_000_000_000
GPS_EPOCH_UNIX_S = 315_964_800  # 1980-01-06T00:00:00Z
# UTC dates from which GPST - UTC increased (IERS bulletin C; 18 s since 2017-01-01)
_LEAPS = ((1136073600, 14), (1230768000, 15), (1341100800, 16), (1435708800, 17), (1483228800, 18))


# ------------------------------------------------------------------------------ time scales
def gpst_minus_utc_s(unix_utc_s: float) -> int:
    """GPST - UTC [s] at a UTC instant (13 before 2006, 18 from 2017-01-01 on)."""
    off = 13
    for start, n in _LEAPS:
        if unix_utc_s >= start:
            off = n
    return off


def gpst_to_unix(gpst_calendar_s: float) -> float:
    """A GPST calendar time written as seconds since 1970-01-01 (as RTKLIB prints it) -> UTC
    Unix seconds (leap seconds removed)."""
    return gpst_calendar_s - gpst_minus_utc_s(gpst_calendar_s - 18.0)


def unix_to_gpst(unix_utc_s: float) -> float:
    """UTC Unix seconds -> GPST calendar seconds since 1970-01-01 (inverse of ``gpst_to_unix``)."""
    return unix_utc_s + gpst_minus_utc_s(unix_utc_s)


# ------------------------------------------------------------------------------ containers
@dataclass(frozen=True)
class ImuSeries:
    """IMU samples: ``t_s`` (N,), specific force [m/s^2] and angular rate [rad/s] (N, 3) in the
    axes named by ``frame`` (``"flu"``: x forward, y left, z up, the bus convention; ``"sensor"``:
    the device's own axes, the mounting rotation still to apply)."""

    t_s: np.ndarray
    specific_force_mps2: np.ndarray
    angular_rate_radps: np.ndarray
    frame: str


@dataclass(frozen=True)
class GnssFixes:
    """Single-antenna GNSS epochs. ``t_s``: the drive clock; ``utc_s``: the fix's UTC (Unix s);
    ``h_m`` ellipsoidal height; ``course_rad`` paper yaw (NaN when not moving); ``quality``: GGA
    fix quality; ``num_sats`` (NaN if unknown); ``sigma_h_m``/``sigma_v_m`` (NaN if unknown)."""

    t_s: np.ndarray
    utc_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    speed_mps: np.ndarray
    course_rad: np.ndarray
    quality: np.ndarray
    num_sats: np.ndarray
    sigma_h_m: np.ndarray
    sigma_v_m: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True)
class Reference:
    """A reference trajectory in ENU about ``origin``: positions and velocities (N, 3) of the
    reference point (comma2k19: the device; RTKLIB: the antenna) at ``t_s``."""

    t_s: np.ndarray
    origin: EnuOrigin
    pos_enu_m: np.ndarray
    vel_enu_mps: np.ndarray

    @property
    def speed_mps(self) -> np.ndarray:
        return np.hypot(self.vel_enu_mps[:, 0], self.vel_enu_mps[:, 1])

    @property
    def course_rad(self) -> np.ndarray:
        return np.arctan2(self.vel_enu_mps[:, 1], self.vel_enu_mps[:, 0])

    def at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """(positions, velocities) linearly interpolated at ``t_s`` (NaN outside)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        p = np.column_stack([np.interp(t, self.t_s, self.pos_enu_m[:, k], left=np.nan, right=np.nan)
                             for k in range(3)])
        v = np.column_stack([np.interp(t, self.t_s, self.vel_enu_mps[:, k], left=np.nan, right=np.nan)
                             for k in range(3)])
        return p, v


@dataclass(frozen=True)
class RtkSolution:
    """An RTKLIB ``.pos`` solution (llh, velocity in NEU): ``t_gpst_s`` GPST calendar seconds
    since 1970 as printed, ``q`` RTKLIB quality (1 fix, 2 float, 4 DGPS, 5 single), ``sd_neu_m``
    the printed sigmas, ``vel_neu_mps`` velocity north/east/up."""

    t_gpst_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    q: np.ndarray
    ns: np.ndarray
    sd_neu_m: np.ndarray
    vel_neu_mps: np.ndarray

    RTKLIB_TO_GGA = {1: 4, 2: 5, 3: 1, 4: 2, 5: 1, 6: 6}
    """RTKLIB Q (1 fix, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP) -> GGA fix quality."""

    def fixes(self, t0_gpst_s: float = 0.0) -> GnssFixes:
        """As single-antenna GNSS epochs on the clock t = t_gpst - t0 (course NaN below 0.05 m/s)."""
        vn, ve = self.vel_neu_mps[:, 0], self.vel_neu_mps[:, 1]
        speed = np.hypot(vn, ve)
        course = np.where(speed > 0.05, np.arctan2(vn, ve), np.nan)
        q = np.array([self.RTKLIB_TO_GGA.get(int(v), 1) for v in self.q], dtype=float)
        utc = np.array([gpst_to_unix(t) for t in self.t_gpst_s])
        return GnssFixes(self.t_gpst_s - t0_gpst_s, utc, self.lat_deg, self.lon_deg, self.h_m, speed, course, q,
                         self.ns.astype(float), np.hypot(self.sd_neu_m[:, 0], self.sd_neu_m[:, 1]) / math.sqrt(2.0),
                         self.sd_neu_m[:, 2].copy())

    def reference(self, origin: EnuOrigin | None = None, t0_gpst_s: float = 0.0) -> Reference:
        """The solution as a reference trajectory of the antenna (ENU, velocities E/N/U)."""
        if origin is None:
            origin = EnuOrigin(float(self.lat_deg[0]), float(self.lon_deg[0]), float(self.h_m[0]))
        pos = np.array([origin.to_enu(a, b, c) for a, b, c in zip(self.lat_deg, self.lon_deg, self.h_m)])
        vel = np.column_stack([self.vel_neu_mps[:, 1], self.vel_neu_mps[:, 0], self.vel_neu_mps[:, 2]])
        return Reference(self.t_gpst_s - t0_gpst_s, origin, pos, vel)


@dataclass(frozen=True)
class TimeTag:
    """An RTKLIB time-tag file (``stream.c``, demo5 layout): a 60-byte header text, the tick
    [ms] at the file start, the start time (uint32 seconds + float64 fraction; GPST calendar
    seconds since 1970), then records (tick [ms] since start, byte position in the stream)."""

    header: str
    tick0_ms: int
    start_s: float
    ticks_ms: np.ndarray
    fpos: np.ndarray

    @property
    def end_s(self) -> float:
        return self.start_s + (float(self.ticks_ms[-1]) / 1000.0 if self.ticks_ms.size else 0.0)


# ------------------------------------------------------------------------------ readers
def _seg(seg_dir) -> Path:
    return Path(seg_dir)


def read_comma_ublox(seg_dir) -> GnssFixes:
    """comma2k19 ``processed_log/GNSS/live_gnss_ublox``: ``t`` (device boot s) and ``value``
    columns [lat deg, lon deg, speed m/s, UTC ms, altitude m, bearing deg]. The altitude is
    ellipsoidal (it agrees with the height of ``global_pose`` to 2 m, while the geoid there is
    about 32 m below the ellipsoid); the bearing is the course over ground clockwise from north."""
    d = _seg(seg_dir) / "processed_log" / "GNSS" / "live_gnss_ublox"
    t = np.load(d / "t").astype(float)
    v = np.load(d / "value").astype(float)
    if v.ndim != 2 or v.shape[1] < 6 or v.shape[0] != t.shape[0]:
        raise ValueError(f"{d}: expected value of shape (N, 6) matching t, got {v.shape}")
    n = t.shape[0]
    course = np.array([wrap_pi(math.radians(90.0 - b)) for b in v[:, 5]])
    nan = np.full(n, np.nan)
    return GnssFixes(t, v[:, 3] / 1000.0, v[:, 0], v[:, 1], v[:, 4], v[:, 2], course,
                     np.ones(n), nan.copy(), nan.copy(), nan.copy())


def read_comma_phone_imu(seg_dir) -> ImuSeries:
    """comma2k19 phone IMU (``processed_log/IMU/{accelerometer,gyro}``: m/s^2, rad/s, axes
    [forward, right, down]) in the bus axes x forward, y left, z up: (a, b, c) -> (a, -b, -c).
    Gyro samples are matched to accelerometer samples by time (same clock)."""
    d = _seg(seg_dir) / "processed_log" / "IMU"
    ta, a = np.load(d / "accelerometer" / "t").astype(float), np.load(d / "accelerometer" / "value").astype(float)
    tg, g = np.load(d / "gyro" / "t").astype(float), np.load(d / "gyro" / "value").astype(float)
    if a.shape != (ta.shape[0], 3) or g.shape != (tg.shape[0], 3):
        raise ValueError(f"{d}: accelerometer/gyro arrays do not match their time stamps")
    if ta.shape != tg.shape or not np.allclose(ta, tg, atol=1e-4):
        g = np.column_stack([np.interp(ta, tg, g[:, k]) for k in range(3)])
    flip = np.array([1.0, -1.0, -1.0])
    return ImuSeries(ta, a * flip, g * flip, "flu")


def read_comma_reference(seg_dir, origin: EnuOrigin | None = None) -> Reference:
    """comma2k19 ``global_pose`` (20 Hz offline INS/GNSS/vision solution of the device: ECEF
    position and velocity) in ENU about ``origin`` (default: the first pose)."""
    d = _seg(seg_dir) / "global_pose"
    t = np.load(d / "frame_times").astype(float)
    p = np.load(d / "frame_positions").astype(float)
    v = np.load(d / "frame_velocities").astype(float)
    if origin is None:
        origin = EnuOrigin(*ecef_to_geodetic(p[0]))
    rot = ecef_to_enu_matrix(origin.lat_deg, origin.lon_deg)
    ecef0 = geodetic_to_ecef(origin.lat_deg, origin.lon_deg, origin.h_m)
    return Reference(t, origin, (p - ecef0) @ rot.T, v @ rot.T)


def read_rtklib_pos(path) -> RtkSolution:
    """An RTKLIB ``.pos`` file with llh and velocities (``%`` header lines; columns: date, time
    (GPST), lat, lon, height, Q, ns, sdn, sde, sdu, sdne, sdeu, sdun, age, ratio, vn, ve, vu, ...).
    Lines that do not parse are skipped."""
    import datetime as dt

    rows = []
    with open(path, encoding="ascii", errors="replace") as f:
        for line in f:
            if not line.strip() or line.lstrip().startswith("%"):
                continue
            parts = line.split()
            if len(parts) < 18:
                continue
            try:
                day = dt.datetime.strptime(parts[0] + " " + parts[1], "%Y/%m/%d %H:%M:%S.%f")
                nums = [float(x) for x in parts[2:18]]
            except ValueError:
                continue
            t = calendar.timegm(day.timetuple()) + day.microsecond * 1e-6
            rows.append([t, *nums])
    if not rows:
        raise ValueError(f"{path}: no RTKLIB solution lines with velocities")
    a = np.array(rows)
    return RtkSolution(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4].astype(int), a[:, 5].astype(int),
                       a[:, 6:9], a[:, 14:17])


TIMETAG_HEADER_LEN = 60


def read_timetag(path) -> TimeTag:
    """An RTKLIB time-tag file (demo5: HEADER(60) + TICK(4) + TIME(4 + 8) + records of
    TICK(4) + FPOS(4), little-endian)."""
    b = Path(path).read_bytes()
    if len(b) < TIMETAG_HEADER_LEN + 16 or not b.startswith(b"TIMETAG"):
        raise ValueError(f"{path}: not an RTKLIB time-tag file")
    header = b[:TIMETAG_HEADER_LEN].rstrip(b"\0").decode("ascii", "replace")
    tick0, t_int = struct.unpack_from("<II", b, TIMETAG_HEADER_LEN)
    (t_frac,) = struct.unpack_from("<d", b, TIMETAG_HEADER_LEN + 8)
    body = b[TIMETAG_HEADER_LEN + 16:]
    body = body[: len(body) // 8 * 8]
    rec = np.frombuffer(body, dtype="<u4").reshape(-1, 2)
    return TimeTag(header, int(tick0), float(t_int) + float(t_frac), rec[:, 0].astype(np.int64),
                   rec[:, 1].astype(np.int64))


def read_rtklib_imu(csv_path, tag_path=None) -> ImuSeries:
    """The rtklibexplorer IMU log: ``ax, ay, az`` [g], ``gx, gy, gz`` [deg/s], device counter
    [ms], one row per sample, in the IMU's own axes (``frame = "sensor"``). Times follow the
    publisher's own rule (GNSS_IMU ``convert_imu_file.py``): the counter relative to the first row,
    stretched so the log spans the time-tag file's start to its last tick::

        t_i = t_start + s_i (t_end - t_start) / s_N,   s_i = (ms_i - ms_0) / 1000

    with t_start, t_end from the tag (GPST calendar seconds). Without a tag: t_i = s_i.
    Rows that do not parse are skipped."""
    rows = []
    with open(csv_path, encoding="ascii", errors="replace") as f:
        for line in f:
            parts = line.strip().split(",")
            if len(parts) < 7:
                continue
            try:
                rows.append([float(x) for x in parts[:7]])
            except ValueError:
                continue
    if len(rows) < 2:
        raise ValueError(f"{csv_path}: fewer than two IMU rows")
    a = np.array(rows)
    s = (a[:, 6] - a[:, 6][0]) / 1000.0
    if tag_path is not None:
        tag = read_timetag(tag_path)
        t = tag.start_s + s * (tag.end_s - tag.start_s) / s[-1]
    else:
        t = s
    return ImuSeries(t, a[:, 0:3] * GRAVITY_MPS2, np.radians(a[:, 3:6]), "sensor")


# ------------------------------------------------------------------------------ mounting
def groves_ctm(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Groves' ``Euler_to_CTM`` (module docstring): the publisher's IMU -> body (FRD) matrix."""
    sf, cf = math.sin(roll_rad), math.cos(roll_rad)
    st, ct = math.sin(pitch_rad), math.cos(pitch_rad)
    sp, cp = math.sin(yaw_rad), math.cos(yaw_rad)
    return np.array([[ct * cp, ct * sp, -st],
                     [-cf * sp + sf * st * cp, cf * cp + sf * st * sp, sf * ct],
                     [sf * sp + cf * st * cp, -sf * cp + cf * st * sp, cf * ct]])


def publisher_mounting_rpy(orientation_deg: Sequence[float], misalign_deg: Sequence[float] = (0.0, 0.0, 0.0)
                           ) -> tuple[float, float, float]:
    """Our ``imu_rotation_rpy_rad`` (body -> sensor, eq 1, body x fwd y left z up) from the
    publisher's IMU orientation + misalignment (Groves Euler angles to an FRD body; module
    docstring). Returns (roll, pitch, yaw) [rad]."""
    e = np.radians(np.asarray(orientation_deg, dtype=float) + np.asarray(misalign_deg, dtype=float))
    c_gv = (np.diag([1.0, -1.0, -1.0]) @ groves_ctm(*e)).T
    theta = math.asin(max(-1.0, min(1.0, c_gv[0, 2])))
    psi = math.atan2(c_gv[0, 1], c_gv[0, 0])
    phi = math.atan2(c_gv[1, 2], c_gv[2, 2])
    return phi, theta, psi


# ------------------------------------------------------------------------------ samples
def load_samples(can=(), serial=(), *, signalmap=None, dbc: Mapping[str, str] | None = None
                 ) -> tuple[list[Sample], dict]:
    """Decode files the way ``vdps import`` does (``record.importer.build_adapters``: the same
    adapters and decoders) but keep the samples in memory. ``can``/``serial`` are
    ``importer.CanSource`` / ``SerialSource``. Returns (samples in time order, per-source
    status)."""
    from vdps_hil.adapters.base import EndOfInput
    from vdps_hil.bus.subscription import Subscription
    from vdps_hil.record.importer import build_adapters

    adapters, _ = build_adapters(list(can), list(serial), signalmap=signalmap, dbc=dict(dbc or {}))
    out: list[Sample] = []
    status = {}
    for a in adapters:
        a.open()
        sub = a.subscribe(Subscription(f"realcars-{a.name}", 1 << 30, raw=False))
        try:
            while True:
                try:
                    n = a.poll(0.0)
                except EndOfInput:
                    break
                out.extend(e for e in sub.drain() if isinstance(e, Sample))
                if n == 0 and not a.is_open:
                    break
            out.extend(e for e in sub.drain() if isinstance(e, Sample))
            status[a.name] = a.status()
        finally:
            a.close()
            a.unsubscribe(sub)
    out.sort(key=lambda s: s.t_ns)
    return out, status


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


def _finite(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SensorSetError(f"{where}: expected a finite number, got {v!r}")
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
    for k, f in kinds.items():
        if six <= f:
            imu = "6axis"
            if k != "imu":
                kind_map[k] = "imu"
            break
    if imu is None:
        for k, f in kinds.items():
            if esc <= f:
                imu = "esc3"
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


# ------------------------------------------------------------------------------ pipeline runs
@dataclass(frozen=True)
class Track:
    """Estimates of a run as arrays: ``t_s`` (N,), ``x`` (N, 12) full states (``STATE_NAMES``),
    ``sigma`` (N, 12)."""

    t_s: np.ndarray
    x: np.ndarray
    sigma: np.ndarray

    @property
    def pos_m(self) -> np.ndarray:
        return self.x[:, 0:3]

    @property
    def vel_mps(self) -> np.ndarray:
        return self.x[:, 3:6]

    def antenna(self, lever_arm_m, omega_radps=None) -> tuple[np.ndarray, np.ndarray]:
        """(p_ant, v_ant) of a point at ``lever_arm_m`` (body axes) for every estimate:
        p + C^T l and v + C^T (w x l) (``omega_radps`` (N, 3) body rates, or zero)."""
        la = np.asarray(lever_arm_m, dtype=float)
        p = self.pos_m.copy()
        v = self.vel_mps.copy()
        for i in range(self.t_s.shape[0]):
            ct = dcm_gv(self.x[i, 6], self.x[i, 7], self.x[i, 8]).T
            p[i] += ct @ la
            if omega_radps is not None:
                v[i] += ct @ np.cross(omega_radps[i], la)
        return p, v

    def window(self, t0_s: float, t1_s: float) -> "Track":
        m = (self.t_s >= t0_s) & (self.t_s <= t1_s)
        return Track(self.t_s[m], self.x[m], self.sigma[m])


def track_from_estimates(estimates: Sequence[Estimate], t_offset_s: float = 0.0) -> Track:
    if not estimates:
        return Track(np.zeros(0), np.zeros((0, 12)), np.zeros((0, 12)))
    t = np.array([e.t_ns for e in estimates], dtype=float) / 1e9 + t_offset_s
    return Track(t, np.array([e.x for e in estimates]), np.array([e.sigma for e in estimates]))


@dataclass
class RunResult:
    """One pipeline run: the pipeline (counters, observability), its estimates as a ``Track``
    and the per-kind number of samples handed to it / withheld (GNSS-denied windows)."""

    pipeline: EstimatorPipeline
    track: Track
    handled: dict
    withheld: dict
    nis: dict = field(default_factory=dict)
    """kind -> {"accepted": n, "mean_nis_per_dof": mean(NIS / dof) of the accepted updates}."""


def gnss_denied(windows_s: Sequence[tuple[float, float]], latency_s: float = 0.0):
    """A predicate dropping GNSS samples (kinds ``gnss_*``) whose measurement time t - latency
    is inside a window [t0, t1) (seconds on the drive clock; ``latency_s`` the configured GNSS
    latency, so that no fix measured inside the window reaches the filter, and none measured
    outside is withheld)."""
    ws = sorted((float(a), float(b)) for a, b in windows_s)
    starts = [a for a, _ in ws]

    def drop(s: Sample) -> bool:
        if not s.kind.startswith("gnss"):
            return False
        t = s.t_ns / 1e9 - latency_s
        i = bisect.bisect_right(starts, t) - 1
        return i >= 0 and ws[i][0] <= t < ws[i][1]

    return drop


def run_pipeline(vehicle, config: PipelineConfig, samples: Iterable[Sample], *,
                 kind_map: Mapping[str, str] | None = None, drop=None, origin: EnuOrigin | None = None,
                 preprocess: Sequence = (), order_by_effective_time: bool = True) -> RunResult:
    """Feed ``samples`` to a fresh ``EstimatorPipeline`` and collect its estimates.

    ``kind_map`` renames recorded kinds to pipeline kinds (``esc_imu`` -> ``imu``); ``drop(s)``
    withholds samples (GNSS-denied windows, ``gnss_denied``); ``preprocess`` nodes
    (``process(sample) -> sample``, e.g. ``ZeroRateCalibration``) then see the delivered stream in
    order, before the pipeline. With
    ``order_by_effective_time`` the stream is ordered by t_ns minus the configured latency of
    its kind (a live node would hold samples for the longest latency to achieve the same);
    the pipeline itself subtracts the latency."""
    km = dict(kind_map or {})
    lat = config.latencies
    lat_ns = {"imu": int(round(lat.imu_s * 1e9)), "gnss": int(round(lat.gnss_s * 1e9)),
              "gnss_vel": int(round(lat.gnss_vel_effective_s * 1e9)),
              "suspension": int(round(lat.suspension_s * 1e9)), "wheel": int(round(lat.wheel_s * 1e9))}
    stream = []
    handled: dict[str, int] = {}
    withheld: dict[str, int] = {}
    for s in samples:
        k = km.get(s.kind, s.kind)
        if k != s.kind:
            s = dataclasses.replace(s, kind=k)
        if drop is not None and drop(s):
            withheld[k] = withheld.get(k, 0) + 1
            continue
        handled[k] = handled.get(k, 0) + 1
        stream.append(s)
    if order_by_effective_time and any(lat_ns.values()):
        def eff(s):
            g = s.kind if s.kind == "gnss_vel" else (
                "gnss" if s.kind.startswith("gnss") else ("wheel" if s.kind.startswith("wheel") else s.kind))
            return s.t_ns - lat_ns.get(g, 0)
        stream.sort(key=eff)
    for node in preprocess:
        stream = [node.process(s) for s in stream]
    p = EstimatorPipeline(vehicle, config, origin=origin)
    est = []
    nis: dict[str, list[float]] = {}
    for s in stream:
        for o in p.handle(s):
            if isinstance(o, Estimate):
                est.append(o)
            elif isinstance(o, Innovation) and o.status == "accepted" and o.dof:
                v = nis.setdefault(o.kind, [0, 0.0])
                v[0] += 1
                v[1] += o.nis / o.dof
    summary = {k: {"accepted": n, "mean_nis_per_dof": tot / n} for k, (n, tot) in nis.items()}
    return RunResult(p, track_from_estimates(est), handled, withheld, summary)


# ------------------------------------------------------------------------------ metrics
def interp_angle(t_new, t, a) -> np.ndarray:
    """Linear interpolation of an angle series through its unwrapped form, wrapped to [-pi, pi)."""
    return wrap_pi(np.interp(t_new, t, np.unwrap(a)))


def speed_course_errors(t_s, speed_mps, course_rad, ref: Reference, min_speed_mps: float = 3.0) -> dict:
    """RMS and mean errors of speed [m/s] and course [deg] against the reference interpolated at
    ``t_s`` (inside the reference's span; course only above ``min_speed_mps``)."""
    t = np.asarray(t_s, dtype=float)
    inside = (t >= ref.t_s[0]) & (t <= ref.t_s[-1]) & np.isfinite(speed_mps)
    rs = np.interp(t[inside], ref.t_s, ref.speed_mps)
    es = np.asarray(speed_mps)[inside] - rs
    rc = interp_angle(t[inside], ref.t_s, ref.course_rad)
    ec = wrap_pi(np.asarray(course_rad)[inside] - rc)
    mc = np.isfinite(ec) & (rs >= min_speed_mps)
    return {"n": int(inside.sum()),
            "speed_rms_mps": float(np.sqrt(np.mean(es ** 2))) if es.size else math.nan,
            "speed_mean_mps": float(np.mean(es)) if es.size else math.nan,
            "course_rms_deg": float(np.degrees(np.sqrt(np.mean(ec[mc] ** 2)))) if mc.any() else math.nan,
            "course_mean_deg": float(np.degrees(np.mean(ec[mc]))) if mc.any() else math.nan}


def dead_reckoning(t_s, speed_mps, yaw_rate_radps, p0_m, course0_rad: float, t0_s: float, t1_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Planar dead reckoning from a speed and a yaw rate series (e.g. the mean wheel speed and
    the ESC yaw rate) starting at (p0 (E, N), course0) at t0, trapezoid integration over the
    samples in [t0, t1]::

        course(t) = course0 + int w dt,   p(t) = p0 + int speed [cos course, sin course] dt

    Returns (t, speed, course, p (N, 2))."""
    t = np.asarray(t_s, dtype=float)
    m = (t >= t0_s) & (t <= t1_s)
    tt = np.concatenate([[t0_s], t[m]])
    sp = np.concatenate([[np.interp(t0_s, t, speed_mps)], np.asarray(speed_mps)[m]])
    w = np.concatenate([[np.interp(t0_s, t, yaw_rate_radps)], np.asarray(yaw_rate_radps)[m]])
    dt = np.diff(tt)
    crs = course0_rad + np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)])
    vx, vy = sp * np.cos(crs), sp * np.sin(crs)
    px = p0_m[0] + np.concatenate([[0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * dt)])
    py = p0_m[1] + np.concatenate([[0.0], np.cumsum(0.5 * (vy[1:] + vy[:-1]) * dt)])
    return tt, sp, wrap_pi(crs), np.column_stack([px, py])


def constant_velocity(p0_m, v0_mps, t0_s: float, t_s) -> np.ndarray:
    """Constant-velocity extrapolation p0 + v0 (t - t0) (the outage baseline)."""
    return np.asarray(p0_m)[None, :] + np.outer(np.asarray(t_s, dtype=float) - t0_s, np.asarray(v0_mps))


def outage_windows(t_first_s: float, t_last_s: float, period_s: float, lengths_s: Sequence[float],
                   first_offset_s: float | None = None) -> list[tuple[float, float]]:
    """GNSS outages every ``period_s``: window k starts at t_first + first_offset + k period and
    lasts lengths[k mod len(lengths)] (a window must end before ``t_last``)."""
    off = period_s if first_offset_s is None else first_offset_s
    out = []
    k = 0
    while True:
        t0 = t_first_s + off + k * period_s
        t1 = t0 + lengths_s[k % len(lengths_s)]
        if t1 >= t_last_s:
            break
        out.append((t0, t1))
        k += 1
    return out


# ------------------------------------------------------------------------------ writers
def _nmea_latlon(value_deg: float, deg_digits: int, hemis: str) -> tuple[str, str]:
    h = hemis[0] if value_deg >= 0 else hemis[1]
    a = abs(float(value_deg))
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 6) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:0{deg_digits}d}{m:09.6f}", h


def _hhmmss(utc_s: float) -> str:
    tod = utc_s % 86400.0
    h = int(tod // 3600)
    mi = int((tod - 3600 * h) // 60)
    s = tod - 3600 * h - 60 * mi
    if round(s, 3) >= 60.0:
        s = 59.999
    return f"{h:02d}{mi:02d}{s:06.3f}"


_RMC_MODE = {4: "R", 5: "F", 2: "D", 1: "A", 6: "P"}


def nmea_fix_lines(fixes: GnssFixes, t0_s: float = 0.0, talker: str = "GP") -> list[bytes]:
    """Time-stamped NMEA text for single-antenna fixes: per epoch ``"<t - t0> $GPGGA..."`` and
    ``"<t - t0> $GPRMC..."`` (stamp in seconds, 6 decimals: the ``vdps import`` text form).

    GGA prints lat/lon to 1e-6 minute (2 mm), the height with 3 decimals in the altitude field
    and a geoid separation of 0.000 (the sources give ellipsoidal heights and no geoid model: the
    pipeline uses h = altitude + separation), the satellites if known; RMC prints speed [kn] and
    course [deg from true north] with 3 decimals (course empty when NaN) and the mode letter of
    the fix quality (R RTK fixed, F float, D differential, A autonomous)."""
    from vdps_hil.codecs.nmea.sentence import KNOT_MPS, wrap_sentence
    from vdps_hil.conventions import yaw_to_heading
    import datetime as dt

    out: list[bytes] = []
    for i in range(len(fixes)):
        t = float(fixes.t_s[i]) - t0_s
        utc = float(fixes.utc_s[i])
        lat, ns = _nmea_latlon(fixes.lat_deg[i], 2, "NS")
        lon, ew = _nmea_latlon(fixes.lon_deg[i], 3, "EW")
        q = int(fixes.quality[i])
        sats = "" if not math.isfinite(float(fixes.num_sats[i])) else f"{int(fixes.num_sats[i]):02d}"
        tod = _hhmmss(utc)
        gga = f"{talker}GGA,{tod},{lat},{ns},{lon},{ew},{q},{sats},,{float(fixes.h_m[i]):.3f},M,0.000,M,,"
        c = float(fixes.course_rad[i])
        course = "" if not math.isfinite(c) else f"{yaw_to_heading(c):.3f}"
        date = dt.datetime.fromtimestamp(utc, dt.timezone.utc).strftime("%d%m%y")
        rmc = (f"{talker}RMC,{tod},A,{lat},{ns},{lon},{ew},{float(fixes.speed_mps[i]) / KNOT_MPS:.3f},{course},"
               f"{date},,,{_RMC_MODE.get(q, 'A')}")
        stamp = f"{t:.6f} ".encode("ascii")
        out.append(stamp + wrap_sentence(gga))
        out.append(stamp + wrap_sentence(rmc))
    return out


@dataclass(frozen=True)
class CaptureStats:
    """How an MTi capture placed its packets: ``packets``, ``padding_bytes``, ``delayed``
    (packets placed later than their stamp because the previous one was still on the wire) and
    the largest placement error ``max_error_s`` (quantisation to one byte time included)."""

    packets: int
    padding_bytes: int
    delayed: int
    max_error_s: float
    baud: int


def mti_capture(imu: ImuSeries, t0_s: float = 0.0, baud: int = 115200, max_lead_s: float = 120.0
                ) -> tuple[bytes, CaptureStats]:
    """An Xsens MTData2 byte stream (``codecs.imu_mtdata2.encode_imu_packet``) of ``imu`` for
    ``vdps import --serial imu=FILE@BAUD``.

    The importer stamps a binary capture with its wire time (``SerialFileAdapter``: byte k
    arrives at (k + 1) 10 / baud s, 8N1). Packet i is therefore placed so its last byte is byte
    n_i = round((t_i - t0) baud / 10) - 1, the gap before it filled with zero bytes (idle line;
    the decoder skips them as ``garbage_bytes``, not an error), so the decoded ``t_ns`` is the
    sample's stamp (to one byte time, 10 / baud s) on the clock t - t0. A packet that would
    overlap its predecessor follows it directly (counted ``delayed``). SampleTimeFine carries the
    same t - t0 (100 us ticks) and the packet counter runs from 0. The axes are written as given
    (``imu.frame``): the mounting rotation stays in the model vehicle file.

    Refuses (ValueError) a first sample more than ``max_lead_s`` after t0 (the padding would be
    that many seconds of idle bytes)."""
    from vdps_hil.codecs.imu_mtdata2 import PACKET_BYTES, encode_imu_packet

    t = np.asarray(imu.t_s, dtype=float) - t0_s
    if t.size and (t[0] < 0 or t[0] > max_lead_s):
        raise ValueError(f"first IMU sample at {t[0]:.3f} s after t0: must be within [0, {max_lead_s}] s")
    byte_s = 10.0 / baud
    buf = bytearray()
    delayed = 0
    max_err = 0.0
    f, w = imu.specific_force_mps2, imu.angular_rate_radps
    for i in range(t.shape[0]):
        end = int(round(t[i] / byte_s))  # bytes received when the packet's last byte arrives
        start = end - PACKET_BYTES
        if start < len(buf):
            start = len(buf)
            delayed += 1
        buf.extend(b"\0" * (start - len(buf)))
        buf.extend(encode_imu_packet(int(round(t[i] * 1e9)), f[i], w[i], i))
        max_err = max(max_err, abs(len(buf) * byte_s - t[i]))
    pad = len(buf) - PACKET_BYTES * t.shape[0]
    return bytes(buf), CaptureStats(int(t.shape[0]), int(pad), delayed, max_err, int(baud))


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


# ------------------------------------------------------------------------------ outage studies
@dataclass(frozen=True)
class OutageError:
    """Horizontal error [m] at the end of one GNSS outage [t0, t1): ``filter_m`` (the pipeline's
    antenna position predicted through the outage), ``cv_m`` (constant-velocity extrapolation of
    the last reference epoch before t0), both against the reference at ``t_end_s`` (its last epoch
    before t1); ``speed_mps`` the reference speed at t0."""

    t0_s: float
    t1_s: float
    t_end_s: float
    filter_m: float
    cv_m: float
    speed_mps: float

    @property
    def length_s(self) -> float:
        return self.t1_s - self.t0_s


def outage_errors(track: Track, lever_arm_m, ref: Reference, windows: Sequence[tuple[float, float]]
                  ) -> list[OutageError]:
    """Errors at the end of each outage (``OutageError``). The track's newest estimate at or
    before the evaluation epoch is carried to it with its own velocity (estimates are decimated)."""
    pa, va = track.antenna(lever_arm_m)
    out = []
    for a, b in windows:
        k_end = int(np.searchsorted(ref.t_s, b)) - 1
        k_last = int(np.searchsorted(ref.t_s, a)) - 1
        if k_last < 0 or k_end <= k_last:
            continue
        te = float(ref.t_s[k_end])
        i = int(np.searchsorted(track.t_s, te, side="right")) - 1
        if i < 0:
            continue
        p_f = pa[i] + va[i] * (te - track.t_s[i])
        p_cv = constant_velocity(ref.pos_enu_m[k_last], ref.vel_enu_mps[k_last], float(ref.t_s[k_last]), [te])[0]
        out.append(OutageError(float(a), float(b), te, float(np.hypot(*(p_f[:2] - ref.pos_enu_m[k_end, :2]))),
                               float(np.hypot(*(p_cv[:2] - ref.pos_enu_m[k_end, :2]))),
                               float(ref.speed_mps[k_last])))
    return out


def summarize_outages(errors: Sequence[OutageError]) -> dict:
    """Per outage length: count, mean and max filter error, mean CV error, the reduction
    1 - mean(filter) / mean(CV) and the fraction of outages with filter <= CV / 2."""
    out = {}
    for length in sorted({round(e.length_s, 3) for e in errors}):
        es = [e for e in errors if round(e.length_s, 3) == length]
        f = np.array([e.filter_m for e in es])
        c = np.array([e.cv_m for e in es])
        out[f"{length:g}s"] = {"n": len(es), "filter_mean_m": float(f.mean()), "filter_max_m": float(f.max()),
                               "cv_mean_m": float(c.mean()), "reduction": float(1.0 - f.mean() / c.mean()),
                               "halved_fraction": float(np.mean(f <= 0.5 * c))}
    return out


def velocity_lag(ref: Reference, lags_s=np.arange(-0.3, 0.3001, 0.005), min_speed_mps: float = 3.0) -> float:
    """How much a solution's velocities lag its positions [s]: the L minimising the RMS of
    (p_k+1 - p_k) / dt - v(t_mid - L) over the horizontal axes while moving (positive: the
    velocity describes the motion L seconds earlier than its time stamp)."""
    t, p, v = ref.t_s, ref.pos_enu_m, ref.vel_enu_mps
    dp = np.diff(p[:, :2], axis=0) / np.diff(t)[:, None]
    tm = 0.5 * (t[1:] + t[:-1])
    m = np.hypot(v[1:, 0], v[1:, 1]) > min_speed_mps
    best, best_l = math.inf, math.nan
    for lag in lags_s:
        vm = np.column_stack([np.interp(tm + lag, t, v[:, k]) for k in range(2)])
        e = float(np.sqrt(np.mean((dp[m] - vm[m]) ** 2)))
        if e < best:
            best, best_l = e, float(lag)
    return best_l


def estimate_lag(t_a, x_a, t_b, x_b, lags_s) -> float:
    """The lag L (from ``lags_s``) minimising RMS(x_a(t) - s x_b(t - L)) with the scale s fitted
    (mean ratio): how much series a lags series b (e.g. GNSS speed behind the wheel speeds)."""
    best, best_l = math.inf, math.nan
    t_a = np.asarray(t_a, dtype=float)
    for lag in lags_s:
        xb = np.interp(t_a - lag, t_b, x_b, left=np.nan, right=np.nan)
        m = np.isfinite(xb)
        if m.sum() < 3:
            continue
        s = np.mean(np.asarray(x_a)[m]) / np.mean(xb[m])
        r = float(np.sqrt(np.mean((np.asarray(x_a)[m] - s * xb[m]) ** 2)))
        if r < best:
            best, best_l = r, float(lag)
    return best_l


# ------------------------------------------------------------------------------ steering response
OPENPILOT_RAV4 = {"steer_ratio": 16.88, "tire_stiffness_factor": 0.5533, "mass_kg": 3650 * 0.45359237 + 136.0,
                  "wheelbase_m": 2.65, "center_to_front_m": 0.44 * 2.65,
                  "cornering_stiffness_front_nprad": 121599.4, "cornering_stiffness_rear_nprad": 151033.1}
"""openpilot's starting values for the RAV4 (selfdrive/car/toyota/interface.py: steerRatio 16.88,
tire_stiffness_factor 0.5533, mass 3650 lb + STD_CARGO_KG 136 kg, wheelbase 2.65 m,
centerToFront 0.44 L) and the axle cornering stiffnesses its scale_tire_stiffness gives them
(Civic base 192150 / 202500 N/rad at 1462 kg, CG at 0.4 L)."""


def understeer_gradient(mass_kg: float, l_f_m: float, l_r_m: float, c_f_nprad: float, c_r_nprad: float) -> float:
    """K_us = (m / L) (l_r / C_f - l_f / C_r) [rad / (m/s^2)] of the steady-state bicycle model."""
    L = l_f_m + l_r_m
    return mass_kg / L * (l_r_m / c_f_nprad - l_f_m / c_r_nprad)


@dataclass(frozen=True)
class SteerResponseFit:
    """Least-squares fit of the steady-state bicycle model to a drive (``steer_response_fit``):
    ``theta`` = (p1, p2, p3) with sigmas and covariance, the derived steer ratio, stiffness
    factor and angle offset with sigmas, the information gains and their explanation, and the
    numbers of windows and the speed range used."""

    theta: tuple[float, float, float]
    cov: np.ndarray
    steer_ratio: float
    steer_ratio_sigma: float
    stiffness_factor: float
    stiffness_factor_sigma: float
    angle_offset_deg: float
    angle_offset_sigma_deg: float
    yaw_rate_bias_degps: float
    gains: tuple[float, ...]
    gain_vectors: np.ndarray
    explanations: tuple
    n_windows: int
    speed_range_mps: tuple[float, float]
    steer_range_deg: tuple[float, float]
    residual_sigma: float
    combination: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    """(u_rms [m/s], q = s_R (L + K_us u_rms^2) [m], sigma_q [m]): the steady-state steering
    gain r / delta_sw = u / q at the drive's RMS speed, the combination the drive pins down."""

    def observable(self, gain_threshold: float = 1.0) -> dict[str, bool]:
        """Per quantity: its prior-relative direction is carried by identified directions only
        (|component in the unidentified directions|^2 < 0.5)."""
        weak = self.gain_vectors[:, np.asarray(self.gains) < gain_threshold]
        names = ("steer_ratio_x_wheelbase", "understeer_x_steer_ratio", "angle_offset")
        return {n: bool(np.sum(weak[i] ** 2) < 0.5) for i, n in enumerate(names)}


def steer_response_fit(t_s, speed_mps, steer_wheel_rad, yaw_rate_radps, course_rate_radps, *, wheelbase_m: float,
                       understeer0: float, prior_steer_ratio: float, window_s: float = 1.0,
                       min_speed_mps: float = 5.0, prior_rel_sigma=(0.25, 0.5), prior_offset_sigma_deg: float = 2.0
                       ) -> SteerResponseFit:
    """openpilot's learned quantities (steer ratio s_R, stiffness factor x, steering angle offset
    delta_0) from the steady-state bicycle model, linear in three parameters::

        r = u (delta_sw - delta_0) / (s_R (L + K_us u^2)),   K_us = K_0 / x
        u delta_sw = p1 r + p2 r u^2 + p3 u,   p1 = s_R L,  p2 = s_R K_0 / x,  p3 = delta_0

    ==========  ==========  ===================================================================
    symbol      unit        meaning
    ==========  ==========  ===================================================================
    r           rad/s       yaw rate: the ESC yaw rate minus its bias b_r, b_r = mean over the
                            windows of (r_ESC - course rate of the EKF velocity) (GNSS-based);
                            its variance var(b_r) = var(differences) / N enters the covariance
                            as J_b var(b_r) J_b^T, J_b = d theta / d b_r (central difference)
    u           m/s         speed (EKF); delta_sw [rad] the steering wheel angle (CAN)
    L, K_0      m, rad/(m/s^2)  wheelbase; understeer gradient at x = 1 (model priors)
    ==========  ==========  ===================================================================

    Signals are averaged over ``window_s`` windows (quasi-steady state, nearly independent
    errors); least squares gives theta and Cov = s^2 (A^T A)^-1 + J_b var(b_r) J_b^T (s^2:
    residual variance). The information I = Cov^-1 is compared with a prior (p1, p2 relative sigmas
    ``prior_rel_sigma`` about s_R L and s_R K_0, p3 sigma ``prior_offset_sigma_deg``) as in
    ``observability_report``: gains = eig(S I S), S = diag(prior sigmas); a direction with gain
    < 1 is not identified by the drive (it does not halve the prior variance). s_R = p1 / L,
    x = p1 K_0 / (L p2), delta_0 = p3 (sigmas by first-order propagation)."""
    from vdps_hil.estimation.observability_explain import explain_null_space

    t = np.asarray(t_s, dtype=float)
    u, sw, r_m, cr = (np.asarray(v, dtype=float) for v in (speed_mps, steer_wheel_rad, yaw_rate_radps,
                                                           course_rate_radps))
    ok = np.isfinite(u + sw + r_m + cr) & (u >= min_speed_mps)
    edges = np.arange(t[ok][0], t[ok][-1] + 1e-9, window_s)
    win = []
    for a, b in zip(edges[:-1], edges[1:]):
        m = ok & (t >= a) & (t < b)
        if m.sum() >= 3:
            win.append((u[m].mean(), r_m[m].mean(), sw[m].mean(), cr[m].mean()))
    W = np.array(win)
    n = W.shape[0]
    d = W[:, 1] - W[:, 3]  # yaw rate minus course rate per window
    bias = float(d.mean())
    var_bias = float(d.var(ddof=1) / n)

    def solve(b):
        rr = W[:, 1] - b
        a_ = np.column_stack([rr, rr * W[:, 0] ** 2, W[:, 0]])
        y_ = W[:, 0] * W[:, 2]
        th, *_ = np.linalg.lstsq(a_, y_, rcond=None)
        return a_, y_, th

    A, y, theta = solve(bias)
    res = y - A @ theta
    s2 = float(res @ res / max(n - 3, 1))
    db = 1e-4
    j_b = (solve(bias + db)[2] - solve(bias - db)[2]) / (2 * db)  # d theta / d bias
    cov = np.linalg.pinv(A.T @ A / s2) + np.outer(j_b, j_b) * var_bias
    info = np.linalg.pinv(cov)
    p1, p2, p3 = theta
    sr = p1 / wheelbase_m
    x = p1 * understeer0 / (wheelbase_m * p2) if p2 != 0 else math.inf
    j_x = np.array([understeer0 / (wheelbase_m * p2), -p1 * understeer0 / (wheelbase_m * p2 * p2), 0.0])
    prior = np.array([prior_steer_ratio * wheelbase_m * prior_rel_sigma[0],
                      prior_steer_ratio * understeer0 * prior_rel_sigma[1], math.radians(prior_offset_sigma_deg)])
    g = prior[:, None] * info * prior[None, :]
    gains, vecs = np.linalg.eigh(0.5 * (g + g.T))
    names = ("steer_ratio_x_wheelbase", "understeer_x_steer_ratio", "angle_offset")
    weak = vecs[:, gains < 1.0].T
    expl = list(explain_null_space(weak, names, "is barely seen in the data")) if weak.size else []
    # a constant road bank phi enters as -s_R K_us g sin(phi) u: the same column as the offset
    aug = np.column_stack([A, A[:, 2]])
    _, sv, vt = np.linalg.svd(aug / np.linalg.norm(aug, axis=0), full_matrices=False)
    null = vt[sv < 1e-9 * sv[0]]
    expl += explain_null_space(null, (*names, "road_bank_term"))
    u2 = float(np.mean(A[:, 2] ** 2))
    jq = np.array([1.0, u2, 0.0])
    comb = (math.sqrt(u2), float(p1 + p2 * u2), float(math.sqrt(max(jq @ cov @ jq, 0.0))))
    return SteerResponseFit(tuple(float(v) for v in theta), cov, float(sr), float(math.sqrt(cov[0, 0]) / wheelbase_m),
                            float(x), float(math.sqrt(max(j_x @ cov @ j_x, 0.0))), float(math.degrees(p3)),
                            float(math.degrees(math.sqrt(cov[2, 2]))), float(math.degrees(bias)),
                            tuple(float(v) for v in gains), vecs, tuple(expl), n,
                            (float(W[:, 0].min()), float(W[:, 0].max())),
                            (float(np.degrees(sw[ok].min())), float(np.degrees(sw[ok].max()))), float(math.sqrt(s2)),
                            comb)


def series(samples: Iterable[Sample], kind: str, fields: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(t_s (N,), values (N, len(fields))) of the valid samples of one kind (NaN where a field
    is absent)."""
    t, v = [], []
    for s in samples:
        if s.kind == kind and s.valid:
            t.append(s.t_ns / 1e9)
            v.append([s.fields.get(f, math.nan) for f in fields])
    return np.array(t), np.array(v, dtype=float).reshape(len(t), len(fields))


def steer_signals(samples: Sequence[Sample], track: Track, *, yaw_kind: str = "imu"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The inputs of ``steer_response_fit`` at the track's times: (t, speed (EKF), steering
    wheel angle (CAN, interpolated), yaw rate (``yaw_kind`` z rate, interpolated), course rate
    d/dt atan2(v_N, v_E) of the EKF velocity)."""
    ts, sw = series(samples, "steer", ("steer_wheel_angle_rad",))
    ty, wz = series(samples, yaw_kind, ("angular_rate_radps_z",))
    t = track.t_s
    v = track.vel_mps
    speed = np.hypot(v[:, 0], v[:, 1])
    course = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
    cr = np.gradient(course, t) if t.size > 1 else np.zeros_like(t)
    return t, speed, np.interp(t, ts, sw[:, 0]), np.interp(t, ty, wz[:, 0]), cr
