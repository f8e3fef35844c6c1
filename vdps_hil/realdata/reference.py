"""Errors of a run against a drive's reference and the reference-free baselines: speed and
course errors, planar dead reckoning from wheel speed and yaw rate, constant-velocity
extrapolation, and the lags between series (a solution's velocities behind its positions, GNSS
speed behind the wheel speeds).
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.realdata.containers import Reference
from vdps_hil.units import wrap_pi

__all__ = ["interp_angle", "speed_course_errors", "dead_reckoning", "constant_velocity", "velocity_lag",
           "estimate_lag"]


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
