"""IMU measurement effects: constant biases and a lever arm.

Symbols (body axes, the IMU's axes assumed aligned with them)::

    f_cg, omega, omega_dot   specific force [m/s^2], rate [rad/s], angular accel [rad/s^2] at the CG
    r                        IMU position relative to the CG [m]

* ``imu_bias``:      f_meas = f + b_a,   omega_meas = omega + b_g
* ``imu_lever_arm``: f_imu = f_cg + omega_dot x r + omega x (omega x r),  omega unchanged
"""

from __future__ import annotations

import math
from typing import Mapping

from .base import ImuKinematics, MeasurementEffect, ParamSpec

_F = ("specific_force_mps2_x", "specific_force_mps2_y", "specific_force_mps2_z")
_W = ("angular_rate_radps_x", "angular_rate_radps_y", "angular_rate_radps_z")
_DEG = math.pi / 180.0


class ImuBias(MeasurementEffect):
    """``imu_bias`` -- constant sensor biases added to the readings::

        f_meas,k = f_k + accel_bias_k      [m/s^2]
        w_meas,k = w_k + gyro_bias_k       [rad/s]      k = x, y, z

    Defaults 0.05 m/s^2 on each accelerometer axis and 0.1 deg/s (1.745e-3 rad/s) on each gyro
    axis (a consumer MEMS IMU after turn-on calibration). Regressors: d(field)/d(bias) = 1."""

    name = "imu_bias"
    FIELDS = _F + _W
    PARAMS = tuple(ParamSpec(f"accel_bias_{a}_mps2", "m/s^2", 0.05, f"accelerometer {a} bias", -1.0, 1.0) for a in "xyz") \
        + tuple(ParamSpec(f"gyro_bias_{a}_radps", "rad/s", 0.1 * _DEG, f"gyroscope {a} bias", -0.05, 0.05) for a in "xyz")

    def apply(self, fields: Mapping[str, float], kin: ImuKinematics) -> dict[str, float]:
        out = dict(fields)
        v = self._values
        for a, fn, wn in zip("xyz", _F, _W):
            if fn in out:
                out[fn] = out[fn] + v[f"accel_bias_{a}_mps2"]
            if wn in out:
                out[wn] = out[wn] + v[f"gyro_bias_{a}_radps"]
        return out

    def regressors(self, kin: ImuKinematics) -> dict[str, dict[str, float]]:
        out = {fn: {f"accel_bias_{a}_mps2": 1.0} for a, fn in zip("xyz", _F)}
        out.update({wn: {f"gyro_bias_{a}_radps": 1.0} for a, wn in zip("xyz", _W)})
        return out


def lever_arm_matrix(omega, omega_dot) -> tuple[tuple[float, float, float], ...]:
    """A with A r = omega_dot x r + omega x (omega x r) (= [omega_dot x] + [omega x]^2)."""
    p, q, r = omega
    dp, dq, dr = omega_dot
    return ((-(q * q + r * r), p * q - dr, p * r + dq),
            (p * q + dr, -(p * p + r * r), q * r - dp),
            (p * r - dq, q * r + dp, -(p * p + q * q)))


class ImuLeverArm(MeasurementEffect):
    """``imu_lever_arm`` -- the IMU sits at r from the CG (rigid body kinematics)::

        f_imu = f_cg + omega_dot x r + omega x (omega x r)       [m/s^2]
        omega_imu = omega

    r = (lever_x_m, lever_y_m, lever_z_m), default (0.5, 0, 0): 0.5 m ahead of the CG. Linear in
    r: regressors d f_imu / d r = [omega_dot x] + [omega x]^2."""

    name = "imu_lever_arm"
    FIELDS = _F
    PARAMS = (ParamSpec("lever_x_m", "m", 0.5, "IMU x relative to the CG", -5.0, 5.0),
              ParamSpec("lever_y_m", "m", 0.0, "IMU y relative to the CG", -2.0, 2.0),
              ParamSpec("lever_z_m", "m", 0.0, "IMU z relative to the CG", -2.0, 2.0))

    def apply(self, fields: Mapping[str, float], kin: ImuKinematics) -> dict[str, float]:
        out = dict(fields)
        v = self._values
        r = (v["lever_x_m"], v["lever_y_m"], v["lever_z_m"])
        a = lever_arm_matrix(kin.angular_rate_radps, kin.angular_accel_radps2)
        for k, fn in enumerate(_F):
            if fn in out:
                out[fn] = out[fn] + a[k][0] * r[0] + a[k][1] * r[1] + a[k][2] * r[2]
        return out

    def regressors(self, kin: ImuKinematics) -> dict[str, dict[str, float]]:
        a = lever_arm_matrix(kin.angular_rate_radps, kin.angular_accel_radps2)
        return {fn: {"lever_x_m": a[k][0], "lever_y_m": a[k][1], "lever_z_m": a[k][2]}
                for k, fn in enumerate(_F)}
