"""Measurement builders: sensor quantities -> (z, R) for the observation models (``observations``).

=============================  ============================================================
builder                        measurement
=============================  ============================================================
``suspension_measurement``     eq 5 on the four deflections: y1_sus (z, R, exactly linear in
                               H) and eq 5's z_r with its variance (y2_sus)
``y2_gps_measurement``         y2_gps from the GNSS attitude (pitch, yaw) with an isotropic
                               R floor (paper-faithful (b) only)
``ZrRateBuilder``              the locally referenced y2_sus (correction (c)): the rate of
                               eq 5's z_r over a baseline
``gnss_velocity_measurement``  gnss_vel from the single-antenna speed and course over ground
``nhc_measurement``            the non-holonomic constraint (real cars, below)
=============================  ============================================================

Non-holonomic constraint (the pipeline adds one every ``nhc_period_s`` after a predict):
z = [0, 0] with::

    sigma_lat^2 = sigma_0^2 + (k_beta |a_y| |v|)^2 + (sigma_x w_z)^2

sigma_0 ``nhc_sigma_lat_mps``; the rear-axle slip angle grows with the lateral acceleration a_y
of the mean IMU input (k_beta ``nhc_slip_rad_per_mps2`` [rad/(m/s^2)]); sigma_x
``nhc_point_sigma_m`` is the uncertainty of the rear axle's position along x in the model file
(a point l off it moves sideways by w_z l); sigma_vert ``nhc_sigma_vert_mps``.

Pure functions (and one small buffer, ``ZrRateBuilder``); the pipeline hands their (z, R) to
``MultiRateEKF.update``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SuspensionMeasurement:
    """Eq 5 applied to the four deflections H_1..4 [m] (compression positive, FL FR RR RL).

    ``y1``/``r_y1``: z and R of the y1_sus model; ``z_r_m``/``var_z_r_m2``: eq 5's z_r and its
    variance (y2_sus). With W = 2 l_f + 2 l_r and T = 2 t_f + 2 t_r::

        y1 = [(-H1 - H2 + H3 + H4) / W, (-H1 + H2 + H3 - H4) / T]     (exactly linear in H)
        R_y1 = sigma_H^2 diag(4 / W^2, 4 / T^2)                       (the rows are orthogonal)
        z_r = (-l_r (H1 + H2) - l_f (H3 + H4)) / W,  var = sigma_H^2 (2 l_r^2 + 2 l_f^2) / W^2
    """

    theta_v_rad: float
    phi_v_rad: float
    z_r_m: float
    y1: np.ndarray
    r_y1: np.ndarray
    var_z_r_m2: float


def suspension_measurement(h_m, l_f_m: float, l_r_m: float, t_f_half_m: float, t_r_half_m: float,
                           sigma_m: float) -> SuspensionMeasurement:
    """Eq 5 (signs per ``vdps_hil.conventions``: theta_v nose-up positive) -> y1_sus and y2_sus
    measurements with their covariances (see :class:`SuspensionMeasurement`)."""
    h1, h2, h3, h4 = (float(v) for v in h_m)
    w = 2.0 * l_f_m + 2.0 * l_r_m
    t = 2.0 * t_f_half_m + 2.0 * t_r_half_m
    s_th = (-h1 - h2 + h3 + h4) / w
    s_ph_c_th = (-h1 + h2 + h3 - h4) / t
    th = math.asin(max(-1.0, min(1.0, s_th)))
    ph = math.asin(max(-1.0, min(1.0, s_ph_c_th / math.cos(th))))
    z_r = (-l_r_m * (h1 + h2) - l_f_m * (h3 + h4)) / w
    s2 = sigma_m * sigma_m
    r = np.diag([4.0 * s2 / (w * w), 4.0 * s2 / (t * t)])
    var_zr = s2 * (2.0 * l_r_m ** 2 + 2.0 * l_f_m ** 2) / (w * w)
    return SuspensionMeasurement(th, ph, z_r, np.array([s_th, s_ph_c_th]), r, var_zr)


def suspension_body_rates(hd_mps, l_f_m: float, l_r_m: float, t_f_half_m: float,
                          t_r_half_m: float) -> tuple[float, float]:
    """(roll rate, pitch rate) [rad/s] of the body over the road from the deflection rates
    Hd [m/s]: the time derivative of eq 5's rows at small angles, phi_dot = (-Hd1 + Hd2 + Hd3 -
    Hd4) / (2 t_f + 2 t_r), theta_dot = (-Hd1 - Hd2 + Hd3 + Hd4) / (2 l_f + 2 l_r): what the
    gyro's w_x, w_y read on a flat road. NaN when a rate is not finite."""
    d1, d2, d3, d4 = (float(v) for v in hd_mps)
    return ((-d1 + d2 + d3 - d4) / (2.0 * t_f_half_m + 2.0 * t_r_half_m),
            (-d1 - d2 + d3 + d4) / (2.0 * l_f_m + 2.0 * l_r_m))


