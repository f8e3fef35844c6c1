"""Measurement builders: eq 5's suspension measurement and the y2_gps measurement, their
covariances against Monte Carlo (10 %), and the z_r rate builder of correction (c)."""

import math

import numpy as np
import pytest

from vdps_hil.estimation.measurements import (ZrRateBuilder, suspension_body_rates, suspension_measurement,
                                              y2_gps_measurement)
from vdps_hil.model import frames as fr
from vdps_hil.model.params import load_vehicle

VEH = load_vehicle("sedan-model")
GEO = VEH.geometry


def test_suspension_measurement_is_eq5_and_covariance_matches_monte_carlo(rng):
    h = np.array([0.02, -0.01, 0.015, -0.005])
    sm = suspension_measurement(h, GEO.l_f_m, GEO.l_r_m, GEO.track_half_front_m, GEO.track_half_rear_m, 0.001)
    z_r, th, ph = fr.suspension_to_road_attitude(h, GEO.l_f_m, GEO.l_r_m, GEO.track_half_front_m, GEO.track_half_rear_m)
    assert abs(sm.z_r_m - z_r) < 1e-15 and abs(sm.theta_v_rad - th) < 1e-15 and abs(sm.phi_v_rad - ph) < 1e-15
    np.testing.assert_allclose(sm.y1, [math.sin(th), math.sin(ph) * math.cos(th)], atol=1e-15)
    samples = h + rng.normal(0, 0.001, (40000, 4))
    ys = np.array([suspension_measurement(s, GEO.l_f_m, GEO.l_r_m, GEO.track_half_front_m,
                                          GEO.track_half_rear_m, 0.001).y1 for s in samples[:4000]])
    cov = np.cov(ys.T)
    np.testing.assert_allclose(np.diag(cov), np.diag(sm.r_y1), rtol=0.1)
    assert abs(cov[0, 1]) < 0.1 * math.sqrt(cov[0, 0] * cov[1, 1])
    zr = (-GEO.l_r_m * (samples[:, 0] + samples[:, 1])
          - GEO.l_f_m * (samples[:, 2] + samples[:, 3])) / (2 * GEO.wheelbase_m)
    assert abs(zr.var() / sm.var_z_r_m2 - 1.0) < 0.1


def test_y2_gps_covariance_matches_monte_carlo(rng):
    th, psi, s = 0.1, 0.7, 0.007
    z, r = y2_gps_measurement(th, psi, s, s, floor=0.0)
    r_default = y2_gps_measurement(th, psi, s, s)[1]
    np.testing.assert_allclose(r_default - r, s * s * np.eye(2), atol=1e-18)  # isotropic floor = sigma
    a = np.array([th, psi]) + rng.normal(0, s, (20000, 2))
    zs = np.stack([np.cos(a[:, 0]) * np.cos(a[:, 1]), np.cos(a[:, 0]) * np.sin(a[:, 1])], axis=1)
    np.testing.assert_allclose(np.cov(zs.T), r, atol=0.1 * s * s)
    np.testing.assert_allclose(zs.mean(0), z, atol=1e-3)


def test_zr_rate_builder():
    b = ZrRateBuilder(min_baseline_s=0.5, max_baseline_s=3.0, heave_rate_sigma_mps=0.05)
    assert b.push(0, 0.0, 1e-6) is None
    assert b.push(200_000_000, 0.001, 1e-6) is None  # baseline 0.2 s < 0.5 s
    z, r = b.push(1_000_000_000, 0.01, 1e-6)  # baseline to t = 0.2 s is 0.8 s
    assert abs(z[0] - (0.01 - 0.001) / 0.8) < 1e-12
    assert abs(r[0, 0] - (2e-6 / 0.64 + 0.05 ** 2)) < 1e-15
    assert b.push(10_000_000_000, 0.0, 1e-6) is None  # everything older than 3 s dropped
    with pytest.raises(ValueError):
        ZrRateBuilder(min_baseline_s=1.0, max_baseline_s=0.5)


@pytest.mark.parametrize("hd", [(0.05, -0.02, 0.03, 0.01), (-0.1, 0.1, 0.1, -0.1), (0.0, 0.0, 0.2, 0.2)])
def test_suspension_body_rates_are_the_time_derivative_of_eq_5(hd):
    """The roll and pitch rates from the deflection rates equal the finite difference of eq 5's
    angles over 1 ms at small angles (tolerance 1e-4 rad/s: eq 5's arcsine over 1 ms)."""
    g = VEH.geometry
    args = (g.l_f_m, g.l_r_m, g.track_half_front_m, g.track_half_rear_m, 0.001)
    h0 = np.array([0.01, -0.005, 0.0, 0.004])
    dt = 1e-3
    a = suspension_measurement(h0, *args)
    b = suspension_measurement(h0 + dt * np.array(hd), *args)
    roll_rate, pitch_rate = suspension_body_rates(hd, *args[:4])
    assert roll_rate == pytest.approx((b.phi_v_rad - a.phi_v_rad) / dt, abs=1e-4)
    assert pitch_rate == pytest.approx((b.theta_v_rad - a.theta_v_rad) / dt, abs=1e-4)
