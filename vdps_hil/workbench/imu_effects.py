"""IMU readings with measurement effects taken out, before the estimator runs.

Measurement effects can be taken out before the estimator runs (``imu_effects``): each IMU
sample is replaced by the reading with the effect removed to first order, f = f_meas - (apply(f_meas)
- f_meas) (exact for the additive biases and the lever arm), with the rigid-body kinematics
from the smoothed gyro. The workbench uses this to re-estimate with an identified sensor effect.
"""

from __future__ import annotations

import bisect
from typing import Iterable, Iterator, Sequence

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.model.effects.base import ImuKinematics, MeasurementEffect
from vdps_hil.model.effects.steering import STEER_FIELD, steer_corrected, steering_effects

from .streams import ANGULAR_RATE_FIELDS, SPECIFIC_FORCE_FIELDS, Smoother, stream, uniform

__all__ = ["remove_imu_effects", "gyro_track", "imu_corrected"]


def remove_imu_effects(samples: Sequence[Sample], effects: Sequence[MeasurementEffect],
                       cutoff_hz: float = 10.0) -> list[Sample]:
    """IMU samples with the measurement effects removed to first order (module docstring):
    f = f_meas - (apply(f_meas, kin) - f_meas); other samples unchanged."""
    return list(imu_corrected(samples, effects, gyro_track(samples, cutoff_hz)))


def gyro_track(samples: Iterable[Sample], cutoff_hz: float):
    """(t_base_ns, grid [s], smoothed rate, its derivative) of the gyro, or None (one pass)."""
    t_ns, w = stream(samples, "imu", ANGULAR_RATE_FIELDS)
    t_base = int(t_ns[0]) if len(t_ns) else 0
    tg, wg, rate = uniform(t_ns, w, t_base)
    if rate <= 0:
        return None
    ws = Smoother(cutoff_hz)(wg, rate)
    return t_base, tg, ws, np.gradient(ws, 1.0 / rate, axis=0)


class _Linear:
    """np.interp of every column at one point (the same formula, clamped at both ends), without
    numpy's per-call overhead: one IMU sample at a time."""

    def __init__(self, x: np.ndarray, y: np.ndarray):
        self.x = [float(v) for v in x]
        self.y = [tuple(float(c) for c in row) for row in y]

    def __call__(self, t: float) -> tuple:
        x, y = self.x, self.y
        j = bisect.bisect_right(x, t) - 1
        if j < 0:
            return y[0]
        if j >= len(x) - 1:
            return y[-1]
        x0, y0, y1 = x[j], y[j], y[j + 1]
        dx, d = x[j + 1] - x0, t - x0
        return tuple((b - a) / dx * d + a for a, b in zip(y0, y1))


def imu_corrected(samples: Iterable[Sample], effects: Sequence[MeasurementEffect], track) -> Iterator[Sample]:
    """The samples with the effects taken out of the IMU ones (``track``: :func:`gyro_track`;
    None: no gyro, the IMU samples pass unchanged) and the steering-sensor effects
    (``steering_offset``) out of the steering ones."""
    effects = [e for e in effects if isinstance(e, MeasurementEffect)]
    steer = steering_effects(effects)
    effects = [e for e in effects if e not in steer]
    if (not effects or track is None) and not steer:
        yield from samples
        return
    at = None
    if effects and track is not None:
        t_base, tg, ws, wd = track
        at = _Linear(tg, np.hstack([ws, wd]))
    for s in samples:
        if steer and s.kind == "steer" and s.valid and STEER_FIELD in s.fields:
            f = dict(s.fields)
            f[STEER_FIELD] = steer_corrected(f[STEER_FIELD], steer)
            yield Sample(s.t_ns, s.source, s.kind, f, s.wall_time_ns, s.valid)
            continue
        if at is None or s.kind != "imu" or not s.valid:
            yield s
            continue
        ts = (s.t_ns - t_base) * 1e-9
        v = at(ts)
        om, od = v[:3], v[3:]
        f0 = dict(s.fields)
        kin = ImuKinematics(ts, tuple(f0.get(n, 0.0) for n in SPECIFIC_FORCE_FIELDS), om, od)
        corr = dict(f0)
        for e in effects:
            applied = e.apply(f0, kin)
            for k, v in applied.items():
                if k in corr and k in f0:
                    corr[k] = corr[k] - (v - f0[k])
        yield Sample(s.t_ns, s.source, s.kind, corr, s.wall_time_ns, s.valid)
