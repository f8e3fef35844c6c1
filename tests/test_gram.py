"""The design's column storage and Gram matrices (``workbench.ranking.gram``) against dense
numpy on a small random design (seed fixed), and the statistics' lifetime: a design that holds
its :class:`BlockGram` is freed by reference counting alone (no cycle through the statistics)."""

import gc
import weakref

import numpy as np

from vdps_hil.workbench.ranking.config import GROUP_NAMES
from vdps_hil.workbench.ranking.gram import Band, BlockGram, dense, gram


class _Design:
    """What BlockGram reads of a design: columns, row groups, micro blocks, y."""

    def __init__(self, rng, n=400, n_blocks=8):
        self.y = rng.normal(size=n)
        self.group = rng.integers(0, len(GROUP_NAMES), size=n)
        self.block = np.sort(rng.integers(0, n_blocks, size=n))
        self.n_blocks = n_blocks
        self.cols = [rng.normal(size=n), rng.normal(size=n)]
        for lo in range(0, n - 60, 40):  # overlapping bands, as the smooth velocity columns
            self.cols.append(Band(n, lo, rng.normal(size=80)))
        self._stats = BlockGram(self, self.block * len(GROUP_NAMES) + self.group)


def _x(d):
    return np.column_stack([dense(c) for c in d.cols])


def test_gram_of_bands_and_dense_columns_equals_the_dense_product():
    d = _Design(np.random.default_rng(7))
    x = _x(d)
    rows = np.flatnonzero(np.random.default_rng(8).random(len(d.y)) < 0.6)
    np.testing.assert_allclose(gram(d.cols, rows), x[rows].T @ x[rows], rtol=1e-12, atol=1e-12)


def test_block_gram_sums_and_quadratic_forms_equal_dense_numpy():
    d = _Design(np.random.default_rng(11))
    x, G = _x(d), d._stats
    np.testing.assert_allclose(G.sum(axis=(0, 1)), x.T @ x, rtol=1e-12, atol=1e-10)
    for g in (0, 3):
        r = d.group == g
        np.testing.assert_allclose(G.sum(axis=0)[g], x[r].T @ x[r], rtol=1e-12, atol=1e-10)
    sub = np.array([1, 2, 5])
    r = np.isin(d.block, sub)
    np.testing.assert_allclose(G[sub].sum(axis=(0, 1)), x[r].T @ x[r], rtol=1e-12, atol=1e-10)
    cols, th = [0, 3, 4], np.array([0.5, -1.0, 2.0])
    q = G[sub].quad(cols, th)
    for i, b in enumerate(sub):
        for g in range(len(GROUP_NAMES)):
            m = (d.block == b) & (d.group == g)
            assert abs(q[i, g] - float(np.sum((x[m][:, cols] @ th) ** 2))) < 1e-10


def test_a_design_holding_its_statistics_is_freed_without_the_cyclic_collector():
    d = _Design(np.random.default_rng(3))
    d._stats.sum(axis=(0, 1))  # fill the shared cache too
    ref = weakref.ref(d)
    gc.disable()
    try:
        del d
        assert ref() is None
    finally:
        gc.enable()
