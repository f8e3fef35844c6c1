"""vdps_hil.realdata.reference without the real data: dead reckoning, constant velocity and the lag
estimators."""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.realdata.containers import Reference
from vdps_hil.realdata.reference import constant_velocity, dead_reckoning, estimate_lag, velocity_lag


def test_dead_reckoning_on_a_circle_and_constant_velocity():
    t = np.linspace(0.0, 10.0, 2001)
    w = 0.1
    tt, sp, crs, p = dead_reckoning(t, np.full_like(t, 10.0), np.full_like(t, w), np.zeros(2), 0.0, 0.0, 10.0)
    exact = np.array([100.0 * math.sin(w * 10.0), 100.0 * (1.0 - math.cos(w * 10.0))])
    assert np.allclose(p[-1], exact, atol=1e-3) and math.isclose(crs[-1], 1.0, abs_tol=1e-9)
    assert np.allclose(constant_velocity([1.0, 2.0, 0.0], [3.0, 0.0, 0.0], 5.0, [7.0]), [[7.0, 2.0, 0.0]])


def test_lag_estimators():
    t = np.arange(0.0, 60.0, 0.25)
    p = np.column_stack([np.cumsum(np.full_like(t, 2.5)) + 10 * np.sin(t / 5), 20 * np.cos(t / 7), np.zeros_like(t)])
    v_true = np.column_stack([np.gradient(p[:, 0], t), np.gradient(p[:, 1], t), np.zeros_like(t)])
    late = np.column_stack([np.interp(t - 0.1, t, v_true[:, k]) for k in range(3)])
    from vdps_hil.geodesy import DEFAULT_ORIGIN
    assert math.isclose(velocity_lag(Reference(t, DEFAULT_ORIGIN, p, late)), 0.1, abs_tol=0.011)
    x = np.sin(t)
    assert math.isclose(estimate_lag(t, np.sin(t - 0.15), t, x, np.arange(0, 0.3, 0.01)), 0.15, abs_tol=1e-9)
