"""Compiled kernel of the model-mismatch test (``mismatch``, ``vdps_hil.jit``): the lag products
a new residual adds to a row's integrated autocorrelation time, on plain float64 arrays.

Reference: the Python form of the kernel (``add_lag_products.py_func``, what runs with
``VDPS_JIT=0``), the elementwise operations of numpy's
``lag_sums[1:1 + m] += r * ring[j + MAX_LAG - m:j + MAX_LAG][::-1]``, one product and one sum
per lag in the same order: bit-equal (``tests/test_mismatch_kernels.py``). Compiled because a
row adds a residual at 100 Hz and the slice expression is five numpy calls.
"""

from __future__ import annotations

import numpy as np

from vdps_hil.jit import kernel

__all__ = ["add_lag_products", "warm"]


@kernel()
def add_lag_products(lag_sums, ring, top, m, r):
    """lag_sums[k] += r ring[top - k] for k = 1..m (``mismatch._Row.add``: ring[top - k] is the
    residual k steps before r)."""
    for k in range(1, m + 1):
        lag_sums[k] += r * ring[top - k]


def warm() -> None:
    """Compile (or load from the cache) the kernel with the argument types ``mismatch`` uses."""
    add_lag_products(np.zeros(5), np.ones(8), 4, 4, 1.0)
