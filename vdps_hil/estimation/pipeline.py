"""Estimator pipeline node: bus samples in, estimates with sigmas and innovations out.

``EstimatorPipeline(model_vehicle, config).handle(sample) -> list[Estimate | Innovation]`` is a
pure node (no threads, devices or clocks; time comes only from ``sample.t_ns``); its settings
are ``pipeline_config.PipelineConfig``, its outputs the types of ``estimates``. It consumes
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
                correction (c)), not while a wheel is off the road (``lift_off``); alpha-beta
wheel_speed     alpha-beta (wheel speeds and accelerations); with ``EkfConfig.wheel_speed`` the
                ``wheel_speed`` update (below)
wheel_torque    latest values (for the identifier)
steer           latest steering wheel angle (for the identifier)
==============  ==========================================================================

Sensor mounting from the *model* vehicle file: the IMU rotation and lever arm (``imu_input``)
and the GNSS antenna lever arm (EKF ``gnss_pos``/``gnss_vel``).

Real-car extensions (``EkfConfig`` switches, stated in ``ekf_config``; all off for Table 1): the
``wheel_speed`` update (``wheel_speed``), the non-holonomic constraint every ``nhc_period_s``, and
re-acquisition at the newest fix after ``reacquire_after_gated`` gated ``gnss_pos`` updates.

Fault tolerance (``imu_monitor``, ``aiding_monitor``): IMU samples failing the rate, continuity,
spike or saturation checks are rejected; a predict over a span without accepted samples runs on
the outage input and noise (the covariance grows with the outage); a run of gated aiding
updates inflates the states they observe and re-applies the fix; ``aiding_monitor.health``
says when the estimate is not fit to warn on; after an outage the updates are not iterated while
the IMU settles (``imu_monitor``); a wheel off the road stops the suspension updates (``lift_off``). Latencies (``Latencies``): a fixed delay per sensor kind, late
measurements through the EKF history. Initialisation at a GNSS fix once a heading is known
(``initialisation.initial_state``), again after a NaN reset. Sequencing (``imu_hold_s``, 50 ms):
a measurement later than the newest IMU sample waits for it (``sequencing``); ``finish()``
releases what is held at the end of the input.

Replay: every sample handed to ``handle`` is logged (``input_log``); a fresh pipeline fed the
same samples (``replay``) reproduces the outputs exactly. Never reads simulator truth: a model
vehicle file only; ``/truth`` sources and ``truth*`` kinds are ignored and counted.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.aiding_monitor import AidingMonitor
from vdps_hil.estimation.alpha_beta import TimedAlphaBetaBank
from vdps_hil.estimation.ekf import MultiRateEKF, UpdateResult
from vdps_hil.estimation.estimates import Estimate, FilteredSignals, Innovation
from vdps_hil.estimation.imu_input import ImuMounting, MeanInput
from vdps_hil.estimation.imu_monitor import ImuMonitor
from vdps_hil.estimation.initialisation import LatestAiding, initial_state, reacquisition_states
from vdps_hil.estimation.lift_off import LiftOffDetector, lever_arm_rates
from vdps_hil.estimation.measurements import (ZrRateBuilder, gnss_velocity_measurement, nhc_measurement,
                                              suspension_measurement, y2_gps_measurement)
from vdps_hil.estimation.observability import ObservabilityReport, ObservabilityWindows
from vdps_hil.estimation.observations import ObsKind
from vdps_hil.estimation.pipeline_config import PipelineConfig
from vdps_hil.estimation.sensor_samples import (attitude_sigmas, gnss_fix, suspension_deflections, wheel_speeds,
                                                wheel_torques)
from vdps_hil.estimation.sequencing import ImuSequencer
from vdps_hil.estimation.wheel_speed import WheelSpeedWindow
from vdps_hil.geodesy import EnuOrigin

KINDS = ("imu", "gnss_pos", "gnss_att", "gnss_vel", "suspension", "wheel_speed", "wheel_torque", "steer")

_NAN = math.nan
_SUSPENSION_KINDS = frozenset((ObsKind.Y1_SUS, ObsKind.Y2_SUS_PLANE, ObsKind.Y2_SUS_RATE))


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
        self._imu = ImuMounting(m, self._esc3, self._g)
        self._lever = np.asarray(m.gnss_lever_arm_m, dtype=float)
        kinds = self.ekf.kinds  # real-car rows (module docstring)
        self._use_ws = ObsKind.WHEEL_SPEED in kinds
        self._use_nhc = ObsKind.NHC in kinds
        self._ws = WheelSpeedWindow(model_vehicle, cfg)
        self._nhc_period_ns = int(round(cfg.nhc_period_s * 1e9))
        self._nhc_last = -(1 << 62)
        bw = cfg.bandwidths
        self._ab_gyro = TimedAlphaBetaBank(3, bw.angular_rate_hz, bw.max_gap_s)
        self._ab_wheel = TimedAlphaBetaBank(4, bw.wheel_speed_hz, bw.max_gap_s)
        self._ab_susp = TimedAlphaBetaBank(4, bw.susp_deflection_hz, bw.max_gap_s)
        self._lift = LiftOffDetector(model_vehicle, cfg.lift_off_load_fraction)
        self._torque = [_NAN] * 4
        self._steer = _NAN
        self._last_t = 0
        self._mean = MeanInput()  # IMU inputs for the mean input of the next predict
        self._f_in = (0.0, 0.0, self._g)
        self._w_in = (0.0, 0.0, 0.0)
        self._level_f = None  # recent mean specific force (initialisation by levelling)
        self._aid = LatestAiding()  # latest aiding data for initialisation / re-acquisition
        self._gated_run = 0
        self.imu_monitor, self.aiding_monitor = ImuMonitor(cfg.imu_checks), AidingMonitor(cfg.aiding_checks)
        self._zr_rate = ZrRateBuilder(heave_rate_sigma_mps=cfg.heave_rate_sigma_mps)
        self._log: list[Sample] = []
        self._counts = dict.fromkeys(("messages", "ignored", "truth_ignored", "invalid", "estimates", "wheel_outliers",
                                      "wheel_accel_skipped", "wheel_too_few", "reacquisitions", "outage_predicts",
                                      "inflations", "lift_off", "gnss_vel_no_rates"), 0)
        self._rejected = dict.fromkeys(KINDS, 0)
        self._per_kind = dict.fromkeys(KINDS, 0)
        self._obs = None
        if cfg.observability_window_s:
            self._obs = ObservabilityWindows(self.ekf.layout, int(round(cfg.observability_window_s * 1e9)),
                                             self.ekf)
        # sequencing: measurements later than the newest IMU sample wait for it (module docstring)
        kind_lat = {"gnss_pos": self._lat["gnss"], "gnss_att": self._lat["gnss"],
                    "gnss_vel": self._lat["gnss_vel"], "suspension": self._lat["suspension"]}
        if self._use_ws:  # only then do wheel speeds update (and advance) the filter
            kind_lat["wheel_speed"] = self._lat["wheel"]
        hold_ns = int(round(cfg.imu_hold_s * 1e9))
        self._hold = hold_ns > 0
        self._seq = ImuSequencer(hold_ns, self._lat["imu"], kind_lat)
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
            truth = kind.startswith("truth") or sample.source.startswith("/truth")
            self._counts["truth_ignored" if truth else "ignored"] += 1
            return []
        self._per_kind[kind] += 1
        if not sample.valid:
            self._counts["invalid"] += 1
            self._rejected[kind] += 1
            return []
        out: list = []
        if self._hold and self._seq.offer(sample, kind, fn, out):
            return out
        fn(sample, out)
        return out

    def finish(self) -> list:
        """End of the input: the measurements still held (in time order); their outputs."""
        out: list = []
        self._seq.release_all(out)
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

    def clear_input_log(self) -> None:
        """Forget the recorded inputs (a long replay that does not need them)."""
        self._log.clear()

    @property
    def origin(self) -> EnuOrigin | None:
        return self._origin

    @property
    def counters(self) -> dict:
        return dict(self._counts, held=self._seq.held, hold_expired=self._seq.hold_expired,
                    holding=self._seq.holding, per_kind=dict(self._per_kind), ekf=self.ekf.counters)  # holding: now

    def rejected(self) -> dict[str, int]:
        """Rejected samples per sensor kind (bad fields, no fix, invalid) plus the EKF's
        gated/NaN/too-old updates per measurement kind."""
        return dict(self._rejected, **{f"ekf.{k}": v for k, v in self.ekf.rejected().items()})

    @property
    def observability_reports(self) -> tuple[tuple[int, int, ObservabilityReport], ...]:
        """(t_start_ns, t_end_ns, report) per completed window."""
        return self._obs.reports if self._obs is not None else ()

    def observability_now(self) -> ObservabilityReport | None:
        """Report of the window in progress."""
        return self._obs.now() if self._obs is not None else None

    def augmented_state(self) -> dict[str, tuple[float, float]]:
        """{name: (value, sigma)} of the EKF's bias and wheel-scale states (empty when the
        configuration carries none or before initialisation)."""
        return self.ekf.augmented_state()

    def estimate(self) -> Estimate | None:
        """The current estimate (None before initialisation)."""
        ekf = self.ekf
        return Estimate.from_filter(ekf.t_ns, ekf.layout, ekf.x, ekf.P) if ekf.initialized else None

    def filtered(self) -> FilteredSignals:
        g, w, s = self._ab_gyro, self._ab_wheel, self._ab_susp
        return FilteredSignals(
            self._last_t, tuple(g.x), tuple(g.v), tuple(w.x), tuple(w.v), tuple(s.x), tuple(s.v),
            tuple(self._torque), self._steer,
            {"angular_accel": g.lag_s, "wheel_accel": w.lag_s, "susp_rate": s.lag_s})

    # ---------------------------------------------------------------- IMU / predict
    def _on_imu(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["imu"]
        fw = self._imu.body_input(s.fields)
        if fw is None:
            self._rejected["imu"] += 1
            return
        f, w = fw
        if not self.imu_monitor.check(t, f, w):  # missing / implausible IMU (imu_monitor)
            self._rejected["imu"] += 1
            return
        self._ab_gyro.update(t, (_NAN, _NAN, w[2]) if self._esc3 else w)
        if self._imu.lever_arm_m is not None:
            f = self._imu.at_cg(f, self._ab_gyro.x, self._ab_gyro.v)
        self._last_t = t
        ekf = self.ekf
        if not ekf.initialized:  # levelling: exponential mean of the specific force (tau ~ 100 samples)
            lf = self._level_f
            self._level_f = tuple(f) if lf is None else tuple(o + 0.01 * (v - o) for o, v in zip(lf, f))
            return
        self._mean.add(f, w)
        if t - ekf.t_ns >= self._period_ns:
            self._flush(t, out)

    def _set_mean_input(self, t1: int) -> None:
        """The input of a predict to t1: the mean of the IMU samples, or the outage input and
        noise when the accepted samples do not cover the span (``imu_monitor``)."""
        mean = self._mean.take()
        if mean is not None:
            self._f_in, self._w_in = mean
        if self.imu_monitor.apply_input(self.ekf, t1, self._f_in, self._w_in, mean is not None):
            self._counts["outage_predicts"] += 1

    def _rate_corrected(self) -> tuple[float, float, float]:
        """The last mean gyro input minus the filter's gyro bias [rad/s] (body axes)."""
        b = self.ekf.bias()[0]
        w = self._w_in
        return (w[0] - b[0], w[1] - b[1], w[2] - b[2])

    def _flush(self, t: int, out: list) -> None:
        """Predict to t with the mean of the accumulated IMU samples; emit an estimate."""
        self._set_mean_input(t)
        was = self.ekf.initialized
        self.ekf.predict_to(t)
        if not self.ekf.initialized:
            if was:
                self._after_reset()
            return
        if self._obs is not None:
            self._obs.tick(self.ekf.t_ns)
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
            self._set_mean_input(t)
            ekf.predict_to(t)
            if not ekf.initialized:
                self._after_reset()
                return False
        return True

    def _update(self, kind: ObsKind, z, R, t: int, out: list, aux=None) -> UpdateResult:
        was = self.ekf.initialized
        ekf = self.ekf
        res = ekf.update(kind, z, R, t, aux)
        out.append(Innovation.from_result(res))
        if was and not ekf.initialized:
            self._after_reset()
        elif self.aiding_monitor.observe(res) and t >= ekf.t_ns:  # inflate and accept (aiding_monitor)
            xf, pf = ekf.full_state()
            if ekf.reacquire(t, self.aiding_monitor.inflation(res, xf, pf)):
                self._counts["inflations"] += 1
                res = ekf.update(kind, z, R, t, aux)
                out.append(Innovation.from_result(res))
                self.aiding_monitor.observe(res)
        return res

    def _nhc_update(self, t: int, out: list) -> None:
        """Non-holonomic constraint at the filter time (module docstring)."""
        cfg = self.config
        self._nhc_last = t
        x = self.ekf.x
        speed = math.sqrt(float(x[3]) ** 2 + float(x[4]) ** 2 + float(x[5]) ** 2)
        w = self._rate_corrected()
        z, R = nhc_measurement(speed, self._f_in[1], w[2], cfg.nhc_sigma_lat_mps, cfg.nhc_slip_rad_per_mps2,
                               cfg.nhc_point_sigma_m, cfg.nhc_sigma_vert_mps)
        self._update(ObsKind.NHC, z, R, t, out, aux=w)

    def _after_reset(self) -> None:
        self.aiding_monitor.reset()
        self._mean.reset()
        self._zr_rate.reset()
        if self._obs is not None:
            self._obs.restart()

    # ---------------------------------------------------------------- GNSS
    def _on_gnss_pos(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["gnss"]
        fix = gnss_fix(s.fields, self._origin, self.config.gnss_pos_sigma_h_m, self.config.gnss_pos_sigma_v_m)
        if fix is None:
            self._rejected["gnss_pos"] += 1
            return
        self._origin, enu, sh, sv = fix
        aid = self._aid
        aid.prev_fix, aid.fix = aid.fix, (t, enu, sh, sv)
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
        ekf = self.ekf
        self._gated_run = 0
        t_now = max(t, ekf.t_ns)
        xf, _ = ekf.full_state()
        a = reacquisition_states(t, t_now, enu, sh, sv, xf, self._aid, self._lever, self.config)
        if ekf.reacquire(t_now, a):
            self._counts["reacquisitions"] += 1
            self._mean.reset()

    def _on_gnss_att(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["gnss"]
        g = s.fields.get
        cfg = self.config
        z = np.array([g("gnss_roll_rad", _NAN), g("gnss_pitch_rad", _NAN), g("gnss_yaw_rad", _NAN)])
        if not np.isfinite(z).any():
            self._rejected["gnss_att"] += 1
            return
        sig = attitude_sigmas(s.fields, cfg.gnss_att_sigma_rad)
        self._aid.att = (t, z, sig)
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
        self._aid.vel = (t, speed, course)
        if not self.ekf.initialized:
            self._try_initialize_from_pending(out)
            return
        z, R = gnss_velocity_measurement(speed, course, cfg.gnss_speed_sigma_mps, cfg.gnss_course_min_speed_mps)
        w = lever_arm_rates(self._ab_gyro.x, self._ab_susp.v, self.vehicle.geometry, self.imu_monitor.missing(t),
                            self._lift.active)
        if w is None:  # no IMU and a wheel off the road: the antenna's rates are unknown (lift_off)
            self._counts["gnss_vel_no_rates"] += 1
            return
        aux = w if all(math.isfinite(v) for v in w) else None
        if self._predict_for(t):
            self._update(ObsKind.GNSS_VEL, z, R, t, out, aux=aux)

    # ---------------------------------------------------------------- chassis
    def _on_suspension(self, s: Sample, out: list) -> None:
        t = s.t_ns - self._lat["suspension"]
        h = suspension_deflections(s.fields)
        if h is None:
            self._rejected["suspension"] += 1
            return
        self._ab_susp.update(t, h)
        if self._lift.unloaded(h, self._ab_susp.v):  # a wheel off the road: eq 5 does not hold (lift_off)
            self._counts["lift_off"] += 1
            return
        geo = self.vehicle.geometry
        sm = suspension_measurement(h, geo.l_f_m, geo.l_r_m, geo.track_half_front_m, geo.track_half_rear_m,
                                    self.config.susp_sigma_m)
        self._aid.susp = (t, sm)
        ekf = self.ekf
        if not ekf.initialized or not ekf.kinds & _SUSPENSION_KINDS:
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
        idx, vals = wheel_speeds(s.fields)
        if not idx or self._ab_wheel.update(t, vals, idx) < len(idx):
            self._rejected["wheel_speed"] += 1
        if not self._use_ws or not self.ekf.initialized:
            return
        if self._ws.push(t, idx, vals):
            self._wheel_update(out)

    def _wheel_update(self, out: list) -> None:
        """Wheel-speed update from the recent samples (module docstring; ``wheel_speed``)."""
        m = self._ws.measurement(self.ekf.x, self._ab_wheel.v, self._torque, self._steer, self._counts)
        if m is None:
            return
        t_m, z, R, d, weights = m
        aux = (self._rate_corrected(), d, weights)
        if self._predict_for(t_m):
            self._update(ObsKind.WHEEL_SPEED, z, R, t_m, out, aux=aux)

    def _on_wheel_torque(self, s: Sample, out: list) -> None:
        vals = wheel_torques(s.fields)
        if vals is None:
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
    def _try_initialize_from_pending(self, out: list) -> None:
        if self._aid.fix is not None:
            self._try_initialize(self._aid.fix[0], out)

    def _try_initialize(self, t: int, out: list) -> None:
        """Initialise at the fix of time t when a heading is known (module docstring)."""
        if self._aid.fix is None or self._aid.fix[0] != t:
            return
        state = initial_state(t, self._aid, self._level_f, self._g, self._lever, self.ekf.layout, self.config)
        if state is None:
            return
        self.ekf.initialize(t, *state)
        self._mean.reset()
        self._zr_rate.reset()
        if self._obs is not None:
            self._obs.forget_start()
        if self.config.emit_estimates:
            out.append(self.estimate())
            self._counts["estimates"] += 1
