"""Tests of vdps_hil.estimation.aiding_monitor: the inflate-and-accept rule after a run of gated
aiding updates (it cannot lock the filter out: shown on a real MultiRateEKF whose position is
10 m off with a 0.1 m sigma), the consistency window, and ``health``."""

from __future__ import annotations

import numpy as np

from vdps_hil.estimation.aiding_monitor import AidingChecks, AidingMonitor, health
from vdps_hil.estimation.ekf import MultiRateEKF, UpdateResult
from vdps_hil.estimation.imu_monitor import ImuMonitor
from vdps_hil.estimation.observations import ObsKind
from vdps_hil.estimation.states import States

MS = 1_000_000


def _res(kind, t_ms, status, nu=(0.1, 0.1, 0.1), nis=1.0):
    return UpdateResult(kind, t_ms * MS, status, tuple(nu), (1.0,) * len(nu), nis, len(nu), 21.1)


def test_a_filter_locked_out_by_its_gate_is_let_back_in():
    """Position 10 m off with sigma 0.1 m: the 1 m fixes are gated (NIS ~ 5000); after the third
    the monitor inflates by the innovation and the same fix is accepted: the error falls to the
    fix's level. Without the rule, every fix would be gated for ever."""
    ekf = MultiRateEKF()
    n = ekf.layout.n
    P0 = np.eye(n) * 1e-4
    P0[0, 0] = P0[1, 1] = P0[2, 2] = 0.01
    ekf.initialize(0, np.zeros(n), P0)
    mon = AidingMonitor()
    R = np.eye(3)
    z = np.array([10.0, 0.0, 0.0])
    for k in range(1, 3):
        res = ekf.update(ObsKind.GNSS_POS, z, R, k * 200 * MS)
        assert res.status == "gated" and not mon.observe(res)
        assert not mon.consistent(k * 200 * MS)
    res = ekf.update(ObsKind.GNSS_POS, z, R, 600 * MS)
    assert res.status == "gated" and mon.observe(res)
    xf, pf = ekf.full_state()
    a = mon.inflation(res, xf, pf)
    assert set(a) == {States.X_G, States.Y_G, States.Z_G}
    assert a[States.X_G][1] >= abs(res.innovation[0])
    assert ekf.reacquire(600 * MS, a)
    again = ekf.update(ObsKind.GNSS_POS, z, R, 600 * MS)
    assert again.status == "accepted"
    mon.observe(again)
    assert abs(ekf.x[0] - 10.0) < 1.0
    assert mon.inflations == 1


def test_consistency_returns_once_the_large_innovations_have_left_the_window():
    """Window of 3 updates of 3 dof: consistent while sum NIS <= chi2_0.999(9) = 27.9."""
    mon = AidingMonitor(AidingChecks(window=3))
    k = ObsKind.GNSS_ATT
    for t in (0, 200, 400):
        mon.observe(_res(k, t, "accepted"))
    assert mon.consistent(400 * MS)
    mon.observe(_res(k, 600, "gated", nis=22.0))  # a marginal gating among small ones: 24 <= 27.9
    assert mon.consistent(600 * MS)
    mon.observe(_res(k, 700, "gated", nis=400.0))  # a large innovation: the state is off
    assert not mon.consistent(700 * MS)
    for i, t in enumerate((800, 1000, 1200)):
        mon.observe(_res(k, t, "accepted"))
        assert mon.consistent(t * MS) == (i == 2)


def test_accepted_but_too_large_innovations_are_inconsistent():
    mon = AidingMonitor(AidingChecks(window=3))
    for t in (0, 200, 400):  # NIS 12 each (3 dof): each under the gate, together far above chi2(9)
        mon.observe(_res(ObsKind.GNSS_POS, t, "accepted", nis=12.0))
    assert not mon.consistent(400 * MS)


def test_a_kind_that_stopped_updating_does_not_decide():
    mon = AidingMonitor(AidingChecks(stale_s=1.0))
    mon.observe(_res(ObsKind.GNSS_VEL, 0, "gated", nu=(0.5, 0.01), nis=100.0))
    assert not mon.consistent(500 * MS)
    assert mon.consistent(1500 * MS)  # a GNSS outage: the IMU alone decides then


def test_other_kinds_and_statuses_are_ignored():
    mon = AidingMonitor()
    assert not mon.observe(_res(ObsKind.Y1_SUS, 0, "gated", nu=(1.0, 1.0)))
    assert not mon.observe(_res(ObsKind.GNSS_POS, 0, "too_old"))
    assert mon.consistent(0)


def test_health_names_the_reason():
    imu, aid = ImuMonitor(), AidingMonitor()
    g = (0.0, 0.0, 9.81)
    for k in range(100):
        imu.check(k * MS, g, (0.0, 0.0, 0.0))
    assert health(imu, aid, 99 * MS) is None
    assert health(imu, aid, 500 * MS) == "imu_missing"
    imu.check(600 * MS, g, (0.0, 0.0, 0.0))  # back: a fault that has just ended
    assert health(imu, aid, 600 * MS) == "imu_fault"
    for k in range(601, 1200):
        imu.check(k * MS, g, (0.0, 0.0, 0.0))
    aid.observe(_res(ObsKind.GNSS_POS, 1199, "gated", nis=200.0))
    assert health(imu, aid, 1199 * MS) == "inconsistent"
