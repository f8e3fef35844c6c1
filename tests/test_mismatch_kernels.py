"""The mismatch test's compiled kernel (``identification.mismatch_kernels``) is bit-equal to the
numpy slice expression it replaces and to its own Python form (run with ``VDPS_JIT=0``)."""

import numpy as np

from kernel_checks import run_compiled, run_pure_python, same_bits
from vdps_hil.identification.mismatch import MAX_LAG
from vdps_hil.identification.mismatch_kernels import add_lag_products


def test_lag_products_equal_the_numpy_slice_bit_for_bit(rng):
    ring = rng.normal(size=2 * MAX_LAG)
    for m, j in ((1, 0), (7, 3), (MAX_LAG, 0), (MAX_LAG, MAX_LAG - 1), (250, 123)):
        r = float(rng.normal())
        lag = rng.normal(size=MAX_LAG + 1)
        want = lag.copy()
        want[1:1 + m] += r * ring[j + MAX_LAG - m:j + MAX_LAG][::-1]
        add_lag_products(lag, ring, j + MAX_LAG, m, r)
        assert np.array_equal(lag, want)


def test_the_compiled_kernel_is_bit_equal_to_its_python_form(rng):
    calls = [("vdps_hil.identification.mismatch_kernels", "add_lag_products",
              (rng.normal(size=MAX_LAG + 1), rng.normal(size=2 * MAX_LAG), MAX_LAG + j, m, float(rng.normal())))
             for m, j in ((1, 0), (37, 5), (MAX_LAG, 17))]
    assert same_bits(run_compiled(calls), run_pure_python(calls))
