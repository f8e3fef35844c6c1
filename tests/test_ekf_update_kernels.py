"""The EKF's compiled update kernels (``estimation.ekf_update_kernels``) equal their numpy
reference (the ``observations`` models, ``ekf_reference.update_reference``) within 1e-12 of the
largest element for every measurement kind (accepted, gated, rows of NaN, a singular S), and
bit-equal to their own Python form (``VDPS_JIT=0``) except where ``math.hypot`` enters
(gnss_vel: numba's hypot is the C library's, Python's its own; stated 1 ulp)."""

import math

import numpy as np
import pytest

from kernel_checks import run_compiled, run_pure_python, same_bits
from vdps_hil.estimation import ekf_update_kernels as U
from vdps_hil.estimation.ekf_kernels import layout_arrays
from vdps_hil.estimation.ekf_reference import update_reference
from vdps_hil.estimation.observations import ObsKind, make_models
from vdps_hil.estimation.states import StateLayout

TOL = 1e-12
LEVER, NHC = (1.2, -0.3, 0.9), (-1.4, 0.0, -0.55)
WHEELS = np.array([[1.3, 0.8, -0.25], [1.3, -0.8, -0.25], [-1.4, -0.8, -0.25], [-1.4, 0.8, -0.25]])
MODELS = make_models(LEVER, WHEELS, NHC)
PARAMS = U.model_params(LEVER, NHC, WHEELS)
AUG = StateLayout(gyro_bias_axes=(0, 1, 2), accel_bias_axes=(0, 1, 2), wheel_scale=True)
GATES = {d: 10.0 + 3 * d for d in range(1, 7)}


def close(a, b, tol=TOL) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and float(np.abs(a - b).max(initial=0.0)) <= tol * max(1.0, float(np.abs(b).max()))


def _aux(kind, rng):
    if kind in (ObsKind.GNSS_VEL, ObsKind.NHC):
        return tuple(rng.normal(0, 0.3, 3))
    if kind == ObsKind.WHEEL_SPEED:
        return tuple(rng.normal(0, 0.3, 3)), tuple(rng.normal(0, 0.1, 4)), (0.4, 0.3, 0.0, 0.3)
    if kind == ObsKind.Y2_GPS:
        return float(rng.normal(0, 0.02))
    return None


def _kernel_aux(kind, aux):
    code = U.KIND_CODES.index(kind.value)
    if aux is None:
        return np.zeros(11), False
    if code == 7:
        return np.array([*aux[0], *aux[1], *aux[2]]), True
    return np.atleast_1d(np.asarray(aux, dtype=float)), True


def _xe(rng):
    x = np.concatenate([rng.normal(0, 30, 3), [20.0, 3.0, 0.1], rng.normal(0, 0.1, 2), [1.0],
                        rng.normal(0, 0.03, 2), [0.9], rng.normal(0, 0.01, 7)])
    return x


@pytest.mark.parametrize("kind", list(ObsKind), ids=lambda k: k.value)
def test_models_equal_the_reference(kind, rng):
    code = U.KIND_CODES.index(kind.value)
    m = MODELS[kind]
    for ext in (False, True):
        for with_aux in (False, True):
            xe = _xe(rng)
            aux = _aux(kind, rng) if with_aux else None
            a, has = _kernel_aux(kind, aux)
            y, H = np.empty(m.dim), np.empty((m.dim, 19))
            U.model_eval(code, xe, a, has, *PARAMS, y, H, ext)
            x_ref = xe if ext else xe[:12]
            assert close(y, m.h(x_ref, aux))
            Hr = m.jacobian(x_ref, aux)
            assert close(H[:, :Hr.shape[1]], Hr) and not H[:, Hr.shape[1]:].any()


def _case(kind, layout, rng, offset=0.0, nan_row=None):
    idx = layout.full_index
    xe = _xe(rng)
    x = xe[idx].copy()
    a = rng.normal(size=(layout.n, layout.n))
    P = a @ a.T * 1e-4 + 1e-5 * np.eye(layout.n)
    m = MODELS[kind]
    aux = _aux(kind, rng)
    xf, _ = layout.expand(x, ext=layout.augmented)
    z = m.h(xf, aux) + rng.normal(0, 0.01, m.dim) + offset
    if nan_row is not None and m.dim > 1:
        z[nan_row] = np.nan
    b = rng.normal(size=(m.dim, m.dim))
    R = b @ b.T * 1e-4 + 1e-4 * np.eye(m.dim)
    return x, P, z, R, aux


