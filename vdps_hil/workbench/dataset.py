"""A drive as one time-aligned table of measured and estimated signals (the workbench's input).

Only the ``/raw/`` topics of a recording are read (``record.decode.decode_recording``) and only
a *model* vehicle file: the estimator (eq 7-12) and the identifier (eq 19-23) run on the decoded
samples exactly as ``vdps replay`` runs them (``estimator_run``: the Figure 2 node configured by
the replay's rule, the sensor set named or inferred from the recording), and the table puts the
estimator's outputs next to the sensor signals on one uniform grid (default 50 Hz: the signals
are low-passed at 10 Hz). The identifier runs only with ``DatasetConfig(identify=True)``, its
outcome then kept as ``table.rls``: the estimator does not read it (the same states either way)
and the workbench identifies the parameters itself, so by default it is skipped (a third of the
estimator pass's time).

Columns (SI, names carry units; ``i`` = wheel 1..4 FL FR RR RL, axes body x fwd y left z up)
---------------------------------------------------------------------------------------------
==============================================  ====================================================
``pos_g_m_{e,n,u}``, ``vel_g_mps_{e,n,u}``       EKF CG position / velocity, ENU (eq 7)
``roll_g_rad``, ``pitch_g_rad``, ``yaw_g_rad``   EKF absolute attitude (eq 1; yaw unwrapped)
``road_bank_rad``, ``road_grade_rad``            EKF road angles (eq 2)
``vel_b_mps_{x,y,z}``                            C_g^v v_g (eq 1)
``specific_force_b_mps2_{x,y,z}``                IMU, rotated into body axes and moved to the CG
                                                 with the model file's mounting
``rate_b_radps_{x,y,z}``, ``angular_accel_b_radps2_{x,y,z}``  gyro (the estimator's gyro bias out) and its derivative
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

GNSS measurements (for the measurement effects' innovations, ``innovations``) are kept as they
arrived in ``table.gnss``: ``pos`` (ENU of the antenna on the estimator's origin, sigmas), ``att``
(roll, pitch, yaw, sigmas), ``vel`` (speed, course). EKF innovations per measurement kind (NIS,
dof) are in ``table.innovations``.

Where the steps live: decoding, per-kind sample streams and the smoothing (``streams``); the
estimator's pass over the drive (``estimator_run``); measurement effects taken out of the IMU
readings before it (``imu_effects``, ``load_drive(imu_effects=...)``); this module puts them on
one grid (:func:`build_table`).

The gyro rates lose the estimator's final gyro bias estimate where the sensor set carries bias
states (the real-car sets): the ESC cluster of the RAV4 reads -0.40 deg/s at rest, and through the
yaw rate in the slip angles that bias put -246 N m into the mean yaw residual (raw residuals with
the model file's parameters; taken out, +63 N m). Its accelerometer bias estimate is not taken
out: with it taken out, the RAV4's inferred set (phone IMU) had its IMU-bias candidate fit a
lateral bias of -1.12 m/s^2 where it fits -0.41 without, so the filter's estimate is not the bias
the GNSS innovations see there (why was not investigated; 2026-12-06).
"""

from __future__ import annotations

import itertools
import math
import os
from dataclasses import dataclass, field
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np
from scipy.signal import butter, filtfilt

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.pipeline import PipelineConfig
from vdps_hil.estimation.sensorsets import KindMap
from vdps_hil.pipeline.configure import DEFAULT_SUSP_SIGMA_M, SystemConfigError, sample_stats, system_config
from vdps_hil.pipeline.node import SystemConfig
from vdps_hil.model.effects.base import MeasurementEffect
from vdps_hil.model.frames import dcm_gv_batch
from vdps_hil.model.params import Vehicle

from .estimator_run import EstimatorRun, RlsResult, innovation_tables, renamed, run_system
from .imu_effects import gyro_track, imu_corrected
from .streams import (ANGULAR_RATE_FIELDS, ESC_SUBSTITUTES, GNSS_ATT_FIELDS, GNSS_POS_FIELDS, GNSS_VEL_FIELDS,
                      SPECIFIC_FORCE_FIELDS, SUSPENSION_FIELDS, WHEEL_SPEED_FIELDS, WHEEL_TORQUE_FIELDS, DatasetError,
                      Smoother, Streams, iter_raw, on_grid, smoothed, smoothed_or_substituted, stream)

