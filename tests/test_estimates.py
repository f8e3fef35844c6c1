"""Tests of vdps_hil.estimation.estimates: ``Estimate.from_filter`` against the numpy form of its
sigmas (sqrt(maximum(diag, 0)) of E P E^T and of the eq-4 angles' J P J^T), bit for bit."""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.estimation.estimates import Estimate
from vdps_hil.estimation.states import StateLayout


def _numpy_form(layout, x, P):
    xf, e, ang, jac = layout.expand_with_vehicle_angles(x)
    pf = e @ P @ e.T
    pa = jac @ pf[6:11, 6:11] @ jac.T
    return (tuple(xf.tolist()), tuple(np.sqrt(np.maximum(pf.diagonal(), 0.0)).tolist()), tuple(ang.tolist()),
            tuple(np.sqrt(np.maximum(pa.diagonal(), 0.0)).tolist()))


def _same(a, b) -> bool:
    return len(a) == len(b) and all(p == q or (math.isnan(p) and math.isnan(q)) for p, q in zip(a, b))


def test_from_filter_equals_the_numpy_form_bit_for_bit(rng):
    for layout in (StateLayout(), StateLayout(road_estimated=False), StateLayout.paper(),
                   StateLayout(gyro_bias_axes=(2,), accel_bias_axes=(0, 1))):
        n = layout.n
        for k in range(50):
            x = rng.normal(size=n) * 0.3
            a = rng.normal(size=(n, n))
            P = a @ a.T * 1e-3
            if k == 1:
                P[3, 3] = -1e-9  # a slightly negative variance: sigma 0
            if k == 2:
                P[4, :] = P[:, 4] = math.nan
            est = Estimate.from_filter(7, layout, x, P)
            ref = _numpy_form(layout, x, P)
            assert est.t_ns == 7
            for got, want in zip((est.x, est.sigma, est.vehicle_angles_rad, est.vehicle_angles_sigma_rad), ref):
                assert _same(got, want)
