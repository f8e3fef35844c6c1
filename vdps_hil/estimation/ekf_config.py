"""Configuration of the multi-rate EKF: which sensors exist, which of the paper's corrections
are applied, the noise figures and the real-car extensions. The state layout
(``EkfConfig.layout``) and the measurement kinds (``EkfConfig.kinds``) follow from it.

Corrections of the paper (``PaperFaithful``: True = as printed, the default False = corrected):

(a) ``a_psi_v_zero_rate``: eq 6 gives psi_v a zero rate, so between GPS epochs it lags the
    heading (by yaw rate x 0.2 s at 5 Hz). With psi_r = 0 only five of the six angles are
    independent; corrected, psi_v is *derived* from eq 4 (``StateLayout(psi_v_state=False)``)
    and the filter carries 11 states.
(b) ``b_y2_gps``: y2^gps is computed from the same GNSS attitude as y1^gps, so using both
    counts that attitude twice with independent noise. Corrected: y2^gps is dropped (with (a)
    corrected psi_v needs no observation of its own). Faithful: y2^gps is used with
    R = J R_att J^T + floor^2 I (``measurements.y2_gps_measurement``; the isotropic floor, by
    default the angle sigma, keeps the lagging zero-rate psi_v from being gated on the radial
    direction of the unit-circle measurement, and also weakens the double counting).
(c) ``c_y2_sus_single_plane``: y2^sus = n . p assumes one road plane through the ENU origin.
    Corrected: that form is used only when ``road_plane_through_origin`` is configured true;
    otherwise the locally referenced form n . v = dz_r/dt (``observations.Y2SusRate``).
(d) ``d_accel_as_acceleration``: eq 7 integrates the accelerometer as if it measured the
    kinematic acceleration; it measures specific force. Corrected: gravity [0, 0, -g] is added.

Process noise: white IMU noise sigma per sample at f_imu gives q = sigma^2 / f_imu for the mean
input (``kinematics``); axes an ESC cluster does not provide (w_x, w_y, f_z) are substituted by
0, 0, g with PSD 2 sigma_sub^2 tau_sub (first-order Markov at low frequency). Road angles (and
psi_v in the faithful (a) variant) are random walks.

Real-car extensions (not in the paper; every one OFF by default, so the paper's Table-1 set
runs eq 7-11 as before; the sensor sets of real cars in ``configs/sensorsets`` switch them on):

* IMU bias states (``gyro_bias``, ``accel_bias``; ``states.AugStates``): the inputs become
  w_b = w_meas - b_g, f_b = f_meas - b_a, with b random walks (``gyro_bias_rw`` [rad/s/sqrt(s)],
  ``accel_bias_rw`` [m/s^2/sqrt(s)]) and prior sigmas ``gyro_bias_sigma_radps``,
  ``accel_bias_sigma_mps2``; d x_dot / d b_g = -G_w, d x_dot / d b_a = -G_f (G = d f/d [f, w];
  ``ekf_reference.filter_jacobians``). Only the axes the IMU has (ESC cluster: b_g,z, b_a,x, b_a,y).
* Wheel speed (``wheel_speed``): the ``wheel_speed`` observation (``observations.WheelSpeed``),
  optionally with the scale state k_w (``wheel_scale_state``, random walk ``wheel_scale_rw``).
* Non-holonomic constraint (``nonholonomic``): the ``nhc`` observation
  (``observations.NonHolonomic``).
* Re-acquisition (``reacquire``): after persistent gating of the position the caller resets
  position, velocity and yaw to the fixes (their cross-covariances dropped) and keeps the rest
  (attitude, biases); counted ``reacquisitions``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vdps_hil.estimation.observations import ObsKind
from vdps_hil.estimation.states import StateLayout
from vdps_hil.units import GRAVITY_MPS2, deg2rad

_IMU_KINDS = ("6axis", "esc3")
_GNSS_KINDS = ("multi_antenna", "single_antenna", "none")


@dataclass(frozen=True)
class PaperFaithful:
    """One switch per documented correction; True implements the paper as printed."""

    a_psi_v_zero_rate: bool = False
    b_y2_gps: bool = False
    c_y2_sus_single_plane: bool = False
    d_accel_as_acceleration: bool = False

    @classmethod
    def all(cls) -> "PaperFaithful":
        return cls(True, True, True, True)

    @classmethod
    def only(cls, name: str) -> "PaperFaithful":
        """Only the named switch faithful (``"a_psi_v_zero_rate"`` ...)."""
        if name not in cls.__dataclass_fields__:
            raise ValueError(f"unknown paper_faithful switch {name!r}")
        return cls(**{name: True})

    def any(self) -> bool:
        return any((self.a_psi_v_zero_rate, self.b_y2_gps, self.c_y2_sus_single_plane,
                    self.d_accel_as_acceleration))


@dataclass(frozen=True)
class SensorSet:
    """Which sources exist. ``imu``: "6axis" (serial IMU) or "esc3" (ESC cluster on CAN: yaw
    rate, a_x, a_y only). ``gnss``: "multi_antenna" (position + attitude), "single_antenna"
    (position + speed/course) or "none". ``suspension``/``wheel_speeds``: fitted or not."""

    imu: str = "6axis"
    gnss: str = "multi_antenna"
    suspension: bool = True
    wheel_speeds: bool = True

    def __post_init__(self):
        if self.imu not in _IMU_KINDS:
            raise ValueError(f"SensorSet.imu must be one of {_IMU_KINDS}, got {self.imu!r}")
        if self.gnss not in _GNSS_KINDS:
            raise ValueError(f"SensorSet.gnss must be one of {_GNSS_KINDS}, got {self.gnss!r}")
        for name in ("suspension", "wheel_speeds"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"SensorSet.{name} must be true or false, got {getattr(self, name)!r}")

    @classmethod
    def paper(cls) -> "SensorSet":
        """Table 1: 3-antenna GNSS, 6-axis IMU, four suspension sensors, tachometers."""
        return cls()


@dataclass(frozen=True)
class EkfConfig:
    """Filter configuration; the state layout and the enabled measurement kinds follow from it.

    Noise figures default to Table 1 (accelerometer 0.02 m/s^2 and gyro 0.08 deg/s at 1 kHz)."""

    sensors: SensorSet = field(default_factory=SensorSet)
    paper_faithful: PaperFaithful = field(default_factory=PaperFaithful)
    estimate_road: bool | None = None  # None: estimate road angles iff suspension is fitted
    road_plane_through_origin: bool = False  # (c): y2^sus = n.p valid (one plane through origin)
    use_gnss_velocity: bool = True  # speed/course updates when such samples arrive
    gravity_mps2: float = GRAVITY_MPS2
    imu_rate_hz: float = 1000.0
    accel_noise_mps2: float = 0.02  # per-sample sigma at imu_rate_hz (Table 1)
    gyro_noise_radps: float = float(deg2rad(0.08))  # per-sample sigma (Table 1)
    accel_model_psd: float = 0.0  # extra white acceleration PSD [(m/s^2)^2 s] (bias, vibration)
    gyro_model_psd: float = 0.0  # extra white rate PSD [(rad/s)^2 s]
    substitute_accel_sigma_mps2: float = 0.5  # esc3: f_z := g, error sigma
    substitute_gyro_sigma_radps: float = 0.05  # esc3: w_x = w_y := 0, error sigma
    substitute_corr_time_s: float = 0.2  # esc3: correlation time of the substitution error
    road_angle_rw: float = 3e-4  # road angle random walk [rad/sqrt(s)]
    psi_v_rw: float = 0.3  # faithful (a) only: psi_v random walk [rad/sqrt(s)]
    gate_probability: float | None = 0.9999  # chi-square gate; None disables gating
    history_s: float = 1.0  # latency buffer length [s]; 0 disables late measurements
    max_step_s: float = 0.05  # longest single predict step [s] (longer spans are split)
    update_iterations: int = 3  # iterated-EKF relinearisations for the nonlinear kinds (1 = EKF)
    # real-car extensions (module docstring); all off for the paper's Table-1 set
    gyro_bias: bool = False  # gyro bias states b_g (the axes the IMU has)
    accel_bias: bool = False  # accelerometer bias states b_a
    gyro_bias_sigma_radps: float = float(deg2rad(0.5))  # prior sigma of b_g
    accel_bias_sigma_mps2: float = 0.1  # prior sigma of b_a
    gyro_bias_rw: float = 1e-4  # b_g random walk [rad/s/sqrt(s)]
    accel_bias_rw: float = 1e-3  # b_a random walk [m/s^2/sqrt(s)]
    wheel_speed: bool = False  # wheel_speed rows (needs sensors.wheel_speeds)
    wheel_scale_state: bool = False  # wheel-speed scale state k_w (with wheel_speed)
    wheel_scale_sigma: float = 0.02  # prior sigma of k_w [-]
    wheel_scale_rw: float = 1e-4  # k_w random walk [1/sqrt(s)]
    nonholonomic: bool = False  # nhc rows (no lateral/vertical velocity at the rear axle)

    def __post_init__(self):
        for name in ("imu_rate_hz", "accel_noise_mps2", "gyro_noise_radps", "substitute_accel_sigma_mps2",
                     "substitute_gyro_sigma_radps", "substitute_corr_time_s", "max_step_s",
                     "gyro_bias_sigma_radps", "accel_bias_sigma_mps2", "wheel_scale_sigma"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"EkfConfig.{name} must be a positive finite number, got {v!r}")
        for name in ("gyro_bias", "accel_bias", "wheel_speed", "wheel_scale_state", "nonholonomic"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"EkfConfig.{name} must be true or false, got {getattr(self, name)!r}")
        for name in ("accel_model_psd", "gyro_model_psd", "road_angle_rw", "psi_v_rw", "history_s", "gravity_mps2",
                     "gyro_bias_rw", "accel_bias_rw", "wheel_scale_rw"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"EkfConfig.{name} must be a non-negative finite number, got {v!r}")
        if not (isinstance(self.update_iterations, int) and 1 <= self.update_iterations <= 20):
            raise ValueError(f"EkfConfig.update_iterations must be an integer in 1..20, got {self.update_iterations!r}")
        if self.gate_probability is not None and not (0.0 < self.gate_probability < 1.0):
            raise ValueError(f"EkfConfig.gate_probability must be in (0, 1) or None, got {self.gate_probability!r}")

    @property
    def road_estimated(self) -> bool:
        return self.sensors.suspension if self.estimate_road is None else bool(self.estimate_road)

    def with_real_car_rows(self) -> "EkfConfig":
        """This configuration with the real-car extensions on (module docstring): IMU bias states,
        the non-holonomic constraint and, when wheel speeds are fitted, the wheel-speed row and
        its scale state (what ``configs/sensorsets`` of real cars switch on; e.g. for a sensor set
        inferred from a recording without multi-antenna attitude)."""
        import dataclasses

        ws = self.sensors.wheel_speeds
        return dataclasses.replace(self, gyro_bias=True, accel_bias=True, nonholonomic=True, wheel_speed=ws,
                                   wheel_scale_state=ws)

    @property
    def gyro_bias_axes(self) -> tuple[int, ...]:
        """Body axes with a gyro bias state (ESC cluster: z only)."""
        if not self.gyro_bias:
            return ()
        return (2,) if self.sensors.imu == "esc3" else (0, 1, 2)

    @property
    def accel_bias_axes(self) -> tuple[int, ...]:
        """Body axes with an accelerometer bias state (ESC cluster: x, y)."""
        if not self.accel_bias:
            return ()
        return (0, 1) if self.sensors.imu == "esc3" else (0, 1, 2)

    @property
    def uses_wheel_speed(self) -> bool:
        return self.wheel_speed and self.sensors.wheel_speeds

    def layout(self) -> StateLayout:
        road = self.road_estimated
        return StateLayout(road_estimated=road, psi_v_state=road and self.paper_faithful.a_psi_v_zero_rate,
                           gyro_bias_axes=self.gyro_bias_axes, accel_bias_axes=self.accel_bias_axes,
                           wheel_scale=self.uses_wheel_speed and self.wheel_scale_state)

    def kinds(self) -> frozenset[ObsKind]:
        """Measurement kinds this configuration uses (eq 9 rows that exist for the sensors)."""
        s, pf, road = self.sensors, self.paper_faithful, self.road_estimated
        k: set[ObsKind] = set()
        if s.gnss != "none":
            k.add(ObsKind.GNSS_POS)
            if self.use_gnss_velocity:
                k.add(ObsKind.GNSS_VEL)
        if s.gnss == "multi_antenna":
            k.add(ObsKind.GNSS_ATT)
            if road and pf.b_y2_gps:
                k.add(ObsKind.Y2_GPS)
        if s.suspension and road:
            k.add(ObsKind.Y1_SUS)
            if pf.c_y2_sus_single_plane or self.road_plane_through_origin:
                k.add(ObsKind.Y2_SUS_PLANE)
            else:
                k.add(ObsKind.Y2_SUS_RATE)
        if self.uses_wheel_speed:
            k.add(ObsKind.WHEEL_SPEED)
        if self.nonholonomic:
            k.add(ObsKind.NHC)
        return frozenset(k)

    def input_psd(self) -> np.ndarray:
        """q_u = [q_ax, q_ay, q_az, q_wx, q_wy, q_wz] of the mean IMU input (module docstring)."""
        qa = self.accel_noise_mps2 ** 2 / self.imu_rate_hz + self.accel_model_psd
        qg = self.gyro_noise_radps ** 2 / self.imu_rate_hz + self.gyro_model_psd
        q = np.array([qa, qa, qa, qg, qg, qg])
        if self.sensors.imu == "esc3":
            tau = self.substitute_corr_time_s
            q[2] = 2.0 * self.substitute_accel_sigma_mps2 ** 2 * tau
            q[3] = q[4] = 2.0 * self.substitute_gyro_sigma_radps ** 2 * tau
        return q

    @property
    def gravity_in_model_mps2(self) -> float:
        """g added to the velocity equation: 0 when faithful (d)."""
        return 0.0 if self.paper_faithful.d_accel_as_acceleration else self.gravity_mps2