__all__ = ["DatasetConfig", "DatasetError", "DriveTable", "load_drive", "reestimator", "build_table",
           "table_from_samples", "column_names", "STATE_COLUMNS"]

STATE_COLUMNS = ("pos_g_m_e", "pos_g_m_n", "pos_g_m_u", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u",
                 "roll_g_rad", "pitch_g_rad", "yaw_g_rad", "road_bank_rad", "road_grade_rad")
"""Table names of the EKF states 0..10 of eq 7 (``psi_v`` follows from them, eq 4)."""


@dataclass(frozen=True)
class DatasetConfig:
    """How a drive becomes a table.

    period_s: grid step [s] (default 0.02: five samples per period of the cutoff); cutoff_hz: zero-phase low-pass of every signal [Hz];
    settle_s: time after the estimator's initialisation left out (filter transient) [s];
    velocity_crossover_hz: below it the velocity is the estimator's, above it the integrated IMU's;
    min_rate_for_derivative_hz: slower sensors give no derivative; sensorset: a named sensor set
    (``configs/sensorsets``; default inferred from the recording, as ``vdps replay``);
    susp_sigma_m: the suspension sensor's sigma (``vdps replay --susp-sigma``); pipeline: an
    estimator config replacing the sensor set's; identify: also run ``vdps replay``'s identifier
    (eq 19-23) and keep its outcome as ``table.rls`` (the estimate is the same without it)."""

    period_s: float = 0.02
    cutoff_hz: float = 10.0
    settle_s: float = 1.0
    min_rate_for_derivative_hz: float = 20.0
    velocity_crossover_hz: float = 0.2
    sensorset: str | None = None
    susp_sigma_m: float = DEFAULT_SUSP_SIGMA_M
    pipeline: PipelineConfig | None = None
    identify: bool = False

    def __post_init__(self):
        for k in ("period_s", "cutoff_hz", "min_rate_for_derivative_hz"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise DatasetError(f"DatasetConfig.{k} must be positive, got {v!r}")
        if self.cutoff_hz >= 0.5 / self.period_s:
            raise DatasetError("DatasetConfig.cutoff_hz must be below the grid's Nyquist frequency")


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
    rls: RlsResult | None = None
    sensors: dict = field(default_factory=dict)

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
                          dict(self.rates_hz), self.vehicle, dict(self.counters), self.rls, dict(self.sensors))


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
    sm = Smoother(cfg.cutoff_hz)
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
    c, vg_raw = _state_columns(run, grid, rel, sm, cols, sig)
    f, subst = _imu_columns(samples, vehicle, grid, t0_ns, sm, cfg, cols, rates, run.gyro_bias_radps)
    _velocity_columns(grid, vg_raw, c, f, cfg, cols)
    _wheel_columns(samples, grid, t0_ns, sm, cfg, cols, rates)
    _input_columns(samples, grid, rel, cols, rates)

    # --- GNSS as measured (for the innovations of the measurement effects)
    gnss = _gnss_tables(samples, run.origin, rel)
    innov = innovation_tables(run.innovations, rel)
    counters = {"estimator": run.counters, "samples": samples.count}
    return DriveTable(t0_ns, grid, cols, sig, gnss, innov, rates, vehicle, counters, run.rls,
                      {"imu_substituted": list(subst)} if subst else {})


def _state_columns(run: EstimatorRun, grid: np.ndarray, rel: Callable, sm: Smoother, cols: dict,
                   sig: dict) -> tuple[np.ndarray, np.ndarray]:
    """The estimator states (eq 7) on the grid: interpolated, yaw unwrapped, smoothed like every
    signal, with their sigmas. Returns (C_g^v per row (eq 1), the unsmoothed ENU velocity)."""
    te = rel(run.est_t_ns)
    x = run.est_x[:, :11].copy()
    x[:, 8] = np.unwrap(x[:, 8])
    er = 1.0 / max(float(np.median(np.diff(te))), 1e-4) if len(te) > 1 else 100.0
    xg = on_grid(grid, te, x)
    ok = np.all(np.isfinite(xg), axis=1)
    xs = np.full_like(xg, np.nan)
    if ok.sum() > 20:
        xs[ok] = sm(xg[ok], er)
    sg = on_grid(grid, te, run.est_sigma[:, :11])
    for k, n in enumerate(STATE_COLUMNS):
        cols[n] = xs[:, k]
        sig[n] = sg[:, k]
    c = dcm_gv_batch(cols["roll_g_rad"], cols["pitch_g_rad"], cols["yaw_g_rad"])
    vg_raw = on_grid(grid, te, run.est_x[:, 3:6])
    return c, vg_raw


