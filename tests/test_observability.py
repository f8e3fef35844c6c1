"""Numerical observability rank: known rank-deficient systems, and the EKF's linearisation over
10 s of the synthetic manoeuvre (paper sensor set: rank 11 of 11; no suspension sensors:
phi_r and theta_r unobservable; single antenna at standstill without lever arm: yaw)."""

import dataclasses

import numpy as np

from vdps_hil.experiments import synthetic as syn
from vdps_hil.estimation.ekf import MultiRateEKF
from vdps_hil.estimation.ekf_config import EkfConfig, SensorSet
from vdps_hil.estimation.observability import ObservabilityWindow, observability_rank
from vdps_hil.estimation.observations import ObsKind
from vdps_hil.model.params import load_vehicle
from vdps_hil.units import GRAVITY_MPS2

VEH = load_vehicle("sedan-model")
SIG0 = np.array([2.0, 2.0, 4.0, 1.0, 1.0, 1.0, 0.02, 0.02, 0.02, 0.05, 0.05, 0.05])


def test_rank_of_known_matrices():
    names = ("a", "b", "c")
    r = observability_rank([np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])], names)
    assert r.rank == 2 and r.unobservable == ("c",) and not r.full_rank
    assert r.participation["c"] > 0.99
    r = observability_rank([np.eye(3)], names)
    assert r.rank == 3 and r.unobservable == () and r.full_rank
    # a combination (a - b) unobservable: both take part with 0.5 -> not above the threshold
    r = observability_rank([np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])], names)
    assert r.rank == 2 and abs(r.participation["a"] - 0.5) < 1e-12
    assert observability_rank([], names).rank == 0


def test_constant_velocity_position_vs_velocity_measurements():
    """x' = v: measuring position over two epochs observes both; measuring v alone does not
    observe x."""
    phi = np.eye(2) + np.array([[0.0, 0.1], [0.0, 0.0]])
    win = ObservabilityWindow(("x", "v"))
    win.on_update(np.array([[1.0, 0.0]]), np.array([[1.0]]))
    win.on_predict(phi)
    win.on_update(np.array([[1.0, 0.0]]), np.array([[4.0]]))
    assert win.report().rank == 2
    win.restart()
    win.on_update(np.array([[0.0, 1.0]]), np.array([[1.0]]))
    win.on_predict(phi)
    win.on_update(np.array([[0.0, 1.0]]), np.array([[1.0]]))
    rep = win.report()
    assert rep.rank == 1 and rep.unobservable == ("x",)


def _window_over_manoeuvre(config, seconds=10.0):
    data = syn.make_sensor_data(syn.Maneuver(duration_s=seconds), VEH, seed=3)
    ekf = MultiRateEKF.from_vehicle(VEH, config)
    x0, p0 = syn.initial_state(data.maneuver, ekf.layout, 0.0, SIG0, np.random.default_rng(3))
    ekf.initialize(0, x0, p0)
    win = ObservabilityWindow.for_layout(ekf.layout).attach(ekf)
    syn.drive_ekf(ekf, data, VEH)
    return win.report()


def test_paper_sensor_set_is_fully_observable():
    rep = _window_over_manoeuvre(EkfConfig())
    assert rep.n_states == 11 and rep.rank == 11 and rep.unobservable == ()
    assert set(rep.to_json()) >= {"rank", "unobservable", "singular_values"}


def test_road_angles_unobservable_without_suspension():
    rep = _window_over_manoeuvre(EkfConfig(sensors=SensorSet(suspension=False), estimate_road=True))
    assert rep.rank == 9 and set(rep.unobservable) == {"phi_r_rad", "theta_r_rad"}


def test_yaw_unobservable_at_standstill_with_single_antenna():
    veh = dataclasses.replace(VEH, mounting=dataclasses.replace(VEH.mounting, gnss_lever_arm_m=(0.0, 0.0, 0.0)))
    ekf = MultiRateEKF.from_vehicle(veh, EkfConfig(sensors=SensorSet(gnss="single_antenna", suspension=False),
                                                   use_gnss_velocity=False))
    ekf.initialize(0, np.zeros(9), np.eye(9))
    win = ObservabilityWindow.for_layout(ekf.layout).attach(ekf)
    ekf.set_input([0.0, 0.0, GRAVITY_MPS2], [0.0, 0.0, 0.0])
    for k in range(1, 51):
        ekf.predict_to(k * 200_000_000)
        ekf.update(ObsKind.GNSS_POS, np.zeros(3), np.diag([1.0, 1.0, 9.0]))
    rep = win.report()
    assert rep.unobservable == ("psi_g_rad",) and rep.rank == 8


def test_whitened_rows_are_chol_of_r_inverse_for_repeated_and_new_noise(rng):
    """Each update's rows are chol(R^-1)^T H Phi: whether R repeats (the whitener is kept by the
    matrix's bytes) or changes, in place or not, the blocks equal the formula to the last bit."""
    win = ObservabilityWindow([f"s{i}" for i in range(4)])
    r1 = np.diag([0.5, 2.0])
    r2 = np.array([[1.0, 0.3], [0.3, 0.8]])
    hs = [rng.normal(size=(2, 4)) for _ in range(5)]
    rs = [r1, r2, r1.copy(), r2, r1]
    for h, r in zip(hs, rs):
        win.on_predict(np.eye(4) + 0.01 * rng.normal(size=(4, 4)))
        phi = win._phi.copy()
        win.on_update(h, r)
        want = np.linalg.cholesky(np.linalg.inv(r)).T @ h @ phi
        assert np.array_equal(win._blocks[-1], want)
    r1[0, 0] = 5.0  # the caller reuses its array with new noise: a new whitener
    win.on_update(hs[0], r1)
    assert np.array_equal(win._blocks[-1], np.linalg.cholesky(np.linalg.inv(r1)).T @ hs[0] @ win._phi)
