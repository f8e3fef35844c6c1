"""Settings of the estimator pipeline node (``pipeline.EstimatorPipeline``): the EKF
configuration, the predict and output periods, the measurement noise used when a sample carries
no sigma of its own (Table 1), the alpha-beta bandwidths (``Bandwidths``), the per-sensor
latencies (``Latencies``), initialisation, the real-car rows (wheel speed, non-holonomic
constraint, re-acquisition) and the IMU hold of the sequencing (``sequencing``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vdps_hil.estimation.aiding_monitor import AidingChecks
from vdps_hil.estimation.ekf_config import EkfConfig
from vdps_hil.estimation.imu_monitor import ImuChecks
from vdps_hil.units import deg2rad


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
    lift_off_load_fraction: float = 0.1  # no suspension update below this share of a corner's static load (lift_off)
    heave_rate_sigma_mps: float = 0.05  # y2_sus rate form (measurements.ZrRateBuilder)
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
    imu_checks: ImuChecks = field(default_factory=ImuChecks)  # missing / implausible IMU (imu_monitor)
    aiding_checks: AidingChecks = field(default_factory=AidingChecks)  # gate lock-out, consistency

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