def _imu_columns(samples: Streams, vehicle: Vehicle, grid: np.ndarray, t0_ns: int, sm: Smoother, cfg: DatasetConfig,
                 cols: dict, rates: dict, gyro_bias=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, tuple[str, ...]]:
    """IMU: rotate sensor -> body, smooth, derivative of the rate, move to the CG (the model
    file's mounting), with the estimator's final gyro bias taken out of the rates (``gyro_bias``
    per body axis, ``EstimatorRun.gyro_bias_radps``: w_b = w - b_g as the estimator's input; zero
    where the sensor set carries no bias state). Its accelerometer bias is not taken out (module
    docstring). Returns (the specific force at the CG in body axes (n, 3), the sensor fields
    substituted: an ESC cluster's missing axes, ``streams.ESC_SUBSTITUTES``)."""
    imu_names = list(SPECIFIC_FORCE_FIELDS) + list(ANGULAR_RATE_FIELDS)
    val, der, rate, subst = smoothed_or_substituted(samples, "imu", imu_names, ESC_SUBSTITUTES, sm, grid, t0_ns,
                                                    cfg.min_rate_for_derivative_hz)
    rates["imu"] = rate
    m = vehicle.mounting
    rot = np.asarray(m.imu_rotation_rpy_rad, dtype=float)
    f, w, wd = val[:, 0:3], val[:, 3:6], der[:, 3:6]
    if rot.any():
        r_sb = dcm_gv_batch(np.array([rot[0]]), np.array([rot[1]]), np.array([rot[2]]))[0].T
        f, w, wd = f @ r_sb.T, w @ r_sb.T, wd @ r_sb.T
    bg = np.asarray(gyro_bias, dtype=float)
    if bg.any():
        w = w - bg  # a constant: the derivative wd is unchanged
    arm = np.asarray(m.imu_lever_arm_m, dtype=float)
    if arm.any():
        f = f - np.cross(wd, arm) - np.cross(w, np.cross(w, arm))
    for k, a in enumerate("xyz"):
        cols[f"specific_force_b_mps2_{a}"] = f[:, k]
        cols[f"rate_b_radps_{a}"] = w[:, k]
        cols[f"angular_accel_b_radps2_{a}"] = wd[:, k]
    return f, subst


def _velocity_columns(grid: np.ndarray, vg_raw: np.ndarray, c: np.ndarray, f: np.ndarray, cfg: DatasetConfig,
                      cols: dict) -> None:
    """Velocity: the estimate's slow part, the IMU's fast part (zero-phase complementary), in
    ENU and rotated into the body (eq 1)."""
    vg = _complementary_velocity(grid, vg_raw, c, f, cfg.velocity_crossover_hz)
    for k, a in enumerate("enu"):
        cols[f"vel_g_mps_{a}"] = vg[:, k]
    vb = np.einsum("nij,nj->ni", c, vg)
    for k, a in enumerate("xyz"):
        cols[f"vel_b_mps_{a}"] = vb[:, k]


def _wheel_columns(samples: Streams, grid: np.ndarray, t0_ns: int, sm: Smoother, cfg: DatasetConfig, cols: dict,
                   rates: dict) -> None:
    """Wheel speeds and suspension deflections with their derivatives (each tachometer field as
    its own stream: front and rear come in different frames)."""
    wrates = []
    for i in range(4):
        v_, d_, r_ = smoothed(samples, "wheel_speed", [WHEEL_SPEED_FIELDS[i]], sm, grid, t0_ns,
                              cfg.min_rate_for_derivative_hz, True)
        cols[f"wheel_speed_radps_{i + 1}"] = v_[:, 0]
        cols[f"wheel_accel_radps2_{i + 1}"] = d_[:, 0]
        wrates.append(r_)
    rates["wheel_speed"] = min(wrates)
    v_, d_, r_ = smoothed(samples, "suspension", list(SUSPENSION_FIELDS), sm, grid, t0_ns,
                          cfg.min_rate_for_derivative_hz, True)
    rates["suspension"] = r_
    for i in range(4):
        cols[f"susp_deflection_m_{i + 1}"] = v_[:, i]
        cols[f"susp_deflection_rate_mps_{i + 1}"] = d_[:, i]


