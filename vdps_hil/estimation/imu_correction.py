"""Streaming removal of identified IMU measurement effects (a bias, a lever arm) before the
estimator, so a model saved by the workbench (``vdps diagnose --add imu_bias --save-model``)
corrects the readings in ``vdps replay``, ``vdps bench`` and ``vdps log --pipeline``.

A measurement effect maps the reading at the CG to what the sensor reports,
``m = h(f, kin)`` (``model.effects.imu``). To first order around the reading,

    f_corr = m - (h(m, kin) - m)                                            (1)

exact for the additive biases and for the lever arm (whose term does not depend on f). The
kinematics ``kin`` need the angular rate and the angular acceleration. Causally, from the
gyro readings w_k at times t_k (what the sensor gives; no look-ahead, unlike the workbench's
zero-phase batch smoother):

    w_s,k = w_s,k-1 + a (w_k - w_s,k-1),     a = 1 - exp(-2 pi f_c dt)      (2)
    wdot_k = (w_s,k - w_s,k-1) / dt                                          (3)

a first-order low-pass at f_c (default 10 Hz) and the derivative of its output: a band-limited
derivative lagging the true omega_dot by about 1 / (2 pi f_c) = 16 ms. The gyro fields of the
kinematics are themselves corrected first when a gyro bias is among the effects (the bias is
removed from w before (2)).

Symbols: m measured fields (catalogue names, SI), f corrected, w [rad/s], wdot [rad/s^2],
dt [s] between IMU samples (gaps > ``max_gap_s`` restart the filter), f_c [Hz].

A steering-sensor effect of the model (``steering_offset``) is taken out of the ``steer``
samples the same way, r - (e(r) - r) (``model.effects.steering.steer_corrected``; exact for an
offset): the estimator's wheel-speed row and the identifier's slip angles read the steering.
"""

from __future__ import annotations

import math
from typing import Sequence

from vdps_hil.bus.samples import Sample
from vdps_hil.model.effects.base import ImuKinematics, MeasurementEffect
from vdps_hil.model.effects.steering import STEER_FIELD, steer_corrected, steering_effects

__all__ = ["ImuEffectCorrection"]

_F = ("specific_force_mps2_x", "specific_force_mps2_y", "specific_force_mps2_z")
_W = ("angular_rate_radps_x", "angular_rate_radps_y", "angular_rate_radps_z")


class ImuEffectCorrection:
    """Sample node: ``process(sample)`` returns the IMU sample with the effects removed (eq 1),
    every other sample unchanged. Pure apart from its filter state; one per IMU stream."""

    def __init__(self, effects: Sequence[MeasurementEffect], cutoff_hz: float = 10.0, max_gap_s: float = 0.1,
                 kind: str = "imu"):
        meas = [e for e in effects if isinstance(e, MeasurementEffect)]
        self._steer = tuple(steering_effects(meas))  # out of the steering samples (r - (e(r) - r))
        self.effects = tuple(e for e in meas if e not in self._steer)
        if not (math.isfinite(cutoff_hz) and cutoff_hz > 0):
            raise ValueError("cutoff_hz must be positive")
        self.cutoff_hz = float(cutoff_hz)
        self.max_gap_s = float(max_gap_s)
        self.kind = kind
        self._t_ns: int | None = None
        self._ws: tuple[float, float, float] | None = None
        self._wd = (0.0, 0.0, 0.0)
        self.corrected = 0

    def _gyro(self, fields) -> tuple[float, float, float] | None:
        if not all(n in fields for n in _W):
            return None
        w = {n: float(fields[n]) for n in _W}
        zero = ImuKinematics(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        for e in self.effects:  # rate effects are additive (a bias): remove them before (2)
            if any(n in e.FIELDS for n in _W):
                applied = e.apply(w, zero)
                w = {n: w[n] - (applied[n] - w[n]) for n in _W}
        return tuple(w[n] for n in _W)

    def process(self, sample: Sample) -> Sample:
        if self._steer and sample.kind == "steer" and sample.valid and STEER_FIELD in sample.fields:
            f = dict(sample.fields)
            f[STEER_FIELD] = steer_corrected(f[STEER_FIELD], self._steer)
            return Sample(sample.t_ns, sample.source, sample.kind, f, sample.wall_time_ns, sample.valid)
        if not self.effects or sample.kind != self.kind or not sample.valid:
            return sample
        f0 = sample.fields
        w = self._gyro(f0)
        if w is not None:
            dt = None if self._t_ns is None else (sample.t_ns - self._t_ns) * 1e-9
            if dt is None or not (0.0 < dt <= self.max_gap_s) or self._ws is None:
                self._ws, self._wd = w, (0.0, 0.0, 0.0)
            elif dt > 0.0:
                a = 1.0 - math.exp(-2.0 * math.pi * self.cutoff_hz * dt)
                ws = tuple(p + a * (x - p) for p, x in zip(self._ws, w))
                self._wd = tuple((n - p) / dt for n, p in zip(ws, self._ws))
                self._ws = ws
            self._t_ns = sample.t_ns
        om = self._ws if self._ws is not None else (0.0, 0.0, 0.0)
        kin = ImuKinematics(sample.t_ns * 1e-9, tuple(float(f0.get(n, 0.0)) for n in _F), om, self._wd)
        corr = dict(f0)
        for e in self.effects:
            applied = e.apply(f0, kin)
            for k, v in applied.items():
                if k in f0:
                    corr[k] = corr[k] - (v - f0[k])
        self.corrected += 1
        return Sample(sample.t_ns, sample.source, sample.kind, corr, sample.wall_time_ns, sample.valid)
