"""Wheel lift-off: when the suspension deflections stop telling the body's attitude over the road.

Eq 5 (``measurements.suspension_measurement``) takes the body's height over the road at each
corner from its suspension deflection: the wheel stands on the road and the tire carries the
corner's load. A wheel that has lifted off (two-wheel tip-up in a fishhook, a crest) hangs at
full droop in the air: its deflection says where the wheel hangs, not where the road is, so
``y1_sus`` and ``y2_sus`` then measure a wrong attitude, with the precision of a good one
(4e-4 rad). Taken anyway, they pull roll and pitch, and through the filter's correlations yaw and
velocity, away from the truth: on ``fishhook-suv`` with the GNSS out for 2 s over the tip-up, a
1.7 deg yaw error against a 0.25 deg sigma (``tools/fault_campaign.py``, issue 20).

The load of each corner follows from the spring law of eq 14 (``model.spring_law``)::

    F_z,i = K_s,i(H_i) H_i + D_s,i Hd_i + F_arb,i + m_u,i g      (>= 0; 0 once lifted)

with H_i the deflection (compression from the design ride height plus the static compression),
Hd_i its alpha-beta rate. A corner is *unloaded* when F_z,i < ``load_fraction`` F_z,i(0, 0), the
static load: the wheel is off the road or about to leave it. While any corner is unloaded, the
suspension updates are not made (counted as ``lift_off``); the attitude is carried by the IMU and
the GNSS. Without an IMU (an outage) the pipeline takes the roll and pitch rates of the GNSS
antenna's lever arm (omega x r of ``gnss_vel``) from the suspension rates
(``measurements.suspension_body_rates``); with a wheel off the road as well those rates are
unknown (a tip-up rolls at up to 2-3 rad/s, 2 m/s at a 0.85 m antenna height), so the GNSS
velocity update is not made either (counted as ``gnss_vel_no_rates``). ``load_fraction`` (0.1)
leaves a margin for the spring law's error in the model file and the rate's lag (a physical
choice, not fitted: at 0 the wheel has already left the road).

Symbols: H [m] (compression positive), Hd [m/s], F [N].
"""

from __future__ import annotations

import math

from vdps_hil.estimation.measurements import suspension_body_rates
from vdps_hil.model.spring_law import suspension_forces_n

__all__ = ["LiftOffDetector", "lever_arm_rates"]


def lever_arm_rates(gyro_radps, susp_rate_mps, geometry, imu_missing: bool, lifted: bool) -> list | None:
    """Body rates [rad/s] for the GNSS antenna's lever arm (omega x r): the gyro's (alpha-beta)
    ``gyro_radps``; while the IMU is missing, roll and pitch rates from the suspension rates
    (``measurements.suspension_body_rates``; the held ones where those are not finite, e.g. a car
    without suspension sensors) and the held yaw rate; None while the IMU is missing
    and a wheel is off the road (``lifted``: the rates are unknown; module docstring)."""
    w = list(gyro_radps)
    if not imu_missing:
        return w
    if lifted:
        return None
    g = geometry
    rates = suspension_body_rates(susp_rate_mps, g.l_f_m, g.l_r_m, g.track_half_front_m, g.track_half_rear_m)
    if all(math.isfinite(r) for r in rates):  # a car without suspension sensors keeps the held gyro rates
        w[:2] = rates
    return w


class LiftOffDetector:
    """``unloaded(h, hd)``: True while any corner's spring-law load is below ``load_fraction`` of
    its static load (module docstring). ``load_fraction`` 0 turns the check off."""

    def __init__(self, vehicle, load_fraction: float):
        if not (isinstance(load_fraction, (int, float)) and math.isfinite(load_fraction) and 0 <= load_fraction < 1):
            raise ValueError(f"lift-off load fraction must be in [0, 1), got {load_fraction!r}")
        self.vehicle = vehicle
        self.load_fraction = float(load_fraction)
        static = suspension_forces_n(vehicle, (0.0,) * 4, (0.0,) * 4)
        self._limit_n = [self.load_fraction * float(f) for f in static]
        self.unloaded_samples = 0
        self.active = False  # the latest verdict

    def unloaded(self, h, hd) -> bool:
        """Whether a corner is unloaded at deflections ``h`` [m] and rates ``hd`` [m/s] (a
        non-finite rate is taken as 0); counted."""
        if self.load_fraction <= 0.0:
            return False
        rate = [v if math.isfinite(v) else 0.0 for v in hd]
        fz = suspension_forces_n(self.vehicle, h, rate)
        self.active = any(f < lim for f, lim in zip(fz, self._limit_n))  # NaN loads compare False
        self.unloaded_samples += self.active
        return self.active