def y2_gps_measurement(theta_g_rad: float, psi_g_rad: float, sigma_theta_rad: float,
                       sigma_psi_rad: float, floor: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """z = [C_g^v(1,1), C_g^v(1,2)] = [cos th cos psi, cos th sin psi] from the GNSS attitude and
    R = J diag(sigma_th^2, sigma_psi^2) J^T + floor^2 I.

    J is singular at theta = 0 (z then moves only along the circle of radius cos(theta)); the
    radial direction would get almost no noise, and the second-order residual of a lagging
    psi_v (eq 6's zero rate, yaw rate x 0.2 s ~ 0.05 rad -> 1e-3 radially) would be gated. The
    isotropic ``floor`` (default: the larger angle sigma) keeps the paper's measurement usable."""
    if floor is None:
        floor = max(sigma_theta_rad, sigma_psi_rad)
    ct, st = math.cos(theta_g_rad), math.sin(theta_g_rad)
    cp, sp = math.cos(psi_g_rad), math.sin(psi_g_rad)
    z = np.array([ct * cp, ct * sp])
    j = np.array([[-st * cp, -ct * sp], [-st * sp, ct * cp]])
    return z, j @ np.diag([sigma_theta_rad ** 2, sigma_psi_rad ** 2]) @ j.T + floor ** 2 * np.eye(2)


class ZrRateBuilder:
    """Measurement of the locally referenced y2^sus (correction (c), ``Y2SusRate``)::

        z = (z_r(t_k) - z_r(t_j)) / (t_k - t_j)
        R = (var_k + var_j) / (t_k - t_j)^2 + sigma_heave^2

    t_j is the newest stored epoch at least ``min_baseline_s`` before t_k (epochs older than
    ``max_baseline_s`` are dropped). The mean heave rate over the baseline stands for the
    instantaneous n . v at t_k; ``heave_rate_sigma_mps`` covers the difference (body heave
    relative to the road plane)."""

    def __init__(self, min_baseline_s: float = 0.5, max_baseline_s: float = 3.0,
                 heave_rate_sigma_mps: float = 0.05):
        if not (0.0 < min_baseline_s < max_baseline_s):
            raise ValueError("ZrRateBuilder needs 0 < min_baseline_s < max_baseline_s")
        self._min_ns = int(round(min_baseline_s * 1e9))
        self._max_ns = int(round(max_baseline_s * 1e9))
        self._q = heave_rate_sigma_mps ** 2
        self._buf: list[tuple[int, float, float]] = []

    def reset(self) -> None:
        self._buf.clear()

    def push(self, t_ns: int, z_r_m: float, var_m2: float):
        """Add an epoch; returns (z (1,), R (1, 1)) or None when no baseline is available."""
        buf = self._buf
        while buf and t_ns - buf[0][0] > self._max_ns:
            buf.pop(0)
        out = None
        for tj, zj, vj in reversed(buf):
            if t_ns - tj >= self._min_ns:
                dt = (t_ns - tj) * 1e-9
                out = (np.array([(z_r_m - zj) / dt]), np.array([[(var_m2 + vj) / (dt * dt) + self._q]]))
                break
        buf.append((int(t_ns), float(z_r_m), float(var_m2)))
        return out


def gnss_velocity_measurement(speed_mps: float, course_rad: float, sigma_mps: float,
                              course_min_speed_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """z = [speed, course] and R = diag(sigma^2, (sigma / speed)^2) of the ``gnss_vel`` model; below
    ``course_min_speed_mps`` (or without a course) the course row is NaN (dropped by the EKF)."""
    ss = sigma_mps
    if speed_mps >= course_min_speed_mps and math.isfinite(course_rad):
        z = np.array([speed_mps, course_rad])
        R = np.diag([ss * ss, (ss / speed_mps) ** 2])
    else:
        z = np.array([speed_mps, math.nan])
        R = np.diag([ss * ss, 1.0])
    return z, R


def nhc_measurement(speed_mps: float, lateral_accel_mps2: float, yaw_rate_radps: float, sigma_lat_mps: float,
                    slip_rad_per_mps2: float, point_sigma_m: float, sigma_vert_mps: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """z = [0, 0] and R = diag(sigma_lat^2, sigma_vert^2) of the non-holonomic constraint (module
    docstring): |v| ``speed_mps``, a_y ``lateral_accel_mps2``, w_z ``yaw_rate_radps``."""
    s_lat = math.sqrt(sigma_lat_mps ** 2 + (slip_rad_per_mps2 * abs(lateral_accel_mps2) * speed_mps) ** 2
                      + (point_sigma_m * yaw_rate_radps) ** 2)
    return np.zeros(2), np.diag([s_lat * s_lat, sigma_vert_mps ** 2])
