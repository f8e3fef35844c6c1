"""vdps_hil.realdata.steering without the real data: the steady-state steering fit on a known
bicycle."""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.realdata.steering import steer_response_fit


def test_steer_response_fit_recovers_a_known_bicycle(rng):
    L, sr, k, off = 2.65, 15.0, 0.004, math.radians(0.3)
    t = np.arange(0.0, 120.0, 0.05)
    u = 10.0 + 8.0 * np.sin(2 * math.pi * t / 120.0) ** 2
    sw = math.radians(20.0) * np.sin(2 * math.pi * t / 7.0) + off
    r = u * (sw - off) / (sr * (L + k * u * u))
    bias = math.radians(0.3)
    fit = steer_response_fit(t, u, sw + rng.normal(0.0, 1e-4, t.shape), r + bias, r + rng.normal(0.0, 1e-4, t.shape),
                             wheelbase_m=L, understeer0=k, prior_steer_ratio=16.0)
    print(f"\nknown bicycle s_R {sr}, x 1, offset 0.3 deg -> {fit.steer_ratio:.2f} +- {fit.steer_ratio_sigma:.2f}, "
          f"{fit.stiffness_factor:.3f} +- {fit.stiffness_factor_sigma:.3f}, {fit.angle_offset_deg:.3f} deg")
    assert abs(fit.steer_ratio - sr) < max(3 * fit.steer_ratio_sigma, 0.05)
    assert abs(fit.stiffness_factor - 1.0) < max(3 * fit.stiffness_factor_sigma, 0.01)
    assert abs(fit.angle_offset_deg - 0.3) < max(3 * fit.angle_offset_sigma_deg, 0.005)
    assert math.isclose(fit.yaw_rate_bias_degps, 0.3, abs_tol=0.01)
    assert all(fit.observable().values())
    # one speed only: s_R L and s_R K_us are no longer separable
    fit2 = steer_response_fit(t, np.full_like(t, 15.0), sw, 15.0 * (sw - off) / (sr * (L + k * 225.0)),
                              15.0 * (sw - off) / (sr * (L + k * 225.0)), wheelbase_m=L, understeer0=k,
                              prior_steer_ratio=16.0)
    assert not fit2.observable()["understeer_x_steer_ratio"]
    assert any(e.names[:2] == ("steer_ratio_x_wheelbase", "understeer_x_steer_ratio") for e in fit2.explanations)
