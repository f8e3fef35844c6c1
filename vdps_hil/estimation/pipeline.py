"""Estimator pipeline node: bus samples in, estimates with sigmas and innovations out.

``EstimatorPipeline(model_vehicle, config).handle(sample) -> list[Estimate | Innovation]`` is a
pure node (no threads, devices or clocks; time comes only from ``sample.t_ns``). It consumes
catalogue fields (``vdps_hil.bus.samples``) of the kinds

==============  ==========================================================================
kind            use
==============  ==========================================================================
imu             specific force / angular rate -> mean input of the next predict (one predict
                per ``predict_period_s``); gyro -> alpha-beta (rates, angular accelerations).
                ESC cluster (``SensorSet.imu == "esc3"``): w_x = w_y := 0, f_z := g.
gnss_pos        lat/lon/alt (+ geoid separation) -> ENU (origin: given, or the first valid
                fix) -> ``gnss_pos`` update (antenna lever arm from the model file)
gnss_att        roll/pitch/yaw -> ``gnss_att`` (+ ``y2_gps`` when paper-faithful (b))
gnss_vel        speed/course -> ``gnss_vel`` (course only above ``gnss_course_min_speed_mps``)
suspension      deflections -> eq 5 -> ``y1_sus`` and ``y2_sus`` (plane or rate form, EKF
                correction (c)); alpha-beta (suspension rates)
wheel_speed     alpha-beta (wheel speeds and accelerations); with ``EkfConfig.wheel_speed`` the
                ``wheel_speed`` update (below)
wheel_torque    latest values (for the identifier)
steer           latest steering wheel angle (for the identifier)
==============  ==========================================================================

Sensor mounting from the *model* vehicle file: the IMU rotation (body -> sensor, roll-pitch-yaw
of eq 1, f_b = C_bs^T f_s) and lever arm (f_cg = f_s - w_dot x l - w x (w x l), with w, w_dot
from the alpha-beta filters), and the GNSS antenna lever arm (EKF ``gnss_pos``/``gnss_vel``).

Real-car extensions (``EkfConfig`` switches, all off for the paper's Table-1 set):

* Wheel speed: every ``wheel_speed_period_s`` the wheel samples of the last ``wheel_speed_window_s``
  are averaged per wheel (omega_i r_0, r_0 = ``tire.rolling_radius_m`` of the model file, stamped
  at their mean time). A wheel further than ``wheel_outlier_mps + wheel_outlier_rel |median|``
  from the median of the four is dropped (locked or spinning; counted ``wheel_outliers``); the
  mean of the others is z (sign from the filter's forward speed: wheel speeds carry none), with
  front road-wheel angles d = steering wheel angle / steer ratio. Slip and braking: with
  a_w = r_0 x the mean alpha-beta wheel acceleration of the wheels used, the update is skipped
  when |a_w| > ``wheel_accel_gate_mps2`` (counted ``wheel_accel_skipped``) and otherwise::

      sigma^2 = sigma_0^2 + (c_a a_w)^2 + (|z| |T| / (r_0 C_kappa))^2

  sigma_0 ``wheel_speed_sigma_mps``, c_a ``wheel_accel_sigma_s`` [s], |T| the mean absolute wheel
  torque of the wheels used (when a ``wheel_torque`` source exists) and C_kappa
  ``wheel_long_stiffness_n`` (slip ratio ~ T / (r_0 C_kappa)).
* Non-holonomic constraint: every ``nhc_period_s`` after a predict, z = [0, 0] with::

      sigma_lat^2 = sigma_0^2 + (k_beta |a_y| |v|)^2 + (sigma_x w_z)^2

  sigma_0 ``nhc_sigma_lat_mps``; the rear-axle slip angle grows with the lateral acceleration a_y
  of the mean IMU input (k_beta ``nhc_slip_rad_per_mps2`` [rad/(m/s^2)]); sigma_x
  ``nhc_point_sigma_m`` is the uncertainty of the rear axle's position along x in the model file
  (a point l off it moves sideways by w_z l); sigma_vert ``nhc_sigma_vert_mps``.
* Gyro rates handed to the observation models (lever arms) are bias-corrected with the filter's
  b_g.
* Re-acquisition: after ``reacquire_after_gated`` consecutive gated ``gnss_pos`` updates (0, the
  default: never; the real-car sensor sets use 5)
  position, velocity and yaw are reset to the newest fix (velocity and yaw from the GNSS
  speed/course when fresh and moving, else from the last two fixes), their cross-covariances
  dropped, attitude and biases kept (``MultiRateEKF.reacquire``; counted ``reacquisitions``).

Latency per sensor (``Latencies``): a fixed delay subtracted from ``t_ns`` of that kind (an
adapter that stamps at reception); the EKF applies measurements that are then in its past with
its history buffer (``ekf`` module docstring).

Initialisation: at a GNSS fix once a heading is known (GNSS yaw, or course at speed):
attitude from the GNSS attitude (or roll/pitch from the mean specific force and yaw from the
course), velocity from speed/course or the difference of two fixes, road angles from a recent
suspension sample with eq 4 (road normal n = (C_g^v)^T C_r^v e_3), position = fix - (C_g^v)^T l.
After a NaN reset of the EKF the next fix re-initialises.

Sequencing (``imu_hold_s``, default 50 ms): the filter predicts to a measurement's time with the
mean of the IMU samples it has. A measurement that arrives before the IMU samples up to its time
(live: a CAN frame up to a serial read window ahead of the IMU packets of the same instant) would
make it advance on a stale mean and then count those IMU samples into the next interval. So a
measurement that can advance the filter (GNSS, suspension; wheel speeds when the filter takes
them) whose time is later than the newest IMU sample's is held until an IMU sample at or after
its time arrives, and the held ones go first, in time order -- the order a time-ordered input has
anyway -- or until the newest sample time has moved ``imu_hold_s`` past its arrival (the IMU
stopped; counted ``hold_expired``). Other samples (torques, steering, wheel speeds feeding only
the alpha-beta filters) go on at once. ``finish()`` releases what is held at the end
of the input. Before the first IMU sample nothing is held. Times are compared with the
per-sensor latencies removed.

Replay: every sample handed to ``handle`` is appended to ``input_log``; feeding the same
samples to a fresh pipeline (``EstimatorPipeline.replay``) reproduces the outputs exactly.
The pipeline never reads simulator truth: it accepts only a model vehicle file and ignores
(counts) samples from ``/truth`` sources or of kind ``truth*``.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from vdps_hil.bus.samples import Sample, axis_fields, wheel_fields
from vdps_hil.estimation.alpha_beta import TimedAlphaBetaBank
from vdps_hil.estimation.ekf import EkfConfig, MultiRateEKF, UpdateResult
from vdps_hil.estimation.kinematics import vehicle_angles_eq4
from vdps_hil.estimation.observability import ObservabilityReport, ObservabilityWindow
from vdps_hil.estimation.observations import (ObsKind, ZrRateBuilder, suspension_measurement,
                                              y2_gps_measurement)
from vdps_hil.estimation.states import STATE_NAMES, States
from vdps_hil.geodesy import EnuOrigin
from vdps_hil.model.frames import dcm_gv
from vdps_hil.units import deg2rad

KINDS = ("imu", "gnss_pos", "gnss_att", "gnss_vel", "suspension", "wheel_speed", "wheel_torque", "steer")

_SF = axis_fields("specific_force_mps2")
_AR = axis_fields("angular_rate_radps")
_SUSP = wheel_fields("susp_deflection_m")
_WS = wheel_fields("wheel_speed_radps")
_WT = wheel_fields("wheel_torque_nm")
_WS_INDEX = {n: i for i, n in enumerate(_WS)}
_NAN = math.nan


@dataclass(frozen=True)
class Bandwidths:
    """Alpha-beta bandwidth per signal group [Hz] (critically damped gains, ``alpha_beta``)."""

    angular_rate_hz: float = 5.0
    wheel_speed_hz: float = 5.0
    susp_deflection_hz: float = 2.0
    max_gap_s: float = 2.0  # a longer gap between samples restarts a filter


@dataclass(frozen=True)
class Latencies:
    """Fixed delay [s] between measurement and the sample's t_ns, per sensor (0: stamped at
    measurement time)."""

    imu_s: float = 0.0
    gnss_s: float = 0.0
    suspension_s: float = 0.0
    wheel_s: float = 0.0
    gnss_vel_s: float | None = None  # GNSS speed/course when it differs from the position (None: gnss_s)

    @property
    def gnss_vel_effective_s(self) -> float:
        return self.gnss_s if self.gnss_vel_s is None else self.gnss_vel_s


@dataclass(frozen=True)
class PipelineConfig:
    """Pipeline settings; measurement noise defaults are Table 1 (used when a sample carries no
    sigma of its own)."""

    ekf: EkfConfig = field(default_factory=EkfConfig)
    predict_period_s: float = 0.01
    emit_estimates: bool = True  # Estimates as outputs
    output_period_s: float = 0.0  # at most one Estimate per period (0: after every predict step)
    gnss_pos_sigma_h_m: float = 1.0
    gnss_pos_sigma_v_m: float = 3.0
    gnss_att_sigma_rad: float = float(deg2rad(0.4))
    gnss_speed_sigma_mps: float = 0.1
    gnss_course_min_speed_mps: float = 3.0
    susp_sigma_m: float = 0.001
    heave_rate_sigma_mps: float = 0.05  # y2_sus rate form (observations.ZrRateBuilder)
    y2_gps_floor_rad: float | None = None  # faithful (b) only: isotropic R floor (None: the angle sigma)
    bandwidths: Bandwidths = field(default_factory=Bandwidths)
    latencies: Latencies = field(default_factory=Latencies)
    init_max_age_s: float = 1.0  # newest data usable for initialisation
    init_road_sigma_rad: float = 0.05
    init_level_sigma_rad: float = 0.05  # roll/pitch from the mean specific force
    init_course_sigma_rad: float = 0.1  # yaw from course over ground
    init_velocity_sigma_mps: float = 30.0  # no velocity information at all
    observability_window_s: float | None = 10.0
    # real-car extensions (module docstring; used only when the EkfConfig switches are on)
    wheel_speed_sigma_mps: float = 0.05
    wheel_speed_period_s: float = 0.1
    wheel_speed_window_s: float = 0.05
    wheel_outlier_mps: float = 0.3
    wheel_outlier_rel: float = 0.03
    wheel_accel_gate_mps2: float = 4.0
    wheel_accel_sigma_s: float = 0.05
    wheel_long_stiffness_n: float = 1.0e5
    nhc_period_s: float = 0.1
    nhc_sigma_lat_mps: float = 0.1
    nhc_sigma_vert_mps: float = 0.1
    nhc_slip_rad_per_mps2: float = 0.005
    nhc_point_sigma_m: float = 0.3
    reacquire_after_gated: int = 0  # off for the paper's set (its 10 dB SNR runs gate 5 fixes in a row)
    reacquire_velocity_sigma_mps: float = 1.0
    imu_hold_s: float = 0.05  # sequencing (module docstring): longest hold of a measurement; 0: off

    def __post_init__(self):
        for name in ("predict_period_s", "gnss_pos_sigma_h_m", "gnss_pos_sigma_v_m", "gnss_att_sigma_rad",
                     "gnss_speed_sigma_mps", "susp_sigma_m", "heave_rate_sigma_mps", "init_max_age_s",
                     "wheel_speed_sigma_mps", "wheel_speed_period_s", "wheel_speed_window_s", "wheel_outlier_mps",
                     "wheel_accel_gate_mps2", "wheel_long_stiffness_n", "nhc_period_s", "nhc_sigma_lat_mps",
                     "nhc_sigma_vert_mps", "reacquire_velocity_sigma_mps"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"PipelineConfig.{name} must be a positive finite number, got {v!r}")
        for name in ("wheel_outlier_rel", "wheel_accel_sigma_s", "nhc_slip_rad_per_mps2", "nhc_point_sigma_m",
                     "imu_hold_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"PipelineConfig.{name} must be a non-negative finite number, got {v!r}")
        if not (isinstance(self.reacquire_after_gated, int) and self.reacquire_after_gated >= 0):
            raise ValueError(f"PipelineConfig.reacquire_after_gated must be an integer >= 0, "
                             f"got {self.reacquire_after_gated!r}")


@dataclass(frozen=True)
class Estimate:
    """The 12 states of eq 7 (``States`` order, ``STATE_NAMES``) with 1-sigma, and the
    road-relative vehicle angles (phi_v, theta_v, psi_v) of eq 4 with their sigmas."""

    t_ns: int
    x: tuple[float, ...]
    sigma: tuple[float, ...]
    vehicle_angles_rad: tuple[float, float, float]
    vehicle_angles_sigma_rad: tuple[float, float, float]

    def get(self, state) -> float:
        return self.x[_state_index(state)]

    def sigma_of(self, state) -> float:
        return self.sigma[_state_index(state)]

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "state": dict(zip(STATE_NAMES, self.x)),
                "sigma": dict(zip(STATE_NAMES, self.sigma)),
                "vehicle_angles_rad": dict(zip(("phi_v", "theta_v", "psi_v"), self.vehicle_angles_rad)),
                "vehicle_angles_sigma_rad": dict(zip(("phi_v", "theta_v", "psi_v"), self.vehicle_angles_sigma_rad))}


@dataclass(frozen=True)
class Innovation:
    """One EKF update: innovation per used row, sqrt(diag S), NIS and the gate."""

    t_ns: int
    kind: str
    status: str
    innovation: tuple[float, ...]
    innovation_sigma: tuple[float, ...]
    nis: float
    dof: int
    gate: float
    delayed: bool

    @classmethod
    def from_result(cls, r: UpdateResult) -> "Innovation":
        return cls(r.t_ns, r.kind.value, r.status, r.innovation, r.innovation_sigma, r.nis, r.dof, r.gate, r.delayed)

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "kind": self.kind, "status": self.status, "innovation": list(self.innovation),
                "innovation_sigma": list(self.innovation_sigma), "nis": self.nis, "dof": self.dof,
                "gate": self.gate, "delayed": self.delayed}


@dataclass(frozen=True)
class FilteredSignals:
    """Latest alpha-beta outputs (eq 12) and pass-through inputs for the identifier; NaN where
    no sample has arrived. ``lags_s``: derivative lag per group at its last sampling period."""

    t_ns: int
    angular_rate_radps: tuple[float, float, float]
    angular_accel_radps2: tuple[float, float, float]
    wheel_speed_radps: tuple[float, float, float, float]
    wheel_accel_radps2: tuple[float, float, float, float]
    susp_deflection_m: tuple[float, float, float, float]
    susp_rate_mps: tuple[float, float, float, float]
    wheel_torque_nm: tuple[float, float, float, float]
    steer_wheel_angle_rad: float
    lags_s: dict


def _state_index(state) -> int:
    if isinstance(state, str):
        return STATE_NAMES.index(state)
    return int(States(state))


class EstimatorPipeline:
    """Sensor samples -> multi-rate EKF + alpha-beta filters (module docstring)."""

    def __init__(self, model_vehicle, config: PipelineConfig | None = None, origin: EnuOrigin | None = None):
        if getattr(model_vehicle, "kind", None) != "model":
            raise ValueError("EstimatorPipeline reads only a model vehicle file (kind = \"model\"), never truth")
        self.vehicle = model_vehicle
        self.config = config or PipelineConfig()
        cfg = self.config
        self.ekf = MultiRateEKF.from_vehicle(model_vehicle, cfg.ekf)
        self._origin = origin
        self._esc3 = cfg.ekf.sensors.imu == "esc3"
        self._g = cfg.ekf.gravity_mps2
        self._period_ns = int(round(cfg.predict_period_s * 1e9))
        self._out_ns = int(round(cfg.output_period_s * 1e9))
        self._last_out = -(1 << 62)
        lat = cfg.latencies
        self._lat = {"imu": int(round(lat.imu_s * 1e9)), "gnss": int(round(lat.gnss_s * 1e9)),
                     "gnss_vel": int(round(lat.gnss_vel_effective_s * 1e9)),
                     "suspension": int(round(lat.suspension_s * 1e9)), "wheel": int(round(lat.wheel_s * 1e9))}
        m = model_vehicle.mounting
        rot = np.asarray(m.imu_rotation_rpy_rad, dtype=float)
        # sensor -> body as plain floats (row-major 3 x 3)
        self._imu_rot = None if not rot.any() else tuple(
            tuple(float(v) for v in row) for row in dcm_gv(rot[0], rot[1], rot[2]).T)
        arm = np.asarray(m.imu_lever_arm_m, dtype=float)
        self._imu_arm = None if not arm.any() else tuple(float(v) for v in arm)
        # real-car extensions
        kinds = self.ekf.kinds
        self._use_ws = ObsKind.WHEEL_SPEED in kinds
        self._use_nhc = ObsKind.NHC in kinds
        self._r0 = float(model_vehicle.tire.rolling_radius_m)
        sr = float(getattr(model_vehicle.geometry, "steer_ratio", 0.0) or 0.0)
        self._steer_ratio = sr if sr > 0 and math.isfinite(sr) else 0.0
        self._ws_recent: deque[tuple[int, list[float]]] = deque()
        self._ws_period_ns = int(round(cfg.wheel_speed_period_s * 1e9))
        self._ws_window_ns = int(round(cfg.wheel_speed_window_s * 1e9))
        self._ws_last = -(1 << 62)
        self._nhc_period_ns = int(round(cfg.nhc_period_s * 1e9))
        self._nhc_last = -(1 << 62)
        self._f_in = (0.0, 0.0, self._g)
        self._w_in = (0.0, 0.0, 0.0)
        self._gated_run = 0
        self._lever = np.asarray(m.gnss_lever_arm_m, dtype=float)
        bw = cfg.bandwidths
        self._ab_gyro = TimedAlphaBetaBank(3, bw.angular_rate_hz, bw.max_gap_s)
        self._ab_wheel = TimedAlphaBetaBank(4, bw.wheel_speed_hz, bw.max_gap_s)
        self._ab_susp = TimedAlphaBetaBank(4, bw.susp_deflection_hz, bw.max_gap_s)
        self._torque = [_NAN] * 4
        self._steer = _NAN
        self._last_t = 0
        # IMU accumulator for the mean input of the next predict
        self._acc = [0.0] * 6
        self._acc_n = 0
        self._level_f = None  # recent mean specific force (initialisation by levelling)
        # latest aiding data for initialisation / y2_gps
        self._fix = None  # (t, enu, sigma_h, sigma_v)
        self._prev_fix = None
        self._att = None  # (t, roll, pitch, yaw, sigmas)
        self._vel = None  # (t, speed, course)
        self._susp = None  # (t, SuspensionMeasurement)
        self._zr_rate = ZrRateBuilder(heave_rate_sigma_mps=cfg.heave_rate_sigma_mps)
        self._log: list[Sample] = []
        self._counts = {"messages": 0, "ignored": 0, "truth_ignored": 0, "invalid": 0, "estimates": 0,
                        "wheel_outliers": 0, "wheel_accel_skipped": 0, "wheel_too_few": 0, "reacquisitions": 0}
        self._rejected = dict.fromkeys(KINDS, 0)
        self._per_kind = dict.fromkeys(KINDS, 0)
        self._obs_reports: list[tuple[int, int, ObservabilityReport]] = []
        self._obs = None
        self._obs_t0 = None
        self._obs_ns = None
        if cfg.observability_window_s:
            self._obs = ObservabilityWindow.for_layout(self.ekf.layout).attach(self.ekf)
            self._obs_ns = int(round(cfg.observability_window_s * 1e9))
        # sequencing: measurements later than the newest IMU sample wait for it (module docstring)
        self._hold_ns = int(round(cfg.imu_hold_s * 1e9))
        self._kind_lat = {"gnss_pos": self._lat["gnss"], "gnss_att": self._lat["gnss"],
                          "gnss_vel": self._lat["gnss_vel"], "suspension": self._lat["suspension"]}
        if self._use_ws:  # only then do wheel speeds update (and advance) the filter
            self._kind_lat["wheel_speed"] = self._lat["wheel"]
        self._imu_mark: int | None = None  # newest IMU sample time (latency removed)
        self._newest = -(1 << 62)  # newest sample time seen
        self._held: list = []  # heap of (t, seq, arrival time, sample, handler)
        self._held_seq = 0
        self._counts.update(held=0, hold_expired=0)
        self._handlers = {"imu": self._on_imu, "gnss_pos": self._on_gnss_pos, "gnss_att": self._on_gnss_att,
                          "gnss_vel": self._on_gnss_vel, "suspension": self._on_suspension,
                          "wheel_speed": self._on_wheel_speed, "wheel_torque": self._on_wheel_torque,
                          "steer": self._on_steer}

    # ---------------------------------------------------------------- public
    def handle(self, sample: Sample) -> list:
        """Consume one sample; returns the outputs it caused (Estimate / Innovation)."""
        self._log.append(sample)
        self._counts["messages"] += 1
        kind = sample.kind
        fn = self._handlers.get(kind)
        if fn is None or sample.source[:6] == "/truth":
            if kind.startswith("truth") or sample.source.startswith("/truth"):
                self._counts["truth_ignored"] += 1
            else:
                self._counts["ignored"] += 1
            return []
        self._per_kind[kind] += 1
        if not sample.valid:
            self._counts["invalid"] += 1
            self._rejected[kind] += 1
            return []
        out: list = []
        if self._hold_ns:
            t_s = sample.t_ns
            if t_s > self._newest:
                self._newest = t_s
            if self._held or kind in self._kind_lat:
                self._sequence(sample, kind, fn, out)
                return out
            if kind == "imu":  # nothing held: only the mark moves
                t = t_s - self._lat["imu"]
                if self._imu_mark is None or t > self._imu_mark:
                    self._imu_mark = t
        fn(sample, out)
        return out

    def _sequence(self, sample: Sample, kind: str, fn, out: list) -> None:
        """Hand ``sample`` on now or hold it until the IMU has reached its time (module docstring,
        "Sequencing")."""
        held = self._held
        t_s = sample.t_ns
        if kind == "imu":
            t = t_s - self._lat["imu"]
            while held and held[0][0] <= t:
                h = heapq.heappop(held)
                h[4](h[3], out)
            if self._imu_mark is None or t > self._imu_mark:
                self._imu_mark = t
            fn(sample, out)
        else:
            lat = self._kind_lat.get(kind)
            if lat is None or self._imu_mark is None or t_s - lat <= self._imu_mark:
                fn(sample, out)
            else:
                self._held_seq += 1
                self._counts["held"] += 1
                heapq.heappush(held, (t_s - lat, self._held_seq, self._newest, sample, fn))
        while held and self._newest - held[0][2] >= self._hold_ns:  # the IMU has stopped
            h = heapq.heappop(held)
            self._counts["hold_expired"] += 1
            h[4](h[3], out)

    def finish(self) -> list:
        """End of the input: the measurements still held (in time order); their outputs."""
        out: list = []
        while self._held:
            h = heapq.heappop(self._held)
            h[4](h[3], out)
        return out

    @classmethod
    def replay(cls, model_vehicle, config: PipelineConfig | None, samples, origin: EnuOrigin | None = None):
        """A fresh pipeline fed ``samples`` in order: (pipeline, all outputs)."""
        p = cls(model_vehicle, config, origin)
        out: list = []
        for s in samples:
            out.extend(p.handle(s))
        return p, out

    @property
    def input_log(self) -> tuple[Sample, ...]:
        """Every sample handed to ``handle``, in order (feed it to ``replay``)."""
        return tuple(self._log)

    @property
    def origin(self) -> EnuOrigin | None:
        return self._origin

    @property
    def counters(self) -> dict:
        d = dict(self._counts)
        d["holding"] = len(self._held)  # held now (sequencing)
        d["per_kind"] = dict(self._per_kind)
        d["ekf"] = self.ekf.counters
        return d

    def rejected(self) -> dict[str, int]:
        """Rejected samples per sensor kind (bad fields, no fix, invalid) plus the EKF's
        gated/NaN/too-old updates per measurement kind."""
        d = {k: v for k, v in self._rejected.items()}
        for k, v in self.ekf.rejected().items():
            d[f"ekf.{k}"] = v
        return d

    @property
    def observability_reports(self) -> tuple[tuple[int, int, ObservabilityReport], ...]:
        """(t_start_ns, t_end_ns, report) per completed window."""
        return tuple(self._obs_reports)

    def observability_now(self) -> ObservabilityReport | None:
        """Report of the window in progress."""
        return self._obs.report() if self._obs is not None else None

    def augmented_state(self) -> dict[str, tuple[float, float]]:
        """{name: (value, sigma)} of the EKF's bias and wheel-scale states (empty when the
        configuration carries none or before initialisation)."""
        return self.ekf.augmented_state()

    def estimate(self) -> Estimate | None:
        """The current estimate (None before initialisation)."""
        if not self.ekf.initialized:
            return None
        xf, e, ang, jac = self.ekf.layout.expand_with_vehicle_angles(self.ekf.x)
        pf = e @ self.ekf.P @ e.T
        sig = np.sqrt(np.maximum(pf.diagonal(), 0.0))
        pa = jac @ pf[6:11, 6:11] @ jac.T
        sa = np.sqrt(np.maximum(pa.diagonal(), 0.0))
        return Estimate(self.ekf.t_ns, tuple(xf.tolist()), tuple(sig.tolist()), tuple(ang.tolist()), tuple(sa.tolist()))

    def filtered(self) -> FilteredSignals:
        g, w, s = self._ab_gyro, self._ab_wheel, self._ab_susp
        return FilteredSignals(
            self._last_t, tuple(g.x), tuple(g.v), tuple(w.x), tuple(w.v), tuple(s.x), tuple(s.v),
            tuple(self._torque), self._steer,
            {"angular_accel": g.lag_s, "wheel_accel": w.lag_s, "susp_rate": s.lag_s})

    # ---------------------------------------------------------------- IMU / predict
    def _on_imu(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["imu"]
        fd = s.fields
        g = fd.get
        if self._esc3:
            f = [g(_SF[0], _NAN), g(_SF[1], _NAN), self._g]
            w = [0.0, 0.0, g(_AR[2], _NAN)]
        else:
            f = [g(_SF[0], _NAN), g(_SF[1], _NAN), g(_SF[2], _NAN)]
            w = [g(_AR[0], _NAN), g(_AR[1], _NAN), g(_AR[2], _NAN)]
        if not math.isfinite(f[0] + f[1] + f[2] + w[0] + w[1] + w[2]):
            self._rejected["imu"] += 1
            return
        rot = self._imu_rot
        if rot is not None:
            r0, r1, r2 = rot
            f = [r0[0] * f[0] + r0[1] * f[1] + r0[2] * f[2], r1[0] * f[0] + r1[1] * f[1] + r1[2] * f[2],
                 r2[0] * f[0] + r2[1] * f[1] + r2[2] * f[2]]
            w = [r0[0] * w[0] + r0[1] * w[1] + r0[2] * w[2], r1[0] * w[0] + r1[1] * w[1] + r1[2] * w[2],
                 r2[0] * w[0] + r2[1] * w[1] + r2[2] * w[2]]
        self._ab_gyro.update(t, (_NAN, _NAN, w[2]) if self._esc3 else w)
        if self._imu_arm is not None:
            f = self._lever_arm_correction(f)
        self._last_t = t
        ekf = self.ekf
        if not ekf.initialized:  # levelling: exponential mean of the specific force (tau ~ 100 samples)
            lf = self._level_f
            self._level_f = tuple(f) if lf is None else tuple(o + 0.01 * (v - o) for o, v in zip(lf, f))
            return
        a = self._acc
        a[0] += f[0]
        a[1] += f[1]
        a[2] += f[2]
        a[3] += w[0]
        a[4] += w[1]
        a[5] += w[2]
        self._acc_n += 1
        if t - ekf.t_ns >= self._period_ns:
            self._flush(t, out)

    def _lever_arm_correction(self, f):
        """f_cg = f_s - w_dot x l - w x (w x l) in plain floats (hot path: once per IMU sample);
        axes the IMU lacks (NaN in the alpha-beta bank, an ESC cluster's x/y) count as 0."""
        g = self._ab_gyro
        wx, wy, wz = (v if v - v == 0.0 else 0.0 for v in g.x)
        ax, ay, az = (v if v - v == 0.0 else 0.0 for v in g.v)
        lx, ly, lz = self._imu_arm
        ux, uy, uz = wy * lz - wz * ly, wz * lx - wx * lz, wx * ly - wy * lx  # w x l
        return [f[0] - (ay * lz - az * ly) - (wy * uz - wz * uy),
                f[1] - (az * lx - ax * lz) - (wz * ux - wx * uz),
                f[2] - (ax * ly - ay * lx) - (wx * uy - wy * ux)]

    def _set_mean_input(self) -> None:
        n = self._acc_n
        if n:
            a = self._acc
            self._f_in = (a[0] / n, a[1] / n, a[2] / n)
            self._w_in = (a[3] / n, a[4] / n, a[5] / n)
            self.ekf.set_input(self._f_in, self._w_in)
            self._acc = [0.0] * 6
            self._acc_n = 0

    def _rate_corrected(self) -> tuple[float, float, float]:
        """The last mean gyro input minus the filter's gyro bias [rad/s] (body axes)."""
        b = self.ekf.bias()[0]
        w = self._w_in
        return (w[0] - b[0], w[1] - b[1], w[2] - b[2])

    def _flush(self, t: int, out: list) -> None:
        """Predict to t with the mean of the accumulated IMU samples; emit an estimate."""
        self._set_mean_input()
        was = self.ekf.initialized
        self.ekf.predict_to(t)
        if not self.ekf.initialized:
            if was:
                self._after_reset()
            return
        self._observability_tick()
        if self._use_nhc and t - self._nhc_last >= self._nhc_period_ns:
            self._nhc_update(t, out)
            if not self.ekf.initialized:
                return
        if self.config.emit_estimates and t - self._last_out >= self._out_ns:
            self._last_out = t
            out.append(self.estimate())
            self._counts["estimates"] += 1

    def _predict_for(self, t: int) -> bool:
        """Bring the filter to a measurement at t (if it is not in the filter's past)."""
        ekf = self.ekf
        if t > ekf.t_ns:
            self._set_mean_input()
            ekf.predict_to(t)
            if not ekf.initialized:
                self._after_reset()
                return False
        return True

    def _update(self, kind: ObsKind, z, R, t: int, out: list, aux=None) -> UpdateResult:
        was = self.ekf.initialized
        res = self.ekf.update(kind, z, R, t, aux)
        out.append(Innovation.from_result(res))
        if was and not self.ekf.initialized:
            self._after_reset()
        return res

    def _nhc_update(self, t: int, out: list) -> None:
        """Non-holonomic constraint at the filter time (module docstring)."""
        cfg = self.config
        self._nhc_last = t
        x = self.ekf.x
        speed = math.sqrt(float(x[3]) ** 2 + float(x[4]) ** 2 + float(x[5]) ** 2)
        ay = self._f_in[1]
        w = self._rate_corrected()
        s_lat = math.sqrt(cfg.nhc_sigma_lat_mps ** 2 + (cfg.nhc_slip_rad_per_mps2 * abs(ay) * speed) ** 2
                          + (cfg.nhc_point_sigma_m * w[2]) ** 2)
        R = np.diag([s_lat * s_lat, cfg.nhc_sigma_vert_mps ** 2])
        self._update(ObsKind.NHC, np.zeros(2), R, t, out, aux=w)

    def _after_reset(self) -> None:
        self._acc = [0.0] * 6
        self._acc_n = 0
        self._zr_rate.reset()
        if self._obs is not None:
            self._obs.restart()
            self._obs_t0 = None

    def _observability_tick(self) -> None:
        if self._obs is None:
            return
        t = self.ekf.t_ns
        if self._obs_t0 is None:
            self._obs_t0 = t
            self._obs.restart()
        elif t - self._obs_t0 >= self._obs_ns:
            self._obs_reports.append((self._obs_t0, t, self._obs.report()))
            self._obs_t0 = t
            self._obs.restart()

    # ---------------------------------------------------------------- GNSS
    def _on_gnss_pos(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["gnss"]
        g = s.fields.get
        lat, lon, alt = g("gnss_lat_deg", _NAN), g("gnss_lon_deg", _NAN), g("gnss_alt_m", _NAN)
        sep = g("gnss_geoid_sep_m", 0.0)
        q = g("gnss_fix_quality", 1.0)
        if not math.isfinite(sep):
            sep = 0.0
        if not (math.isfinite(lat + lon + alt) and abs(lat) <= 90.0 and abs(lon) <= 180.0) or not (q > 0):
            self._rejected["gnss_pos"] += 1
            return
        h = alt + sep
        if self._origin is None:
            self._origin = EnuOrigin(lat, lon, h)
        enu = self._origin.to_enu(lat, lon, h)
        sh = g("gnss_pos_sigma_h_m", self.config.gnss_pos_sigma_h_m)
        sv = g("gnss_pos_sigma_v_m", self.config.gnss_pos_sigma_v_m)
        if not (sh > 0 and math.isfinite(sh)):
            sh = self.config.gnss_pos_sigma_h_m
        if not (sv > 0 and math.isfinite(sv)):
            sv = self.config.gnss_pos_sigma_v_m
        self._prev_fix, self._fix = self._fix, (t, enu, sh, sv)
        if not self.ekf.initialized:
            self._try_initialize(t, out)
            return
        if self._predict_for(t):
            res = self._update(ObsKind.GNSS_POS, enu, np.diag([sh * sh, sh * sh, sv * sv]), t, out)
            if res.status == "accepted":
                self._gated_run = 0
            elif res.status == "gated":
                self._gated_run += 1
                n = self.config.reacquire_after_gated
                if n and self._gated_run >= n and self.ekf.initialized:
                    self._reacquire(t, enu, sh, sv)

    def _reacquire(self, t: int, enu, sh: float, sv: float) -> None:
        """Re-acquisition after persistent gating (module docstring)."""
        cfg = self.config
        ekf = self.ekf
        self._gated_run = 0
        t_now = max(t, ekf.t_ns)
        xf, _ = ekf.full_state()
        yaw, s_yaw = float(xf[States.PSI_G]), None
        vel, s_vel = None, cfg.init_velocity_sigma_mps
        max_age = int(cfg.init_max_age_s * 1e9)
        if self._fresh(self._vel, t) and self._vel[1] >= cfg.gnss_course_min_speed_mps \
                and math.isfinite(self._vel[2]):
            sp, crs = self._vel[1], self._vel[2]
            vel, s_vel = (sp * math.cos(crs), sp * math.sin(crs)), cfg.reacquire_velocity_sigma_mps
            yaw, s_yaw = crs, cfg.init_course_sigma_rad
        elif self._prev_fix is not None and 0 < t - self._prev_fix[0] <= max_age:
            dt = (t - self._prev_fix[0]) * 1e-9
            vel = ((enu[0] - self._prev_fix[1][0]) / dt, (enu[1] - self._prev_fix[1][1]) / dt)
            s_vel = math.sqrt(2.0) * sh / dt + cfg.reacquire_velocity_sigma_mps
            if math.hypot(*vel) >= cfg.gnss_course_min_speed_mps:
                yaw, s_yaw = math.atan2(vel[1], vel[0]), cfg.init_course_sigma_rad
        if vel is None:
            vel = (float(xf[3]), float(xf[4]))
        c = dcm_gv(float(xf[6]), float(xf[7]), yaw)
        lead = (t_now - t) * 1e-9  # the fix is older than the filter: carry it forward
        p = np.asarray(enu, dtype=float) - c.T @ self._lever
        a = {States.X_G: (p[0] + vel[0] * lead, sh), States.Y_G: (p[1] + vel[1] * lead, sh),
             States.Z_G: (p[2], sv), States.XDOT_G: (vel[0], s_vel), States.YDOT_G: (vel[1], s_vel),
             States.ZDOT_G: (0.0, min(s_vel, 2.0))}
        if s_yaw is not None:
            a[States.PSI_G] = (yaw, s_yaw)
        if ekf.reacquire(t_now, a):
            self._counts["reacquisitions"] += 1
            self._acc = [0.0] * 6
            self._acc_n = 0

    def _on_gnss_att(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["gnss"]
        g = s.fields.get
        cfg = self.config
        z = np.array([g("gnss_roll_rad", _NAN), g("gnss_pitch_rad", _NAN), g("gnss_yaw_rad", _NAN)])
        if not np.isfinite(z).any():
            self._rejected["gnss_att"] += 1
            return
        sig = []
        for name in ("gnss_roll_sigma_rad", "gnss_pitch_sigma_rad", "gnss_yaw_sigma_rad"):
            v = g(name, cfg.gnss_att_sigma_rad)
            sig.append(v if (v > 0 and math.isfinite(v)) else cfg.gnss_att_sigma_rad)
        self._att = (t, z, sig)
        if not self.ekf.initialized:
            self._try_initialize_from_pending(out)
            return
        if not self._predict_for(t):
            return
        self._update(ObsKind.GNSS_ATT, z, np.diag(np.square(sig)), t, out)
        if ObsKind.Y2_GPS in self.ekf.kinds and math.isfinite(z[1] + z[2]) and self.ekf.initialized:
            zz, rr = y2_gps_measurement(z[1], z[2], sig[1], sig[2], self.config.y2_gps_floor_rad)
            self._update(ObsKind.Y2_GPS, zz, rr, t, out)  # theta_v from eq 4 of the state

    def _on_gnss_vel(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["gnss_vel"]
        g = s.fields.get
        cfg = self.config
        speed, course = g("gnss_speed_mps", _NAN), g("gnss_course_rad", _NAN)
        if not (math.isfinite(speed) and speed >= 0.0):
            self._rejected["gnss_vel"] += 1
            return
        self._vel = (t, speed, course)
        if not self.ekf.initialized:
            self._try_initialize_from_pending(out)
            return
        ss = cfg.gnss_speed_sigma_mps
        if speed >= cfg.gnss_course_min_speed_mps and math.isfinite(course):
            z = np.array([speed, course])
            R = np.diag([ss * ss, (ss / speed) ** 2])
        else:
            z = np.array([speed, _NAN])
            R = np.diag([ss * ss, 1.0])
        w = list(self._ab_gyro.x)
        aux = w if all(math.isfinite(v) for v in w) else None
        if self._predict_for(t):
            self._update(ObsKind.GNSS_VEL, z, R, t, out, aux=aux)

    # ---------------------------------------------------------------- chassis
    def _on_suspension(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["suspension"]
        g = s.fields.get
        h = [g(n, _NAN) for n in _SUSP]
        if not math.isfinite(sum(h)):
            self._rejected["suspension"] += 1
            return
        self._ab_susp.update(t, h)
        geo = self.vehicle.geometry
        sm = suspension_measurement(h, geo.l_f_m, geo.l_r_m, geo.track_half_front_m, geo.track_half_rear_m,
                                    self.config.susp_sigma_m)
        self._susp = (t, sm)
        ekf = self.ekf
        if not ekf.initialized or not ekf.kinds & {ObsKind.Y1_SUS, ObsKind.Y2_SUS_PLANE, ObsKind.Y2_SUS_RATE}:
            return
        if not self._predict_for(t):
            return
        if ObsKind.Y1_SUS in ekf.kinds:
            self._update(ObsKind.Y1_SUS, sm.y1, sm.r_y1, t, out)
        if ObsKind.Y2_SUS_PLANE in ekf.kinds and ekf.initialized:
            self._update(ObsKind.Y2_SUS_PLANE, np.array([sm.z_r_m]), np.array([[sm.var_z_r_m2]]), t, out)
        if ObsKind.Y2_SUS_RATE in ekf.kinds and ekf.initialized:
            zr = self._zr_rate.push(t, sm.z_r_m, sm.var_z_r_m2)
            if zr is not None:
                self._update(ObsKind.Y2_SUS_RATE, zr[0], zr[1], t, out)

    def _on_wheel_speed(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["wheel"]
        # the wheels this sample carries (a CAN frame carries two of the four): a sample is
        # rejected when it carries none or one of its values is unusable
        idx, vals = [], []
        for name, v in s.fields.items():
            i = _WS_INDEX.get(name)
            if i is not None:
                idx.append(i)
                vals.append(v)
        if not idx or self._ab_wheel.update(t, vals, idx) < len(idx):
            self._rejected["wheel_speed"] += 1
        if not self._use_ws or not self.ekf.initialized:
            return
        w = [_NAN, _NAN, _NAN, _NAN]
        for i, v in zip(idx, vals):
            w[i] = v
        recent = self._ws_recent
        recent.append((t, w))
        while recent and t - recent[0][0] > self._ws_window_ns:
            recent.popleft()
        if t - self._ws_last >= self._ws_period_ns:
            self._ws_last = t
            self._wheel_update(out)

    def _wheel_update(self, out: list) -> None:
        """Wheel-speed update from the recent samples (module docstring: outliers, slip, sign)."""
        cfg = self.config
        r0 = self._r0
        recent = self._ws_recent
        t_m = int(round(sum(tt for tt, _ in recent) / len(recent)))
        v = []
        for i in range(4):
            vals = [w[i] for _, w in recent if w[i] - w[i] == 0.0]
            v.append(sum(vals) / len(vals) * r0 if vals else _NAN)
        avail = [i for i in range(4) if math.isfinite(v[i])]
        if len(avail) < 2:
            self._counts["wheel_too_few"] += 1
            return
        med = float(np.median([v[i] for i in avail]))
        tol = cfg.wheel_outlier_mps + cfg.wheel_outlier_rel * abs(med)
        keep = [i for i in avail if abs(v[i] - med) <= tol]
        self._counts["wheel_outliers"] += len(avail) - len(keep)
        if len(keep) < 2:
            self._counts["wheel_too_few"] += 1
            return
        z = sum(v[i] for i in keep) / len(keep)
        acc = [self._ab_wheel.v[i] for i in keep if self._ab_wheel.v[i] - self._ab_wheel.v[i] == 0.0]
        a_w = (sum(acc) / len(acc) * r0) if acc else 0.0
        if abs(a_w) > cfg.wheel_accel_gate_mps2:
            self._counts["wheel_accel_skipped"] += 1
            return
        torque = [abs(self._torque[i]) for i in keep if math.isfinite(self._torque[i])]
        s_t = abs(z) * (sum(torque) / len(torque)) / (r0 * cfg.wheel_long_stiffness_n) if torque else 0.0
        var = cfg.wheel_speed_sigma_mps ** 2 + (cfg.wheel_accel_sigma_s * a_w) ** 2 + s_t * s_t
        x = self.ekf.x
        c0 = dcm_gv(float(x[6]), float(x[7]), float(x[8]))[0]
        if float(c0[0] * x[3] + c0[1] * x[4] + c0[2] * x[5]) < -0.3:
            z = -z  # reversing: wheel speeds carry no sign
        d = self._steer / self._steer_ratio if (self._steer_ratio and math.isfinite(self._steer)) else 0.0
        weights = [1.0 / len(keep) if i in keep else 0.0 for i in range(4)]
        aux = (self._rate_corrected(), (d, d, 0.0, 0.0), weights)
        if self._predict_for(t_m):
            self._update(ObsKind.WHEEL_SPEED, np.array([z]), np.array([[var]]), t_m, out, aux=aux)

    def _on_wheel_torque(self, s: Sample, out: list) -> None:
        g = s.fields.get
        vals = [g(n, _NAN) for n in _WT]
        if not any(math.isfinite(v) for v in vals):
            self._rejected["wheel_torque"] += 1
            return
        self._torque = [v if math.isfinite(v) else old for v, old in zip(vals, self._torque)]

    def _on_steer(self, s: Sample, out: list) -> None:
        v = s.fields.get("steer_wheel_angle_rad", _NAN)
        if not math.isfinite(v):
            self._rejected["steer"] += 1
            return
        self._steer = v

    # ---------------------------------------------------------------- initialisation
    def _fresh(self, item, t: int) -> bool:
        return item is not None and abs(t - item[0]) <= int(self.config.init_max_age_s * 1e9)

    def _try_initialize_from_pending(self, out: list) -> None:
        if self._fix is not None:
            self._try_initialize(self._fix[0], out)

    def _try_initialize(self, t: int, out: list) -> None:
        """Initialise at the fix of time t when a heading is known (module docstring)."""
        cfg = self.config
        if self._fix is None or self._fix[0] != t:
            return
        _, enu, sh, sv = self._fix
        att_ok = self._fresh(self._att, t)
        roll = pitch = yaw = _NAN
        s_att = [cfg.init_level_sigma_rad, cfg.init_level_sigma_rad, cfg.init_course_sigma_rad]
        if att_ok:
            z, sig = self._att[1], self._att[2]
            roll, pitch, yaw = (float(v) for v in z)
            s_att = [2.0 * v for v in sig]
        vel_ok = self._fresh(self._vel, t)
        if not math.isfinite(yaw) and vel_ok and self._vel[1] >= cfg.gnss_course_min_speed_mps \
                and math.isfinite(self._vel[2]):
            yaw = self._vel[2]
            s_att[2] = cfg.init_course_sigma_rad
        if not math.isfinite(yaw):
            return
        if not (math.isfinite(roll) and math.isfinite(pitch)):
            lf = self._level_f
            if lf is None:
                lf = (0.0, 0.0, self._g)
            fn = math.sqrt(lf[0] ** 2 + lf[1] ** 2 + lf[2] ** 2) or 1.0
            if not math.isfinite(pitch):
                pitch = math.asin(max(-1.0, min(1.0, lf[0] / fn)))
                s_att[1] = cfg.init_level_sigma_rad
            if not math.isfinite(roll):
                roll = math.atan2(lf[1], lf[2])
                s_att[0] = cfg.init_level_sigma_rad
        c = dcm_gv(roll, pitch, yaw)
        x = np.zeros(12)
        x[0:3] = enu - c.T @ self._lever
        sig = np.zeros(12)
        sig[0:3] = (sh, sh, sv)
        if vel_ok and self._vel[1] >= cfg.gnss_course_min_speed_mps and math.isfinite(self._vel[2]):
            x[3:5] = (self._vel[1] * math.cos(self._vel[2]), self._vel[1] * math.sin(self._vel[2]))
            sig[3:6] = (1.0, 1.0, 1.0)
        elif self._prev_fix is not None and 0 < t - self._prev_fix[0] <= int(cfg.init_max_age_s * 1e9):
            dt = (t - self._prev_fix[0]) * 1e-9
            x[3:5] = (enu[0:2] - self._prev_fix[1][0:2]) / dt
            sig[3:5] = math.sqrt(2.0) * sh / dt + 1.0
            sig[5] = 2.0
        else:
            sig[3:6] = cfg.init_velocity_sigma_mps
        x[6:9] = (roll, pitch, yaw)
        sig[6:9] = s_att
        sig[9:12] = cfg.init_road_sigma_rad
        if self._fresh(self._susp, t) and self.ekf.layout.road_estimated:
            sm = self._susp[1]
            # road normal in {g}: n = (C_g^v)^T C_r^v e_3, C_r^v e_3 = [s th_v, s ph_v c th_v, c ph_v c th_v]
            col = np.array([math.sin(sm.theta_v_rad), math.sin(sm.phi_v_rad) * math.cos(sm.theta_v_rad),
                            math.cos(sm.phi_v_rad) * math.cos(sm.theta_v_rad)])
            n = c.T @ col
            x[9] = -math.asin(max(-1.0, min(1.0, n[1])))
            x[10] = math.atan2(-n[0], n[2])
            sig[9:11] = 2.0 * max(s_att[0], s_att[1]) if att_ok else cfg.init_road_sigma_rad
        layout = self.ekf.layout
        if layout.psi_v_state:
            x[11] = vehicle_angles_eq4(x[6:11], with_jacobian=False)[2]
        x0 = layout.from_full(x)
        ec = cfg.ekf
        sig_aug = [ec.gyro_bias_sigma_radps] * 3 + [ec.accel_bias_sigma_mps2] * 3 + [ec.wheel_scale_sigma]
        sig = np.concatenate([sig, sig_aug])
        P0 = np.diag(sig[layout.full_index] ** 2)
        self.ekf.initialize(t, x0, P0)
        self._acc = [0.0] * 6
        self._acc_n = 0
        self._zr_rate.reset()
        self._obs_t0 = None
        if self.config.emit_estimates:
            out.append(self.estimate())
            self._counts["estimates"] += 1
