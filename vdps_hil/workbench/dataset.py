"""A drive as one time-aligned table of measured and estimated signals (the workbench's input).

Only the ``/raw/`` topics of a recording are read (``record.decode.decode_recording``) and only
a *model* vehicle file: the estimator pipeline (``estimation.pipeline.EstimatorPipeline``, eq
7-12) runs on the decoded samples exactly as it runs live, and the table puts its outputs next
to the sensor signals on one uniform grid (default 50 Hz: the signals are low-passed at 10 Hz).

Columns (SI, names carry units; ``i`` = wheel 1..4 FL FR RR RL, axes body x fwd y left z up)
---------------------------------------------------------------------------------------------
==============================================  ====================================================
``pos_g_m_{e,n,u}``, ``vel_g_mps_{e,n,u}``       EKF CG position / velocity, ENU (eq 7)
``roll_g_rad``, ``pitch_g_rad``, ``yaw_g_rad``   EKF absolute attitude (eq 1; yaw unwrapped)
``road_bank_rad``, ``road_grade_rad``            EKF road angles (eq 2)
``vel_b_mps_{x,y,z}``                            C_g^v v_g (eq 1)
``specific_force_b_mps2_{x,y,z}``                IMU, rotated into body axes and moved to the CG
                                                 with the model file's mounting
``rate_b_radps_{x,y,z}``, ``angular_accel_b_radps2_{x,y,z}``  gyro and its derivative
``wheel_speed_radps_i``, ``wheel_accel_radps2_i``  tachometers and their derivative
``susp_deflection_m_i``, ``susp_deflection_rate_mps_i``  suspension sensors and their derivative
``steer_wheel_angle_rad``, ``wheel_torque_nm_i``  inputs from the bus
==============================================  ====================================================

EKF sigmas are in ``table.sigma`` under the same names (positions, velocities, attitude, road).

Velocity (complementary, zero phase): the EKF corrects its velocity at every GNSS update (5 Hz
steps of a few cm/s), which a 10 Hz low-pass keeps; a step of 0.01 m/s in the lateral velocity
moves the axle forces by 100 N, far above the IMU's force noise. So the table's velocity is
v = v_int + LP(v_EKF - v_int), with v_int the integral of C^T f + g (IMU, EKF attitude) and LP a
zero-phase low-pass at ``velocity_crossover_hz`` (0.2 Hz): the slow part is the estimator's, the
fast part the IMU's.

Smoothing (offline, zero phase). Every signal goes through the same low-pass: a Butterworth of
order 4 at ``cutoff_hz`` (default 10 Hz) run forward and backward (``scipy.signal.filtfilt``) on
its own uniform grid; derivatives are central differences of the smoothed signal. Equal zero-
phase filtering keeps measured and modelled sides of eq 13 in step: a causal filter (the
estimator's alpha-beta, eq 12) delays its derivatives by ~1/(2 pi f_c) and that lag would show
up as a spurious residual proportional to the jerk. A sensor slower than
``min_rate_for_derivative_hz`` (e.g. Table 1's 1 Hz suspension) gives values but no derivative
(NaN): equations that need it are then not evaluated.

GNSS measurements (for the measurement effects' innovations, ``residuals``) are kept as they
arrived in ``table.gnss``: ``pos`` (ENU of the antenna on the estimator's origin, sigmas), ``att``
(roll, pitch, yaw, sigmas), ``vel`` (speed, course). EKF innovations per measurement kind (NIS,
dof) are in ``table.innovations``.

Measurement effects can be taken out before the estimator runs (``imu_effects``): each IMU
sample is replaced by the reading with the effect removed to first order, f = f_meas - (apply(f_meas)
- f_meas) (exact for the additive biases and the lever arm), with the rigid-body kinematics
from the smoothed gyro. The workbench uses this to re-estimate with an identified sensor effect.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from array import array
from typing import Iterable, Iterator, Mapping, Sequence

import numpy as np
from scipy.signal import butter, filtfilt

from vdps_hil.bus.samples import Sample, axis_fields, wheel_fields
from vdps_hil.estimation.estimates import Innovation
from vdps_hil.estimation.pipeline import EstimatorPipeline
from vdps_hil.estimation.pipeline_config import PipelineConfig
from vdps_hil.model.effects.base import ImuKinematics, MeasurementEffect
from vdps_hil.model.frames import dcm_gv_batch
from vdps_hil.model.params import Vehicle

__all__ = ["DatasetConfig", "DatasetError", "DriveTable", "decode_raw", "iter_raw", "load_drive", "build_table",
           "EstimatorRun", "run_estimator", "remove_imu_effects"]

_SF = axis_fields("specific_force_mps2")
_AR = axis_fields("angular_rate_radps")
_WS = wheel_fields("wheel_speed_radps")
_WT = wheel_fields("wheel_torque_nm")
_SUSP = wheel_fields("susp_deflection_m")
_GNSS_POS = ("gnss_lat_deg", "gnss_lon_deg", "gnss_alt_m", "gnss_geoid_sep_m", "gnss_pos_sigma_h_m",
             "gnss_pos_sigma_v_m", "gnss_fix_quality")
_GNSS_ATT = ("gnss_roll_rad", "gnss_pitch_rad", "gnss_yaw_rad", "gnss_roll_sigma_rad", "gnss_pitch_sigma_rad",
             "gnss_yaw_sigma_rad")
_GNSS_VEL = ("gnss_speed_mps", "gnss_course_rad")
_STREAM_FIELDS = {"imu": tuple(_SF) + tuple(_AR), "wheel_speed": tuple(_WS), "suspension": tuple(_SUSP),
                  "steer": ("steer_wheel_angle_rad",), "wheel_torque": tuple(_WT), "gnss_pos": _GNSS_POS,
                  "gnss_att": _GNSS_ATT, "gnss_vel": _GNSS_VEL}
STATE_COLUMNS = ("pos_g_m_e", "pos_g_m_n", "pos_g_m_u", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u",
                 "roll_g_rad", "pitch_g_rad", "yaw_g_rad", "road_bank_rad", "road_grade_rad")
"""Table names of the EKF states 0..10 of eq 7 (``psi_v`` follows from them, eq 4)."""


class DatasetError(ValueError):
    """A recording the workbench cannot use (one-line message)."""


@dataclass(frozen=True)
class DatasetConfig:
    """How a drive becomes a table.

    period_s: grid step [s] (default 0.02: five samples per period of the cutoff); cutoff_hz: zero-phase low-pass of every signal [Hz];
    settle_s: time after the estimator's initialisation left out (filter transient) [s];
    velocity_crossover_hz: below it the velocity is the estimator's, above it the integrated IMU's;
    min_rate_for_derivative_hz: slower sensors give no derivative; pipeline: estimator config."""

    period_s: float = 0.02
    cutoff_hz: float = 10.0
    settle_s: float = 1.0
    min_rate_for_derivative_hz: float = 20.0
    velocity_crossover_hz: float = 0.2
    pipeline: PipelineConfig | None = None

    def __post_init__(self):
        for k in ("period_s", "cutoff_hz", "min_rate_for_derivative_hz"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise DatasetError(f"DatasetConfig.{k} must be positive, got {v!r}")
        if self.cutoff_hz >= 0.5 / self.period_s:
            raise DatasetError("DatasetConfig.cutoff_hz must be below the grid's Nyquist frequency")


# ----------------------------------------------------------------------------------- decoding
def iter_raw(path: str | os.PathLike, *, dbc=None, signalmap=None) -> Iterator[Sample]:
    """The decoded ``/raw/`` samples of a recording in t_ns order, one at a time (nothing else
    is read, nothing is held: memory does not grow with the drive's length)."""
    from vdps_hil.record.decode import DecodeError, decode_recording

    try:
        yield from decode_recording(path, dbc=dbc, signalmap=signalmap)
    except DecodeError as e:
        raise DatasetError(str(e)) from None


def decode_raw(path: str | os.PathLike, *, dbc=None, signalmap=None) -> list[Sample]:
    """The decoded ``/raw/`` samples of a recording in t_ns order, as a list (about 2 MiB per
    second of drive: the workbench itself streams with :func:`iter_raw`)."""
    return list(iter_raw(path, dbc=dbc, signalmap=signalmap))


# ----------------------------------------------------------------------------------- estimator
@dataclass
class EstimatorRun:
    """The estimator's outputs sampled for the table: per grid instant the estimate (its own
    t_ns, x, sigma) and every Innovation; ``origin`` is the ENU origin it chose; counters."""

    est_t_ns: np.ndarray
    est_x: np.ndarray
    est_sigma: np.ndarray
    innovations: "InnovationLog | list[Innovation]"
    origin: object
    counters: dict


def run_estimator(samples: Sequence[Sample], vehicle: Vehicle, config: PipelineConfig | None = None,
                  period_s: float = 0.01) -> EstimatorRun:
    """Feed the samples to a fresh :class:`EstimatorPipeline`; take its estimate each time the
    bus time crosses a multiple of ``period_s``."""
    p = EstimatorPipeline(vehicle, config)
    step = int(round(period_s * 1e9))
    nxt = None
    ts, xs, ss, innov = [], [], [], InnovationLog()
    for i, s in enumerate(samples):
        out = p.handle(s)
        if i % 4096 == 4095:
            p.clear_input_log()  # its replay log (input_log) would hold the whole drive (as app.replay.replay_file)
        for o in out:
            if isinstance(o, Innovation):
                innov.add(o)
        t = s.t_ns
        if nxt is None:
            nxt = (t // step + 1) * step
        if t >= nxt:
            nxt = (t // step + 1) * step
            e = p.estimate()
            if e is not None and (not ts or e.t_ns > ts[-1]):
                ts.append(e.t_ns)
                xs.append(e.x)
                ss.append(e.sigma)
    if not ts:
        raise DatasetError("the estimator never initialised (no GNSS fix with a heading in the recording)")
    return EstimatorRun(np.array(ts, dtype=np.int64), np.array(xs), np.array(ss), innov, p.origin,
                        dict(p.counters))


class InnovationLog:
    """The estimator's innovations per measurement kind as packed arrays (an Innovation object
    per update would hold ~0.6 kB: 2000 updates per second of drive)."""

    def __init__(self):
        self._k: dict[str, dict[str, array]] = {}

    def add(self, o: Innovation) -> None:
        d = self._k.get(o.kind)
        if d is None:
            d = self._k[o.kind] = {"t": array("q"), "nis": array("d"), "dof": array("d"), "acc": array("b"),
                                   "n": array("l"), "inn": array("d"), "sig": array("d")}
        d["t"].append(o.t_ns)
        d["nis"].append(o.nis)
        d["dof"].append(o.dof)
        d["acc"].append(o.status == "accepted")
        d["n"].append(len(o.innovation))
        d["inn"].extend(o.innovation)
        m = len(o.innovation)
        sg = list(o.innovation_sigma)[:m]
        d["sig"].extend(sg + [math.nan] * (m - len(sg)))

    def __len__(self) -> int:
        return sum(len(d["t"]) for d in self._k.values())

    def tables(self, rel) -> dict[str, dict[str, np.ndarray]]:
        """As ``DriveTable.innovations``: per kind t_s, nis, dof, accepted, innovation / sigma
        (rows padded with NaN to the kind's widest update)."""
        out = {}
        for kind, d in self._k.items():
            n = np.frombuffer(d["n"], dtype=np.int_) if len(d["n"]) else np.zeros(0, int)
            w = int(n.max()) if len(n) else 0
            inn = np.full((len(n), w), np.nan)
            sg = np.full((len(n), w), np.nan)
            cols = np.arange(w)[None, :] < n[:, None]
            inn[cols] = np.frombuffer(d["inn"], dtype=float)
            sg[cols] = np.frombuffer(d["sig"], dtype=float)
            out[kind] = {"t_s": rel(np.frombuffer(d["t"], dtype=np.int64)), "nis": np.array(d["nis"], dtype=float),
                         "dof": np.array(d["dof"], dtype=float), "accepted": np.array(d["acc"], dtype=bool),
                         "innovation": inn, "sigma": sg}
        return out


# ----------------------------------------------------------------------------------- helpers
class _Smoother:
    """Zero-phase Butterworth low-pass at one cutoff, designed per sampling rate."""

    def __init__(self, cutoff_hz: float, order: int = 4):
        self.cutoff_hz = cutoff_hz
        self.order = order
        self._cache: dict[float, tuple] = {}

    def __call__(self, y: np.ndarray, rate_hz: float) -> np.ndarray:
        if rate_hz <= 2.2 * self.cutoff_hz:
            return y.copy()
        key = round(rate_hz, 6)
        if key not in self._cache:
            self._cache[key] = butter(self.order, self.cutoff_hz / (0.5 * rate_hz))
        b, a = self._cache[key]
        padlen = 3 * max(len(a), len(b))
        if y.shape[0] <= padlen:
            return y.copy()
        return filtfilt(b, a, y, axis=0)


class Streams:
    """The valid samples of each kind the table uses, collected in one pass as packed arrays
    (t_ns, and the kind's fields with NaN where a sample lacks one): 8 bytes a value, so a
    drive is never held as Sample objects. ``count``: every sample seen."""

    def __init__(self, kinds: Mapping[str, Sequence[str]] | None = None):
        self.names = {k: tuple(v) for k, v in (kinds or _STREAM_FIELDS).items()}
        self._t = {k: array("q") for k in self.names}
        self._v = {k: array("d") for k in self.names}
        self.count = 0

    def add(self, s: Sample) -> None:
        self.count += 1
        names = self.names.get(s.kind)
        if names is None or not s.valid:
            return
        f = s.fields
        self._t[s.kind].append(s.t_ns)
        self._v[s.kind].extend([f.get(n, math.nan) for n in names])

    def tap(self, samples: Iterable[Sample]) -> Iterator[Sample]:
        """Pass the samples through, collecting them on the way."""
        for s in samples:
            self.add(s)
            yield s

    def get(self, kind: str, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """(t_ns (n,), values (n, k)) of ``names`` of one kind."""
        have = self.names[kind]
        t = np.frombuffer(self._t[kind], dtype=np.int64).copy() if len(self._t[kind]) else np.zeros(0, np.int64)
        v = np.frombuffer(self._v[kind], dtype=float).reshape(len(t), len(have)) if len(t) else np.zeros((0, len(have)))
        return t, v[:, [have.index(n) for n in names]].copy()


def _stream(samples, kind: str, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(t_ns (n,), values (n, k)) of one sample kind (from :class:`Streams` or a sample
    sequence); a field missing in a sample -> NaN."""
    if not isinstance(samples, Streams):
        st = Streams({kind: names})
        for s in samples:
            st.add(s)
        samples = st
    return samples.get(kind, names)


def _uniform(t_ns: np.ndarray, v: np.ndarray, t0_ns: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Resample a stream (NaN-free rows) onto its own uniform grid (median step); times in s
    relative to ``t0_ns``."""
    ok = np.all(np.isfinite(v), axis=1)
    t_ns, v = t_ns[ok], v[ok]
    if len(t_ns) < 3:
        return (t_ns - t0_ns).astype(float) * 1e-9, v, 0.0
    dt = float(np.median(np.diff(t_ns))) * 1e-9
    if dt <= 0:
        dt = 1e-3
    t = (t_ns - t0_ns).astype(float) * 1e-9
    tg = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    vg = np.column_stack([np.interp(tg, t, v[:, k]) for k in range(v.shape[1])])
    return tg, vg, 1.0 / dt


def _on_grid(grid_s: np.ndarray, t_s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Linear interpolation onto the grid; NaN outside the stream's span."""
    out = np.full((len(grid_s), v.shape[1]), np.nan)
    if len(t_s) < 2:
        return out
    inside = (grid_s >= t_s[0]) & (grid_s <= t_s[-1])
    for k in range(v.shape[1]):
        out[inside, k] = np.interp(grid_s[inside], t_s, v[:, k])
    return out


def _smoothed(samples, kind, names, smoother, grid_s, t0_ns, min_rate_hz, want_rate: bool):
    """(values on the grid, derivatives on the grid or NaN, native rate) of one stream."""
    t_ns, v = _stream(samples, kind, names)
    tg, vg, rate = _uniform(t_ns, v, t0_ns)
    if rate <= 0:
        nan = np.full((len(grid_s), len(names)), np.nan)
        return nan, nan, 0.0
    vs = smoother(vg, rate)
    val = _on_grid(grid_s, tg, vs)
    if want_rate and rate >= min_rate_hz:
        der = _on_grid(grid_s, tg, np.gradient(vs, 1.0 / rate, axis=0))
    else:
        der = np.full_like(val, np.nan)
    return val, der, rate


def remove_imu_effects(samples: Sequence[Sample], effects: Sequence[MeasurementEffect],
                       cutoff_hz: float = 10.0) -> list[Sample]:
    """IMU samples with the measurement effects removed to first order (module docstring):
    f = f_meas - (apply(f_meas, kin) - f_meas); other samples unchanged."""
    return list(_imu_corrected(samples, effects, _gyro_track(samples, cutoff_hz)))


def _gyro_track(samples: Iterable[Sample], cutoff_hz: float):
    """(t_base_ns, grid [s], smoothed rate, its derivative) of the gyro, or None (one pass)."""
    t_ns, w = _stream(samples, "imu", _AR)
    t_base = int(t_ns[0]) if len(t_ns) else 0
    tg, wg, rate = _uniform(t_ns, w, t_base)
    if rate <= 0:
        return None
    ws = _Smoother(cutoff_hz)(wg, rate)
    return t_base, tg, ws, np.gradient(ws, 1.0 / rate, axis=0)


def _imu_corrected(samples: Iterable[Sample], effects: Sequence[MeasurementEffect], track) -> Iterator[Sample]:
    """The samples with the effects taken out of the IMU ones (``track``: :func:`_gyro_track`)."""
    effects = [e for e in effects if isinstance(e, MeasurementEffect)]
    if not effects or track is None:
        yield from samples
        return
    t_base, tg, ws, wd = track
    for s in samples:
        if s.kind != "imu" or not s.valid:
            yield s
            continue
        ts = (s.t_ns - t_base) * 1e-9
        om = tuple(float(np.interp(ts, tg, ws[:, k])) for k in range(3))
        od = tuple(float(np.interp(ts, tg, wd[:, k])) for k in range(3))
        f0 = dict(s.fields)
        kin = ImuKinematics(ts, tuple(f0.get(n, 0.0) for n in _SF), om, od)
        corr = dict(f0)
        for e in effects:
            applied = e.apply(f0, kin)
            for k, v in applied.items():
                if k in corr and k in f0:
                    corr[k] = corr[k] - (v - f0[k])
        yield Sample(s.t_ns, s.source, s.kind, corr, s.wall_time_ns, s.valid)


# ----------------------------------------------------------------------------------- table
@dataclass
class DriveTable:
    """The time-aligned table of one drive (module docstring). ``t_s`` relative to ``t0_ns``."""

    t0_ns: int
    t_s: np.ndarray
    columns: dict[str, np.ndarray]
    sigma: dict[str, np.ndarray]
    gnss: dict[str, dict[str, np.ndarray]]
    innovations: dict[str, dict[str, np.ndarray]]
    rates_hz: dict[str, float]
    vehicle: Vehicle
    counters: dict = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) if len(self.t_s) else 0.0

    @property
    def period_s(self) -> float:
        return float(np.median(np.diff(self.t_s))) if len(self.t_s) > 1 else 0.0

    def has(self, *names: str) -> bool:
        """True when every named column exists and is finite somewhere."""
        return all(n in self.columns and np.isfinite(self.columns[n]).any() for n in names)

    def matrix(self, names: Sequence[str]) -> np.ndarray:
        return np.column_stack([self.columns[n] for n in names])

    def slice(self, mask: np.ndarray) -> "DriveTable":
        """Rows where ``mask`` is True (GNSS and innovations within the same time span)."""
        mask = np.asarray(mask, bool)
        t = self.t_s[mask]
        lo, hi = (t[0], t[-1]) if len(t) else (0.0, -1.0)

        def cut(d):
            out = {}
            for k, tab in d.items():
                sel = (tab["t_s"] >= lo) & (tab["t_s"] <= hi)
                out[k] = {n: a[sel] for n, a in tab.items()}
            return out

        return DriveTable(self.t0_ns, t, {k: v[mask] for k, v in self.columns.items()},
                          {k: v[mask] for k, v in self.sigma.items()}, cut(self.gnss), cut(self.innovations),
                          dict(self.rates_hz), self.vehicle, dict(self.counters))


def build_table(samples: Streams | Sequence[Sample], run: EstimatorRun, vehicle: Vehicle,
                config: DatasetConfig | None = None) -> DriveTable:
    """Put the estimator's outputs and the smoothed sensor signals on one grid (``samples``:
    the drive's :class:`Streams`, or its samples)."""
    cfg = config or DatasetConfig()
    if not isinstance(samples, Streams):
        st = Streams()
        for s in samples:
            st.add(s)
        samples = st
    sm = _Smoother(cfg.cutoff_hz)
    t_first = int(run.est_t_ns[0]) + int(round(cfg.settle_s * 1e9))
    t_last = int(run.est_t_ns[-1])
    if t_last - t_first < 10 * cfg.period_s * 1e9:
        raise DatasetError("the drive is too short after the estimator settled")
    step = int(round(cfg.period_s * 1e9))
    t0_ns = (t_first // step + 1) * step
    grid_ns = np.arange(t0_ns, t_last, step, dtype=np.int64)
    grid = (grid_ns - t0_ns) * 1e-9
    rel = lambda t_ns: (np.asarray(t_ns, dtype=np.int64) - t0_ns) * 1e-9  # noqa: E731
    cols: dict[str, np.ndarray] = {}
    sig: dict[str, np.ndarray] = {}
    rates: dict[str, float] = {}

    # --- estimator states (eq 7): interpolated, yaw unwrapped, smoothed like every signal
    te = rel(run.est_t_ns)
    x = run.est_x[:, :11].copy()
    x[:, 8] = np.unwrap(x[:, 8])
    er = 1.0 / max(float(np.median(np.diff(te))), 1e-4) if len(te) > 1 else 100.0
    xg = _on_grid(grid, te, x)
    ok = np.all(np.isfinite(xg), axis=1)
    xs = np.full_like(xg, np.nan)
    if ok.sum() > 20:
        xs[ok] = sm(xg[ok], er)
    sg = _on_grid(grid, te, run.est_sigma[:, :11])
    for k, n in enumerate(STATE_COLUMNS):
        cols[n] = xs[:, k]
        sig[n] = sg[:, k]
    c = dcm_gv_batch(cols["roll_g_rad"], cols["pitch_g_rad"], cols["yaw_g_rad"])
    vg_raw = _on_grid(grid, te, run.est_x[:, 3:6])

    # --- IMU: rotate sensor -> body, smooth, derivative of the rate, move to the CG
    imu_names = list(_SF) + list(_AR)
    val, der, rate = _smoothed(samples, "imu", imu_names, sm, grid, t0_ns, cfg.min_rate_for_derivative_hz, True)
    rates["imu"] = rate
    m = vehicle.mounting
    rot = np.asarray(m.imu_rotation_rpy_rad, dtype=float)
    f, w, wd = val[:, 0:3], val[:, 3:6], der[:, 3:6]
    if rot.any():
        r_sb = dcm_gv_batch(np.array([rot[0]]), np.array([rot[1]]), np.array([rot[2]]))[0].T
        f, w, wd = f @ r_sb.T, w @ r_sb.T, wd @ r_sb.T
    arm = np.asarray(m.imu_lever_arm_m, dtype=float)
    if arm.any():
        f = f - np.cross(wd, arm) - np.cross(w, np.cross(w, arm))
    for k, a in enumerate("xyz"):
        cols[f"specific_force_b_mps2_{a}"] = f[:, k]
        cols[f"rate_b_radps_{a}"] = w[:, k]
        cols[f"angular_accel_b_radps2_{a}"] = wd[:, k]

    # --- velocity: the estimate's slow part, the IMU's fast part (zero-phase complementary)
    vg = _complementary_velocity(grid, vg_raw, c, f, cfg.velocity_crossover_hz)
    for k, a in enumerate("enu"):
        cols[f"vel_g_mps_{a}"] = vg[:, k]
    vb = np.einsum("nij,nj->ni", c, vg)
    for k, a in enumerate("xyz"):
        cols[f"vel_b_mps_{a}"] = vb[:, k]

    # --- wheels: each tachometer field as its own stream (front and rear come in different frames)
    wrates = []
    for i in range(4):
        v_, d_, r_ = _smoothed(samples, "wheel_speed", [_WS[i]], sm, grid, t0_ns, cfg.min_rate_for_derivative_hz, True)
        cols[f"wheel_speed_radps_{i + 1}"] = v_[:, 0]
        cols[f"wheel_accel_radps2_{i + 1}"] = d_[:, 0]
        wrates.append(r_)
    rates["wheel_speed"] = min(wrates)
    v_, d_, r_ = _smoothed(samples, "suspension", list(_SUSP), sm, grid, t0_ns, cfg.min_rate_for_derivative_hz, True)
    rates["suspension"] = r_
    for i in range(4):
        cols[f"susp_deflection_m_{i + 1}"] = v_[:, i]
        cols[f"susp_deflection_rate_mps_{i + 1}"] = d_[:, i]

    # --- inputs: held between samples (linear between close samples), not smoothed
    for kind, names in (("steer", ["steer_wheel_angle_rad"]), ("wheel_torque", list(_WT))):
        t_ns, v = _stream(samples, kind, names)
        rates[kind] = (1e9 / float(np.median(np.diff(t_ns)))) if len(t_ns) > 2 else 0.0
        g = np.full((len(grid), len(names)), np.nan)
        for k in range(len(names)):
            okk = np.isfinite(v[:, k]) if len(t_ns) else np.zeros(0, bool)
            if okk.sum() >= 2:
                tt = rel(t_ns[okk])
                inside = (grid >= tt[0]) & (grid <= tt[-1] + 0.1)
                g[inside, k] = np.interp(grid[inside], tt, v[okk, k])
        for k, n in enumerate(names):
            cols[n] = g[:, k]

    # --- GNSS as measured (for the innovations of the measurement effects)
    gnss = _gnss_tables(samples, run.origin, rel)
    innov = _innovation_tables(run.innovations, rel)
    counters = {"estimator": run.counters, "samples": samples.count}
    return DriveTable(t0_ns, grid, cols, sig, gnss, innov, rates, vehicle, counters)


def _complementary_velocity(t: np.ndarray, v_est: np.ndarray, c_gv: np.ndarray, f_b: np.ndarray,
                            crossover_hz: float) -> np.ndarray:
    """v = v_int + LP(v_est - v_int), v_int = integral of C^T f + g (ENU), LP zero phase at the
    crossover: the estimate's corrections at every GNSS update (5 Hz steps) are replaced by the
    integrated IMU, the slow part stays the estimate's (module docstring)."""
    ok = np.all(np.isfinite(v_est), axis=1) & np.all(np.isfinite(f_b), axis=1) & np.all(np.isfinite(c_gv), axis=(1, 2))
    out = v_est.copy()
    if ok.sum() < 20 or crossover_hz <= 0:
        return out
    idx = np.flatnonzero(ok)
    # the longest contiguous run
    br = np.flatnonzero(np.diff(idx) > 1)
    st = np.r_[0, br + 1]
    en = np.r_[br, len(idx) - 1]
    j = int(np.argmax(en - st))
    sel = idx[st[j]:en[j] + 1]
    tt = t[sel]
    acc = np.einsum("nji,nj->ni", c_gv[sel], f_b[sel]) + np.array([0.0, 0.0, -9.80665])
    dt = np.diff(tt)
    vint = np.zeros_like(acc)
    vint[1:] = np.cumsum(0.5 * (acc[1:] + acc[:-1]) * dt[:, None], axis=0)
    rate = 1.0 / float(np.median(dt))
    if crossover_hz >= 0.45 * rate:
        return out
    b, a = butter(2, crossover_hz / (0.5 * rate))
    d = v_est[sel] - vint
    if len(d) <= 3 * max(len(a), len(b)):
        return out
    out[sel] = vint + filtfilt(b, a, d, axis=0)
    return out


def _gnss_tables(samples, origin, rel) -> dict[str, dict[str, np.ndarray]]:
    out: dict[str, dict[str, np.ndarray]] = {}
    t, v = _stream(samples, "gnss_pos", _GNSS_POS)
    if len(t) and origin is not None:
        sep = np.where(np.isfinite(v[:, 3]), v[:, 3], 0.0)
        ok = np.isfinite(v[:, 0] + v[:, 1] + v[:, 2]) & ~(v[:, 6] <= 0)
        enu = np.array([origin.to_enu(a, b, h) for a, b, h in zip(v[ok, 0], v[ok, 1], v[ok, 2] + sep[ok])])
        enu = enu.reshape(-1, 3)
        out["pos"] = {"t_s": rel(t[ok]), "e_m": enu[:, 0], "n_m": enu[:, 1], "u_m": enu[:, 2],
                      "sigma_h_m": v[ok, 4], "sigma_v_m": v[ok, 5]}
    t, v = _stream(samples, "gnss_att", _GNSS_ATT)
    if len(t):
        out["att"] = {"t_s": rel(t), "roll_rad": v[:, 0], "pitch_rad": v[:, 1], "yaw_rad": v[:, 2],
                      "roll_sigma_rad": v[:, 3], "pitch_sigma_rad": v[:, 4], "yaw_sigma_rad": v[:, 5]}
    t, v = _stream(samples, "gnss_vel", _GNSS_VEL)
    if len(t):
        out["vel"] = {"t_s": rel(t), "speed_mps": v[:, 0], "course_rad": v[:, 1]}
    return out


def _innovation_tables(innovations, rel) -> dict[str, dict[str, np.ndarray]]:
    if isinstance(innovations, InnovationLog):
        return innovations.tables(rel)
    by: dict[str, list[Innovation]] = {}
    for o in innovations:
        by.setdefault(o.kind, []).append(o)
    out = {}
    for kind, lst in by.items():
        n = max(len(o.innovation) for o in lst)
        inn = np.full((len(lst), n), np.nan)
        sg = np.full((len(lst), n), np.nan)
        for j, o in enumerate(lst):
            inn[j, :len(o.innovation)] = o.innovation
            sg[j, :len(o.innovation_sigma)] = o.innovation_sigma
        out[kind] = {"t_s": rel([o.t_ns for o in lst]), "nis": np.array([o.nis for o in lst], dtype=float),
                     "dof": np.array([o.dof for o in lst], dtype=float),
                     "accepted": np.array([o.status == "accepted" for o in lst]),
                     "innovation": inn, "sigma": sg}
    return out


def load_drive(path: str | os.PathLike, vehicle: Vehicle, *, dbc=None, signalmap=None,
               config: DatasetConfig | None = None, imu_effects: Sequence[MeasurementEffect] = (),
               samples: Iterable[Sample] | None = None) -> DriveTable:
    """Recording (``/raw/`` only) + model vehicle -> :class:`DriveTable`.

    ``samples``: already decoded samples (skips decoding); ``imu_effects``: measurement effects
    taken out of the IMU readings before the estimator runs (module docstring). The samples
    stream through the estimator while the table's signals are collected as packed arrays
    (:class:`Streams`); with ``imu_effects`` the recording is decoded twice (the gyro track
    first, then the corrected samples), so no list of samples is ever held."""
    if getattr(vehicle, "kind", None) != "model":
        raise DatasetError("the workbench reads only a model vehicle file (kind = \"model\")")
    cfg = config or DatasetConfig()

    def source() -> Iterable[Sample]:
        return iter_raw(path, dbc=dbc, signalmap=signalmap) if samples is None else samples

    if samples is not None and imu_effects and iter(samples) is samples:
        samples = list(samples)  # a one-shot iterator cannot be read twice
    feed = source()
    if imu_effects:
        feed = _imu_corrected(source(), imu_effects, _gyro_track(feed, cfg.cutoff_hz))
    streams = Streams()
    try:
        run = run_estimator(streams.tap(feed), vehicle, cfg.pipeline, cfg.period_s)
    except DatasetError:
        if not streams.count:
            raise DatasetError(f"{path}: no decodable /raw/ samples") from None
        raise
    return build_table(streams, run, vehicle, cfg)


def table_from_samples(samples: Iterable[Sample], vehicle: Vehicle, config: DatasetConfig | None = None,
                       imu_effects: Sequence[MeasurementEffect] = ()) -> DriveTable:
    """As :func:`load_drive` from decoded samples (a sequence or an iterator)."""
    return load_drive("<samples>", vehicle, config=config, imu_effects=imu_effects, samples=samples)


def column_names(kind: str) -> Mapping[str, tuple[str, ...]]:
    """Column groups by sensor (for reports)."""
    return {"imu": tuple(f"specific_force_b_mps2_{a}" for a in "xyz") + tuple(f"rate_b_radps_{a}" for a in "xyz"),
            "wheel": tuple(f"wheel_speed_radps_{i}" for i in range(1, 5)),
            "suspension": tuple(f"susp_deflection_m_{i}" for i in range(1, 5))}[kind]
