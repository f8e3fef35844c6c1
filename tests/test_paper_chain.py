"""One drive through the real chain for the paper's experiments (vdps_hil.experiments.paper_chain):
the sensor noise scaling of the Table 2 runs."""

from __future__ import annotations

import pytest

from vdps_hil.experiments import paper_chain as P
from vdps_hil.sim.profiles import load_profile

PROFILE = "table1-susp1k"


def test_scale_noise_scales_every_sigma_and_zero_is_the_zero_noise_profile():
    prof = load_profile(PROFILE)
    assert P.scale_noise(prof, 0.0) == prof.zero_noise()
    k = 3.0
    s = P.scale_noise(prof, k)
    assert s.gnss.pos_sigma_h_m == pytest.approx(k * prof.gnss.pos_sigma_h_m)
    assert s.gnss.attitude_sigma_rad == pytest.approx(k * prof.gnss.attitude_sigma_rad)
    assert s.imu.gyro_sigma_radps == pytest.approx(k * prof.imu.gyro_sigma_radps)
    assert s.suspension.sigma_m == pytest.approx(k * prof.suspension.sigma_m)
    assert s.tachometer.sigma_radps == pytest.approx(k * prof.tachometer.sigma_radps)
    assert s.imu.rate_hz == prof.imu.rate_hz and s.suspension.rate_hz == prof.suspension.rate_hz
