"""The mismatch test's compiled kernel (``identification.mismatch_kernels``) is bit-equal to the
numpy slice expression and ring writes it replaces and to its own Python form (run with
``VDPS_JIT=0``)."""

import numpy as np

from kernel_checks import run_compiled, run_pure_python, same_bits
from vdps_hil.identification.mismatch import MAX_LAG
from vdps_hil.identification.mismatch_kernels import add_residual


def test_a_residual_adds_what_the_numpy_slice_adds_bit_for_bit(rng):
    ring = rng.normal(size=2 * MAX_LAG)
    for n in (0, 1, 7, MAX_LAG - 1, MAX_LAG, 3 * MAX_LAG + 123):
        r = float(rng.normal())
        lag = rng.normal(size=MAX_LAG + 1)
        want_lag, want_ring = lag.copy(), ring.copy()
        j, m = n % MAX_LAG, min(n, MAX_LAG)
        if m:
            want_lag[1:1 + m] += r * want_ring[j + MAX_LAG - m:j + MAX_LAG][::-1]
        want_ring[j] = want_ring[j + MAX_LAG] = r
        add_residual(lag, ring, n, r)
        assert np.array_equal(lag, want_lag) and np.array_equal(ring, want_ring)


def test_the_compiled_kernel_is_bit_equal_to_its_python_form(rng):
    calls = [("vdps_hil.identification.mismatch_kernels", "add_residual",
              (rng.normal(size=MAX_LAG + 1), rng.normal(size=2 * MAX_LAG), n, float(rng.normal())))
             for n in (0, 37, MAX_LAG + 17)]
    assert same_bits(run_compiled(calls), run_pure_python(calls))
