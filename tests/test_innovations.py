"""The strapdown innovations: GNSS noise on a correct drive, and an IMU bias's columns."""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.model.effects import make_effect
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import innovations as I
from vdps_hil.workbench.dataset import load_drive
from vdps_hil.experiments.workbench_study import cached_drive

VEH = load_vehicle("sedan-model")


@pytest.fixture(scope="module")
def drive(drive_cache):
    """The step steer of test_residuals (seed 5) and its table, as (table, None, None)."""
    path = cached_drive(drive_cache, "step-steer", (), seed=5)
    return load_drive(path, VEH), None, None


def test_innovations_are_gnss_noise_and_see_an_imu_bias(drive):
    tab, _, _ = drive
    inn = I.compute_innovations(tab)
    assert len(inn) > 300
    y = inn.values / inn.sigma
    n = inn.nuisance / inn.sigma[:, None]
    th = np.linalg.lstsq(n, y, rcond=None)[0]
    r = y - n @ th
    assert np.sqrt(np.mean(r * r)) < 1.5
    eff = make_effect("imu_bias")
    names = ["accel_bias_x_mps2", "gyro_bias_z_radps"]
    cols = inn.effect_columns(eff, names)
    # an x accelerometer bias b: the ENU velocity error is b times the integral of the body x
    # axis in ENU, (cos psi, sin psi) for a level car (d e / d b, minus: the innovation falls)
    t, psi = tab.t_s, tab["yaw_g_rad"]
    ie = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(psi[1:]) + np.cos(psi[:-1])) * np.diff(t))])
    i_n = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(psi[1:]) + np.sin(psi[:-1])) * np.diff(t))])
    t0 = inn._ctx["t"][0]  # the strapdown's start
    for ch, integral in ((3, ie), (4, i_n)):
        m = inn.channel == ch
        exp = np.interp(inn.t_s[m], t, integral) - np.interp(t0, t, integral)
        assert np.max(np.abs(-cols[m, 0] - exp)) < 0.05 * np.max(np.abs(exp)) + 0.05
    # a yaw gyro bias: the yaw error grows as the time since the start
    att_yaw = inn.channel == 2
    assert np.max(np.abs(cols[att_yaw, 1])) == pytest.approx((inn.t_s[att_yaw] - t0).max(), rel=0.05)
    assert np.all(cols[att_yaw, 1] <= 1e-9)  # the bias is in the readings: the innovation falls
