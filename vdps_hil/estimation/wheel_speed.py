"""The wheel-speed measurement of the real-car extension (``EkfConfig.wheel_speed``) from the
recent wheel samples (``WheelSpeedWindow``; the observation model: ``observations.WheelSpeed``).

Every ``wheel_speed_period_s`` the wheel samples of the last ``wheel_speed_window_s`` are
averaged per wheel (omega_i r_0, r_0 = ``tire.rolling_radius_m`` of the model file, stamped at
their mean time). A wheel further than ``wheel_outlier_mps + wheel_outlier_rel |median|`` from
the median of the four is dropped (locked or spinning; counted ``wheel_outliers``); the mean of
the others is z (sign from the filter's forward speed: wheel speeds carry none; the pipeline
applies it), with front road-wheel angles d = steering wheel angle / steer ratio. Slip and
braking: with a_w = r_0 x the mean alpha-beta wheel acceleration of the wheels used, the update
is skipped when |a_w| > ``wheel_accel_gate_mps2`` (counted ``wheel_accel_skipped``) and
otherwise::

    sigma^2 = sigma_0^2 + (c_a a_w)^2 + (|z| |T| / (r_0 C_kappa))^2

sigma_0 ``wheel_speed_sigma_mps``, c_a ``wheel_accel_sigma_s`` [s], |T| the mean absolute wheel
torque of the wheels used (when a ``wheel_torque`` source exists) and C_kappa
``wheel_long_stiffness_n`` (slip ratio ~ T / (r_0 C_kappa)). Fewer than two usable wheels:
no update (counted ``wheel_too_few``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from vdps_hil.model.frames import dcm_gv

_NAN = math.nan


@dataclass(frozen=True)
class WheelSpeedRow:
    """One wheel-speed measurement: time [ns], z [m/s] (unsigned), its variance [m^2/s^2] and the
    wheels used (indices FL FR RR RL)."""

    t_ns: int
    z_mps: float
    var_m2ps2: float
    wheels: tuple[int, ...]


def wheel_speed_row(recent, r0_m: float, wheel_accel_radps2, torque_nm, cfg, counts: dict) -> WheelSpeedRow | None:
    """The measurement from ``recent`` ((t_ns, [omega_1..4 or NaN]) of the window), the
    alpha-beta wheel accelerations and the latest wheel torques (module docstring); None when
    skipped, the reason counted in ``counts`` (``wheel_too_few``, ``wheel_accel_skipped``; the
    dropped outliers in ``wheel_outliers``). ``cfg``: ``PipelineConfig``."""
    # v: per-wheel mean speed omega_i r_0 [m/s]; med, tol: median and outlier tolerance; a_w: mean wheel
    # acceleration [m/s^2]; s_t: slip sigma |z| |T| / (r_0 C_kappa) [m/s] (module docstring)
    t_m = int(round(sum(tt for tt, _ in recent) / len(recent)))
    v = []
    for i in range(4):
        vals = [w[i] for _, w in recent if w[i] - w[i] == 0.0]
        v.append(sum(vals) / len(vals) * r0_m if vals else _NAN)
    avail = [i for i in range(4) if math.isfinite(v[i])]
    if len(avail) < 2:
        counts["wheel_too_few"] += 1
        return None
    med = float(np.median([v[i] for i in avail]))
    tol = cfg.wheel_outlier_mps + cfg.wheel_outlier_rel * abs(med)
    keep = [i for i in avail if abs(v[i] - med) <= tol]
    counts["wheel_outliers"] += len(avail) - len(keep)
    if len(keep) < 2:
        counts["wheel_too_few"] += 1
        return None
    z = sum(v[i] for i in keep) / len(keep)
    acc = [wheel_accel_radps2[i] for i in keep if wheel_accel_radps2[i] - wheel_accel_radps2[i] == 0.0]
    a_w = (sum(acc) / len(acc) * r0_m) if acc else 0.0
    if abs(a_w) > cfg.wheel_accel_gate_mps2:
        counts["wheel_accel_skipped"] += 1
        return None
    torque = [abs(torque_nm[i]) for i in keep if math.isfinite(torque_nm[i])]
    s_t = abs(z) * (sum(torque) / len(torque)) / (r0_m * cfg.wheel_long_stiffness_n) if torque else 0.0
    var = cfg.wheel_speed_sigma_mps ** 2 + (cfg.wheel_accel_sigma_s * a_w) ** 2 + s_t * s_t
    return WheelSpeedRow(t_m, z, var, tuple(keep))


class WheelSpeedWindow:
    """The wheel samples of the last ``wheel_speed_window_s`` and the update period (module
    docstring) for a model ``vehicle`` (rolling radius, steer ratio) and a ``PipelineConfig``."""

    def __init__(self, vehicle, cfg):
        self._cfg = cfg
        self._r0 = float(vehicle.tire.rolling_radius_m)
        sr = float(getattr(vehicle.geometry, "steer_ratio", 0.0) or 0.0)
        self._steer_ratio = sr if sr > 0 and math.isfinite(sr) else 0.0
        self._recent: deque[tuple[int, list[float]]] = deque()
        self._period_ns = int(round(cfg.wheel_speed_period_s * 1e9))
        self._window_ns = int(round(cfg.wheel_speed_window_s * 1e9))
        self._last = -(1 << 62)

    def push(self, t: int, wheels, values) -> bool:
        """Add the ``values`` [rad/s] of the ``wheels`` (indices) a sample of time t carries;
        True when an update is due (``wheel_speed_period_s`` since the last)."""
        w = [_NAN, _NAN, _NAN, _NAN]
        for i, v in zip(wheels, values):
            w[i] = v
        recent = self._recent
        recent.append((t, w))
        while recent and t - recent[0][0] > self._window_ns:
            recent.popleft()
        if t - self._last >= self._period_ns:
            self._last = t
            return True
        return False

    def measurement(self, x, wheel_accel_radps2, torque_nm, steer_wheel_rad: float, counts: dict):
        """(t_ns, z (1,), R (1, 1), front road-wheel angles (4,), wheel weights (4,)) of the
        ``wheel_speed`` update, z signed by the forward speed of the filter state ``x``; None
        when skipped (``wheel_speed_row``)."""
        row = wheel_speed_row(self._recent, self._r0, wheel_accel_radps2, torque_nm, self._cfg, counts)
        if row is None:
            return None
        z, keep = row.z_mps, row.wheels
        c0 = dcm_gv(float(x[6]), float(x[7]), float(x[8]))[0]
        if float(c0[0] * x[3] + c0[1] * x[4] + c0[2] * x[5]) < -0.3:
            z = -z  # reversing: wheel speeds carry no sign
        sr = self._steer_ratio
        d = steer_wheel_rad / sr if (sr and math.isfinite(steer_wheel_rad)) else 0.0
        weights = [1.0 / len(keep) if i in keep else 0.0 for i in range(4)]
        return row.t_ns, np.array([z]), np.array([[row.var_m2ps2]]), (d, d, 0.0, 0.0), weights
