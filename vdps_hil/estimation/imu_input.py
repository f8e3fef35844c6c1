"""The EKF's IMU input: an IMU sample -> specific force and angular rate in body axes at the CG,
and their mean over a predict interval.

Sensor mounting from the *model* vehicle file: the IMU rotation (body -> sensor, roll-pitch-yaw
of eq 1, f_b = C_bs^T f_s) and lever arm (f_cg = f_s - w_dot x l - w x (w x l), with w, w_dot
from the alpha-beta filters). ESC cluster (``SensorSet.imu == "esc3"``): the axes it does not
measure are substituted, w_x = w_y := 0, f_z := g. The filter predicts once per
``predict_period_s`` with the mean of the samples since the last predict (``MeanInput``; the
process noise of that mean: ``ekf_config`` module docstring).
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.bus.samples import axis_fields
from vdps_hil.model.frames import dcm_gv

_SF = axis_fields("specific_force_mps2")
_AR = axis_fields("angular_rate_radps")
_NAN = math.nan


class ImuMounting:
    """Body-axes IMU input from a sample's fields (module docstring)."""

    def __init__(self, mounting, esc3: bool, gravity_mps2: float):
        rot = np.asarray(mounting.imu_rotation_rpy_rad, dtype=float)
        # sensor -> body as plain floats (row-major 3 x 3)
        self._rot = None if not rot.any() else tuple(
            tuple(float(v) for v in row) for row in dcm_gv(rot[0], rot[1], rot[2]).T)
        arm = np.asarray(mounting.imu_lever_arm_m, dtype=float)
        self.lever_arm_m = None if not arm.any() else tuple(float(v) for v in arm)
        self._esc3 = esc3
        self._g = gravity_mps2

    def body_input(self, fields) -> tuple[list[float], list[float]] | None:
        """(f [m/s^2], w [rad/s]) in body axes at the sensor (ESC axes substituted); None when a
        value is missing or not finite."""
        g = fields.get
        if self._esc3:
            f = [g(_SF[0], _NAN), g(_SF[1], _NAN), self._g]
            w = [0.0, 0.0, g(_AR[2], _NAN)]
        else:
            f = [g(_SF[0], _NAN), g(_SF[1], _NAN), g(_SF[2], _NAN)]
            w = [g(_AR[0], _NAN), g(_AR[1], _NAN), g(_AR[2], _NAN)]
        if not math.isfinite(f[0] + f[1] + f[2] + w[0] + w[1] + w[2]):
            return None
        rot = self._rot
        if rot is not None:
            r0, r1, r2 = rot
            f = [r0[0] * f[0] + r0[1] * f[1] + r0[2] * f[2], r1[0] * f[0] + r1[1] * f[1] + r1[2] * f[2],
                 r2[0] * f[0] + r2[1] * f[1] + r2[2] * f[2]]
            w = [r0[0] * w[0] + r0[1] * w[1] + r0[2] * w[2], r1[0] * w[0] + r1[1] * w[1] + r1[2] * w[2],
                 r2[0] * w[0] + r2[1] * w[1] + r2[2] * w[2]]
        return f, w

    def at_cg(self, f, rate_radps, rate_dot_radps2) -> list[float]:
        """f_cg = f_s - w_dot x l - w x (w x l) in plain floats (hot path: once per IMU sample);
        axes the IMU lacks (NaN in the alpha-beta rates ``rate_radps``/``rate_dot_radps2``, an
        ESC cluster's x/y) count as 0. Only with a lever arm (``lever_arm_m`` not None)."""
        wx, wy, wz = (v if v - v == 0.0 else 0.0 for v in rate_radps)
        ax, ay, az = (v if v - v == 0.0 else 0.0 for v in rate_dot_radps2)
        lx, ly, lz = self.lever_arm_m
        ux, uy, uz = wy * lz - wz * ly, wz * lx - wx * lz, wx * ly - wy * lx  # w x l
        return [f[0] - (ay * lz - az * ly) - (wy * uz - wz * uy),
                f[1] - (az * lx - ax * lz) - (wz * ux - wx * uz),
                f[2] - (ax * ly - ay * lx) - (wx * uy - wy * ux)]


class MeanInput:
    """Sum of the IMU inputs since the last predict; ``take`` gives their mean."""

    __slots__ = ("_acc", "n")

    def __init__(self):
        self._acc = [0.0] * 6
        self.n = 0

    def add(self, f, w) -> None:
        a = self._acc
        a[0] += f[0]
        a[1] += f[1]
        a[2] += f[2]
        a[3] += w[0]
        a[4] += w[1]
        a[5] += w[2]
        self.n += 1

    def reset(self) -> None:
        self._acc = [0.0] * 6
        self.n = 0

    def take(self) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
        """(mean f, mean w) of the samples added since the last reset, and reset; None if none."""
        n = self.n
        if not n:
            return None
        a = self._acc
        f = (a[0] / n, a[1] / n, a[2] / n)
        w = (a[3] / n, a[4] / n, a[5] / n)
        self.reset()
        return f, w
