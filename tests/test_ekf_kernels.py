"""The EKF's compiled predict kernels (``estimation.ekf_kernels``) equal their numpy reference
(``kinematics``, ``states.StateLayout.expand``, ``ekf_reference.propagate_reference``) within
1e-12 of the largest element, on random states of every layout, and bit-equal to their own
Python form (run with ``VDPS_JIT=0``)."""

import math

import numpy as np
import pytest

from kernel_checks import run_compiled, run_pure_python, same_bits
from vdps_hil.estimation import ekf_kernels as K
from vdps_hil.estimation import kinematics as kin
from vdps_hil.estimation.ekf_config import EkfConfig, SensorSet
from vdps_hil.estimation.ekf_reference import propagate_reference
from vdps_hil.estimation.states import StateLayout

TOL = 1e-12
LAYOUTS = [StateLayout(), StateLayout.paper(), StateLayout(road_estimated=False),
           StateLayout(gyro_bias_axes=(0, 1, 2), accel_bias_axes=(0, 1, 2), wheel_scale=True),
           EkfConfig(sensors=SensorSet(imu="esc3"), gyro_bias=True, accel_bias=True).layout()]


def close(a, b, tol=TOL) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and float(np.abs(a - b).max(initial=0.0)) <= tol * max(1.0, float(np.abs(b).max()))


def _angles(rng):
    return rng.uniform(-0.5, 0.5, 5) * np.array([1.0, 1.0, 6.0, 0.2, 0.2])


def test_geometry_equals_the_reference(rng):
    for _ in range(20):
        a = _angles(rng)
        gv = np.empty((4, 3, 3))
        K.dcm_gv_partials_k(a[0], a[1], a[2], gv)
        assert close(gv, np.array(kin.dcm_gv_partials(a[0], a[1], a[2])))
        gr = np.empty((3, 3, 3))
        K.dcm_gr_partials_k(a[3], a[4], gr)
        assert close(gr, np.array(kin.dcm_gr_partials(a[3], a[4])))
        rn = np.empty((3, 3))
        K.road_normal_k(a[3], a[4], rn)
        assert close(rn, np.array(kin.road_normal(a[3], a[4])))
        ang, jac = np.empty(3), np.empty((3, 5))
        K.vehicle_angles_eq4_k(*a, ang, jac)
        ang_r, jac_r = kin.vehicle_angles_eq4(a)
        assert close(ang, ang_r) and close(jac, jac_r)


def _state(rng, layout):
    x = np.zeros(layout.n)
    full = np.concatenate([rng.normal(0, 50, 3), rng.normal(0, 10, 3), _angles(rng), [0.0],
                           rng.normal(0, 0.01, 7)])
    for j, s in enumerate(layout.full_index):
        x[j] = full[s]
    a = rng.normal(size=(layout.n, layout.n))
    return x, a @ a.T * 1e-3 + 1e-4 * np.eye(layout.n)


@pytest.mark.parametrize("layout", LAYOUTS, ids=lambda lay: f"n{lay.n}")
def test_expand_step_and_linearize_equal_the_reference(layout, rng):
    idx, pos, flags, _ = K.layout_arrays(layout)
    for _ in range(5):
        x, _ = _state(rng, layout)
        xe, E = np.empty(K.N_EXT), np.empty((K.N_EXT, layout.n))
        K.expand_k(x, idx, pos, flags, xe, E)
        xr, Er = layout.expand(x, ext=True)
        assert close(xe, xr) and close(E, Er)
        f, w = rng.normal(0, 3, 3) + [0.0, 0.0, 9.8], rng.normal(0, 0.3, 3)
        out = np.empty(12)
        K.step_k(xe, f, w, 0.01, 9.80665, out)
        assert close(out, kin.step(xe[:12], f, w, 0.01, 9.80665))
        F, G = np.empty((12, 12)), np.empty((12, 6))
        K.linearize_k(xe, f, w, F, G)
        Fr, Gr = kin.linearize(xe[:12], f, w)
        assert close(F, Fr) and close(G, Gr)


def _propagate_args(layout, rng):
    idx, _, flags, yaw = K.layout_arrays(layout)
    x, P = _state(rng, layout)
    x[list(yaw)] = 3.14  # near the wrap
    f, w = rng.normal(0, 3, 3) + [0.0, 0.0, 9.8], rng.normal(0, 0.5, 3)
    q_in = np.array([4e-7, 4e-7, 4e-7, 2e-9, 2e-9, 2e-9])
    q_rw = rng.uniform(0, 1e-6, layout.n)
    return (x, P, idx, flags, yaw, f, w, 0.01, 9.80665, q_in, q_rw, np.empty((layout.n, layout.n)))


@pytest.mark.parametrize("layout", LAYOUTS, ids=lambda lay: f"n{lay.n}")
def test_propagate_equals_the_reference(layout, rng):
    for _ in range(5):
        args = _propagate_args(layout, rng)
        x, P, idx, flags, yaw, f, w, dt, g, q_in, q_rw, phi = args
        xr, Pr, phir = propagate_reference(layout, x.copy(), P.copy(), f, w, dt, g, q_in, np.diag(q_rw), list(yaw))
        assert K.propagate(*args)
        assert close(x, xr) and close(P, Pr) and close(phi, phir)
        assert np.array_equal(P, P.T)
        assert all(-math.pi <= x[i] < math.pi for i in yaw)


def test_propagate_reports_a_non_finite_result(rng):
    args = list(_propagate_args(LAYOUTS[0], rng))
    args[5] = np.array([np.nan, 0.0, 9.8])
    assert not K.propagate(*args)


def test_compiled_predict_kernels_bit_equal_their_python_form(rng):
    calls = [("vdps_hil.estimation.ekf_kernels", "propagate", _propagate_args(lay, rng)) for lay in LAYOUTS]
    a = _angles(rng)
    calls.append(("vdps_hil.estimation.ekf_kernels", "vehicle_angles_eq4_k", (*a, np.empty(3), np.empty((3, 5)))))
    for (r1, a1), (r2, a2) in zip(run_pure_python(calls), run_compiled(calls)):
        assert r1 == r2 and same_bits(a1, a2)