def _input_columns(samples: Streams, grid: np.ndarray, rel: Callable, cols: dict, rates: dict) -> None:
    """Inputs (steering, wheel torques): held between samples (linear between close samples), not
    smoothed."""
    for kind, names in (("steer", ["steer_wheel_angle_rad"]), ("wheel_torque", list(WHEEL_TORQUE_FIELDS))):
        t_ns, v = stream(samples, kind, names)
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
    t, v = stream(samples, "gnss_pos", GNSS_POS_FIELDS)
    if len(t) and origin is not None:
        sep = np.where(np.isfinite(v[:, 3]), v[:, 3], 0.0)
        ok = np.isfinite(v[:, 0] + v[:, 1] + v[:, 2]) & ~(v[:, 6] <= 0)
        enu = np.array([origin.to_enu(a, b, h) for a, b, h in zip(v[ok, 0], v[ok, 1], v[ok, 2] + sep[ok])])
        enu = enu.reshape(-1, 3)
        out["pos"] = {"t_s": rel(t[ok]), "e_m": enu[:, 0], "n_m": enu[:, 1], "u_m": enu[:, 2],
                      "sigma_h_m": v[ok, 4], "sigma_v_m": v[ok, 5]}
    t, v = stream(samples, "gnss_att", GNSS_ATT_FIELDS)
    if len(t):
        out["att"] = {"t_s": rel(t), "roll_rad": v[:, 0], "pitch_rad": v[:, 1], "yaw_rad": v[:, 2],
                      "roll_sigma_rad": v[:, 3], "pitch_sigma_rad": v[:, 4], "yaw_sigma_rad": v[:, 5]}
    t, v = stream(samples, "gnss_vel", GNSS_VEL_FIELDS)
    if len(t):
        out["vel"] = {"t_s": rel(t), "speed_mps": v[:, 0], "course_rad": v[:, 1]}
    return out


def load_drive(path: str | os.PathLike, vehicle: Vehicle, *, dbc=None, signalmap=None,
               config: DatasetConfig | None = None, imu_effects: Sequence[MeasurementEffect] = (),
               samples: Iterable[Sample] | None = None, gyro=None) -> DriveTable:
    """Recording (``/raw/`` only) + model vehicle -> :class:`DriveTable`.

    ``samples``: already decoded samples (skips decoding); ``imu_effects``: measurement effects
    taken out of the IMU readings before the estimator runs (module docstring). The samples
    stream through the estimator while the table's signals are collected as packed arrays
    (:class:`Streams`); with ``imu_effects`` the recording is decoded twice (the gyro track
    first, then the corrected samples), so no list of samples is ever held; ``gyro``: that
    track (``imu_effects.gyro_track``) already made from the same recording, arguments and
    sensor set (:func:`reestimator`), to decode once."""
    if getattr(vehicle, "kind", None) != "model":
        raise DatasetError("the workbench reads only a model vehicle file (kind = \"model\")")
    cfg = config or DatasetConfig()

    def source() -> Iterable[Sample]:
        return iter_raw(path, dbc=dbc, signalmap=signalmap) if samples is None else samples

    if samples is not None and imu_effects and iter(samples) is samples:
        samples = list(samples)  # a one-shot iterator cannot be read twice
    feed, system, make_nodes, desc = _configured(source(), path, vehicle, cfg)
    if imu_effects:
        track = gyro
        if track is None:  # one pass for the track, then the samples again
            track = _gyro_track(feed, desc, make_nodes, cfg)
            feed = source()
    km = KindMap.of(desc)
    if imu_effects:
        feed = imu_corrected(renamed(feed, km, make_nodes()), imu_effects, track)
    else:
        feed = renamed(feed, km, make_nodes())
    streams = Streams()
    run = run_system(streams.tap(feed), vehicle, system, cfg.period_s)
    table = build_table(streams, run, vehicle, cfg)
    table.sensors = dict(desc, **table.sensors, **({"not_used": dict(km.dropped)} if km.dropped else {}))
    return table