def _kernel_update(kind, layout, x, P, z, R, aux, iterations):
    code = U.KIND_CODES.index(kind.value)
    idx, pos, flags, yaw = layout_arrays(layout)
    a, has = _kernel_aux(kind, aux)
    n, m = layout.n, z.shape[0]
    gates = np.array([GATES.get(d, math.inf) for d in range(7)])
    x, P = x.copy(), P.copy()
    inn, sig, H, Ru = np.empty(m), np.empty(m), np.empty((m, n)), np.empty((m, m))
    st, dof, nis, gate, finite = U.update(code, x, P, z, R, a, has, idx, pos, flags, yaw, *PARAMS, iterations,
                                          gates, inn, sig, H, Ru)
    return st, dof, nis, gate, inn[:dof], sig[:dof], x, P, H[:dof], Ru[:dof, :dof], finite


STATUS = {"accepted": U.ACCEPTED, "gated": U.GATED, "nan": U.NAN}


@pytest.mark.parametrize("layout", [StateLayout(), StateLayout.paper(), AUG], ids=("n11", "n12", "n19"))
@pytest.mark.parametrize("kind", list(ObsKind), ids=lambda k: k.value)
def test_update_equals_the_reference(kind, layout, rng):
    yaw = [i for i, s in enumerate(layout.full_index) if s in (8, 11)]
    for offset, nan_row, iterations in ((0.0, None, 1), (0.0, None, 3), (0.0, 1, 3), (5.0, None, 1)):
        x, P, z, R, aux = _case(kind, layout, rng, offset, nan_row)
        ref = update_reference(MODELS[kind], layout, x.copy(), P.copy(), z, R, aux, iterations, GATES, yaw)
        got = _kernel_update(kind, layout, x, P, z, R, aux, iterations)
        assert got[0] == STATUS[ref[0]] and got[1] == ref[1]
        assert close(got[2], ref[2]) and close(got[4], ref[4]) and close(got[5], ref[5])
        assert close(got[6], ref[6]) and close(got[7], ref[7])
        if ref[0] == "accepted":
            assert close(got[8], ref[8]) and close(got[9], ref[9]) and got[10]
            assert np.array_equal(got[7], got[7].T)


def test_singular_innovation_covariance_is_nan(rng):
    lay = StateLayout()
    x, _, z, _, _ = _case(ObsKind.GNSS_ATT, lay, rng)
    P, R = np.zeros((lay.n, lay.n)), np.zeros((3, 3))
    ref = update_reference(MODELS[ObsKind.GNSS_ATT], lay, x, P, z, R, None, 1, GATES, [8])
    got = _kernel_update(ObsKind.GNSS_ATT, lay, x, P, z, R, None, 1)
    assert ref[0] == "nan" and ref[1] == 0 and got[0] == U.NAN and got[1] == 0


def test_compiled_update_kernels_bit_equal_their_python_form(rng):
    calls = []
    idx, pos, flags, yaw = layout_arrays(AUG)
    gates = np.array([GATES.get(d, math.inf) for d in range(7)])
    for kind in ObsKind:
        if kind == ObsKind.GNSS_VEL:
            continue  # math.hypot: see the module docstring
        x, P, z, R, aux = _case(kind, AUG, rng)
        a, has = _kernel_aux(kind, aux)
        m = z.shape[0]
        calls.append(("vdps_hil.estimation.ekf_update_kernels", "update",
                      (U.KIND_CODES.index(kind.value), x, P, z, R, a, has, idx, pos, flags, yaw, *PARAMS, 3, gates,
                       np.empty(m), np.empty(m), np.empty((m, AUG.n)), np.empty((m, m)))))
    for (r1, a1), (r2, a2) in zip(run_pure_python(calls), run_compiled(calls)):
        assert same_bits(r1, r2) and same_bits(a1[:5], a2[:5])
