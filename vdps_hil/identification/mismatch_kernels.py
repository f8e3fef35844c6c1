"""Compiled kernel of the model-mismatch test (``mismatch``, ``vdps_hil.jit``): the lag products
a new residual adds to a row's integrated autocorrelation time, on plain float64 arrays.

Reference: the Python form of the kernel (``add_residual.py_func``, what runs with
``VDPS_JIT=0``), the elementwise operations of numpy's
``lag_sums[1:1 + m] += r * ring[j + MAX_LAG - m:j + MAX_LAG][::-1]``, one product and one sum
per lag in the same order, and the two ring writes: bit-equal (``tests/test_mismatch_kernels.py``).
Compiled because a row adds a residual at 100 Hz and the slice expression is five numpy calls.
"""

from __future__ import annotations

import numpy as np

from vdps_hil.jit import kernel

__all__ = ["add_residual", "warm"]


@kernel()
def add_residual(lag_sums, ring, n, r):
    """The n-th residual r (0-based) of a row (``mismatch._Row``): lag_sums[k] += r r_(n-k) for
    k = 1..min(n, L), then r into the ring at j = n % L and j + L (L = len(ring) / 2: the last L
    residuals, r_(n-k) at ring[j + L - k])."""
    half = ring.shape[0] // 2
    j = n % half
    for k in range(1, min(n, half) + 1):
        lag_sums[k] += r * ring[j + half - k]
    ring[j] = r
    ring[j + half] = r


def warm() -> None:
    """Compile (or load from the cache) the kernel with the argument types ``mismatch`` uses."""
    add_residual(np.zeros(5), np.ones(8), 5, 1.0)