def reestimator(path: str | os.PathLike, vehicle: Vehicle, *, dbc=None, signalmap=None,
                config: DatasetConfig | None = None) -> Callable[[Sequence[MeasurementEffect]], DriveTable]:
    """``effects -> load_drive(path, vehicle, ..., imu_effects=effects)`` for re-estimating one
    drive with several sets of sensor effects (``vdps diagnose --add``): the gyro track does not
    depend on the effects, so it is made on the first call and reused, and each later call
    decodes the recording once instead of twice (the same tables; a drive without a gyro has no
    track, and each call then makes its own)."""
    cfg = config or DatasetConfig()
    kept: list = []  # [the track] once made

    def run(effects: Sequence[MeasurementEffect]) -> DriveTable:
        if not effects:
            return load_drive(path, vehicle, dbc=dbc, signalmap=signalmap, config=cfg)
        if not kept:
            feed, _, make_nodes, desc = _configured(iter_raw(path, dbc=dbc, signalmap=signalmap), path, vehicle, cfg)
            kept.append(_gyro_track(feed, desc, make_nodes, cfg))
        return load_drive(path, vehicle, dbc=dbc, signalmap=signalmap, config=cfg, imu_effects=effects,
                          gyro=kept[0])
    return run


def _gyro_track(samples: Iterable[Sample], desc: dict, make_nodes, cfg: DatasetConfig):
    """The IMU corrections' gyro track (``imu_effects.gyro_track``) of the samples as the estimator
    sees them (the kind map of the sensor-set description ``desc``, fresh calibration nodes): one
    definition for :func:`load_drive` and the track :func:`reestimator` keeps, which must be the
    same."""
    return gyro_track(renamed(samples, KindMap.of(desc), make_nodes()), cfg.cutoff_hz)


def _configured(samples: Iterable[Sample], path, vehicle: Vehicle, cfg: DatasetConfig):
    """(the samples from their start, SystemConfig, calibration-node factory, sensor-set
    description with its kind map): the node configured from the first seconds of ``samples``
    (``sample_stats``)."""
    it = iter(samples)
    head, rates, fields = sample_stats(it)
    if not head:
        raise DatasetError(f"{path}: no decodable /raw/ samples")
    system, make_nodes, desc = _system_config(rates, fields, vehicle, cfg)
    return itertools.chain(head, it), system, make_nodes, desc


def _system_config(rates, fields, vehicle: Vehicle, cfg: DatasetConfig):
    """(SystemConfig without predictor, a factory of fresh calibration nodes, sensor-set
    description with its kind map) as ``vdps replay`` configures itself from the first seconds."""
    try:
        system, _, _, desc = system_config(rates, fields, vehicle, cfg.susp_sigma_m, None, cfg.sensorset,
                                                  predict=False, identify=cfg.identify)
    except SystemConfigError as e:
        raise DatasetError(str(e)) from None
    if cfg.pipeline is not None:
        system = SystemConfig.for_profile(rates.get("suspension", 1.0), cfg.susp_sigma_m, pipeline=cfg.pipeline,
                                          predict=False, identify=cfg.identify)

    def make_nodes():
        if cfg.sensorset is None:
            return []
        from vdps_hil.estimation.sensorsets import load_sensorset

        return load_sensorset(cfg.sensorset).calibration_nodes(vehicle)
    return system, make_nodes, desc


def table_from_samples(samples: Iterable[Sample], vehicle: Vehicle, config: DatasetConfig | None = None,
                       imu_effects: Sequence[MeasurementEffect] = ()) -> DriveTable:
    """As :func:`load_drive` from decoded samples (a sequence or an iterator)."""
    return load_drive("<samples>", vehicle, config=config, imu_effects=imu_effects, samples=samples)


def column_names(kind: str) -> Mapping[str, tuple[str, ...]]:
    """Column groups by sensor (for reports)."""
    return {"imu": tuple(f"specific_force_b_mps2_{a}" for a in "xyz") + tuple(f"rate_b_radps_{a}" for a in "xyz"),
            "wheel": tuple(f"wheel_speed_radps_{i}" for i in range(1, 5)),
            "suspension": tuple(f"susp_deflection_m_{i}" for i in range(1, 5))}[kind]
