"""The RLS's compiled kernels (``identification.rls_kernels``) equal the numpy lines of
``WeightedRLS.update`` (its ``VDPS_JIT=0`` path) within 1e-12 of the largest element per step,
with excitation masks, NaN rows, forgetting with anti-windup, clamped bounds and consider
sensitivities, and bit-equal to their own Python form (run with ``VDPS_JIT=0``)."""

import copy

import numpy as np
import pytest

from kernel_checks import run_compiled, run_pure_python, same_bits
from vdps_hil import jit
from vdps_hil.identification.rls import WeightedRLS

TOL = 1e-12
STATE = ("_xq", "_P", "_info", "_info_scaled", "_gg", "_g1", "_rss", "_nrows", "_sens")


def close(a, b, tol=TOL) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and float(np.abs(a - b).max(initial=0.0)) <= tol * max(1.0, float(np.abs(b).max()))


def _rls(forgetting: float) -> WeightedRLS:
    return WeightedRLS([1500.0, 2.0, -3.0], [300.0, 1.0, 2.0], [1.0, 0.5, 2.0, 0.1], forgetting=forgetting,
                       lower=[500.0, -10.0, -10.0], upper=[3000.0, 1.4, 10.0])  # x1 = 1.5 clamps


def _step(rng, m: int = 4, n: int = 3):
    a = rng.normal(size=(m, n)) * [1e-3, 1.0, 0.5]
    b = a @ [1800.0, 1.5, -2.0] + rng.normal(0, 0.05, m)
    if rng.uniform() < 0.2:
        a[rng.integers(m), rng.integers(n)] = np.nan
    if rng.uniform() < 0.1:
        b[rng.integers(m)] = np.inf
    rows = rng.uniform(size=m) < 0.7
    return a, b, rows, rng.normal(size=(m, 2))


@pytest.mark.skipif(not jit.ENABLED, reason="VDPS_JIT=0: nothing compiled to compare")
@pytest.mark.parametrize("forgetting", [1.0, 0.97])
def test_each_compiled_update_equals_the_numpy_update(forgetting, rng):
    rls = _rls(forgetting)
    assert rls._compiled
    clamped = 0
    for _ in range(300):
        a, b, rows, d = _step(rng)
        ref = copy.deepcopy(rls)
        ref._compiled = False
        ok = rls.update(a, b, rows, db_dtheta=d)
        assert ref.update(a, b, rows, db_dtheta=d) == ok
        assert rls.counters == ref.counters
        for name in STATE:
            assert (getattr(rls, name) is None) == (getattr(ref, name) is None)
            if getattr(ref, name) is not None:
                assert close(getattr(rls, name), getattr(ref, name)), name
        assert (rls._g_prev is None) == (ref._g_prev is None)
        clamped = rls.counters.clamped
    c = rls.counters
    assert c.updates > 100 and c.nan_rows > 0 and c.not_excited > 0, c
    assert clamped > 0  # the bounds path ran
    assert close(rls.sigma, ref.sigma, 1e-9) and close(rls.x, ref.x, 1e-12)


@pytest.mark.skipif(not jit.ENABLED, reason="VDPS_JIT=0: nothing compiled to compare")
def test_a_run_of_compiled_updates_follows_the_numpy_run(rng):
    """Over 500 updates the two paths stay within 1e-10 of each other (round-off only)."""
    fast, ref = _rls(1.0), _rls(1.0)
    ref._compiled = False
    for _ in range(500):
        a, b, rows, d = _step(rng)
        assert fast.update(a, b, rows, db_dtheta=d) == ref.update(a, b, rows, db_dtheta=d)
    assert close(fast.x, ref.x, 1e-10) and close(fast.covariance, ref.covariance, 1e-10)
    assert abs(fast.x[0] - 1800.0) < 60.0 and fast.x[1] == 1.4  # what the data say, within the bounds


def test_kernels_are_bit_equal_to_their_python_form(rng):
    m, n = 4, 3
    calls = []
    for _ in range(4):
        a, b, rows, _ = _step(rng, m, n)
        P = rng.normal(size=(n, n))
        P = P @ P.T + np.eye(n)
        args = (a, b, rows, rng.uniform(0.5, 2, m), rng.uniform(0.5, 2, n), rng.normal(size=n), P, 0.98,
                np.zeros((m, n)), np.zeros((m, n)), np.zeros(m), np.zeros(n), np.zeros((n, n)))
        calls.append(("vdps_hil.identification.rls_kernels", "covariance_step", args))
        lo = np.full(n, -np.inf) if len(calls) % 2 else rng.normal(size=n)  # inside, or some bounds crossed
        calls.append(("vdps_hil.identification.rls_kernels", "update_inside",
                      args[:8] + (lo, np.full(n, np.inf)) + args[8:] + (np.eye(n), np.eye(n), np.ones(n), np.ones(n),
                                                                        rng.normal(size=n), True)))
        d = rng.normal(size=(m, 5))
        d[rng.integers(m), rng.integers(5)] = np.nan
        calls.append(("vdps_hil.identification.rls_kernels", "consider_rows", (a, b, rows, args[3], d, np.zeros((m, 5)))))
        qa, aq = rng.normal(size=(m, n)), rng.normal(size=(m, n))
        calls.append(("vdps_hil.identification.rls_kernels", "accumulate",
                      (qa, aq, rng.normal(size=m), 3, rng.normal(size=n), 0.98, np.eye(n), np.eye(n),
                       np.ones(n), np.ones(n), rng.normal(size=n), True)))
    assert same_bits(run_compiled(calls), run_pure_python(calls))


def test_the_consider_rows_are_the_numpy_expression_bit_for_bit(rng):
    from vdps_hil.identification.rls_kernels import consider_rows
    for _ in range(50):
        a, b, rows, d = _step(rng, 4, 3)
        d[rng.integers(4), rng.integers(2)] = np.inf
        qv = rng.uniform(0.5, 2.0, 4)
        sel = rows & np.isfinite(a).all(axis=1) & np.isfinite(b)
        ds = d[sel]
        want = qv[sel, None] * np.where(np.isfinite(ds), ds, 0.0)
        out = np.zeros((4, 2))
        k = consider_rows(a, b, rows, qv, d, out)
        assert k == int(sel.sum()) and np.array_equal(out[:k], want)
