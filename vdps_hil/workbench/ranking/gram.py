"""How the design stores its columns and their Gram matrices, linear in the drive's length.

:class:`Band`: a column that is zero outside one run of rows (the smooth body-velocity columns:
a hat function spans two knot intervals), stored as that run only. :func:`gram` forms
X[rows]^T X[rows] touching only what overlaps; :class:`BlockGram` answers the per (micro block
b, row group g) Gram matrices G_bg = X_bg^T X_bg that blocked cross-validation sums, without
the dense (blocks, groups, p, p) array (p grows with the drive, so that array grew with the
cube of its length).
"""

from __future__ import annotations

import weakref
from typing import Sequence

import numpy as np

from .config import GROUP_NAMES

__all__ = ["Band", "BlockGram", "dense", "stored_values", "take", "keysum", "gram"]


class Band:
    """A design column that is zero outside the rows [lo, lo + len(vals)) (a smooth velocity
    column: a hat function spans two knot intervals)."""

    __slots__ = ("n", "lo", "vals")

    def __init__(self, n: int, lo: int, vals: np.ndarray):
        self.n, self.lo, self.vals = n, lo, vals

    @property
    def hi(self) -> int:
        return self.lo + len(self.vals)

    def dense(self) -> np.ndarray:
        out = np.zeros(self.n)
        out[self.lo:self.hi] = self.vals
        return out


def dense(col) -> np.ndarray:
    return col.dense() if isinstance(col, Band) else col


def stored_values(col) -> np.ndarray:
    return col.vals if isinstance(col, Band) else col


def take(col, rows: np.ndarray) -> np.ndarray:
    """col[rows] for sorted row indices (a band without expanding it)."""
    if not isinstance(col, Band):
        return col[rows]
    out = np.zeros(len(rows))
    i0, i1 = np.searchsorted(rows, [col.lo, col.hi])
    out[i0:i1] = col.vals[rows[i0:i1] - col.lo]
    return out


def keysum(key: np.ndarray, col, w: np.ndarray, size: int) -> np.ndarray:
    """sum of col * w per key value (bincount; a band over its rows only)."""
    if isinstance(col, Band):
        return np.bincount(key[col.lo:col.hi], col.vals * w[col.lo:col.hi], minlength=size)
    return np.bincount(key, col * w, minlength=size)


def gram(cols: Sequence, rows: np.ndarray) -> np.ndarray:
    """X[rows]^T X[rows] for sorted row indices: dense columns as a matrix product, band
    columns only against what overlaps them (linear in the drive length)."""
    p = len(cols)
    g = np.zeros((p, p))
    dense_k = [k for k, c in enumerate(cols) if not isinstance(c, Band)]
    bands = [k for k, c in enumerate(cols) if isinstance(c, Band)]
    d = np.column_stack([cols[k][rows] for k in dense_k]) if dense_k else np.zeros((len(rows), 0))
    if dense_k:
        g[np.ix_(dense_k, dense_k)] = d.T @ d
    seg = []
    for k in bands:
        c = cols[k]
        i0, i1 = (int(i) for i in np.searchsorted(rows, [c.lo, c.hi]))
        v = c.vals[rows[i0:i1] - c.lo]
        seg.append((i0, i1, v, k))
        if dense_k:
            gd = d[i0:i1].T @ v
            g[dense_k, k] = gd
            g[k, dense_k] = gd
    seg.sort(key=lambda z: z[0])
    for a, (i0, i1, va, ka) in enumerate(seg):
        for b in range(a, len(seg)):  # by index: a slice seg[a:] per band copied O(bands^2)
            j0, j1, vb, kb = seg[b]
            if j0 >= i1:
                break
            lo, hi = max(i0, j0), min(i1, j1)
            if lo < hi:
                g[ka, kb] = g[kb, ka] = float(va[lo - i0:hi - i0] @ vb[lo - j0:hi - j0])
    return g


class BlockGram:
    """The Gram matrices G_bg = X_bg^T X_bg of the design's rows per (micro block b, row group g)
    as ``Design.stats`` needs them, without storing the (blocks, groups, p, p) array: p grows
    with the drive through the smooth velocity columns (one pair per ``nuisance_knot_s``), so
    that array grew with the cube of the drive's length. Held: the total (p, p) and the total
    per group (groups, p, p); sums over a set of blocks are computed from the rows of the blocks
    left out (or in, whichever is fewer) and cached (the folds repeat); per-(b, g) quadratic
    forms theta^T G_bg theta = |X_bg theta|^2 and columns G_bg[:, k] come from the rows.

    Indexing as the array: ``G[blocks]`` (a subset of blocks), ``G.sum(axis=(0, 1))``,
    ``G.sum(axis=0)``, ``G[:, :, :, k]``, ``G[:, :, k, k]``; ``G.quad(cols, th)`` is
    einsum("bgpq,p,q->bg", G[:, :, cols][:, :, :, cols], th, th)."""

    def __init__(self, d, key: np.ndarray, blocks: np.ndarray | None = None, shared: dict | None = None):
        # a weak reference: the design holds its statistics (``Design._stats``), so a strong one
        # made a cycle and every drive-sized design lived until the cyclic collector ran
        self.d = d if isinstance(d, weakref.ProxyType) else weakref.proxy(d)
        self.cols = list(d.cols)  # the columns when the statistics were taken (Design copies share the list)
        self.key = key
        self.ng = len(GROUP_NAMES)
        self.blocks = np.arange(d.n_blocks) if blocks is None else np.asarray(blocks, dtype=int)
        self._shared = shared if shared is not None else {}
        self._rows = None

    def _totals(self):
        if "total" not in self._shared:
            p = len(self.cols)
            per = np.zeros((self.ng, p, p))
            g_all = self.d.group
            for g in range(self.ng):
                rows = np.flatnonzero(g_all == g)
                if len(rows):
                    per[g] = gram(self.cols, rows)
            self._shared["per_group"] = per
            self._shared["total"] = per.sum(axis=0)
        return self._shared["total"], self._shared["per_group"]

    def rows(self) -> np.ndarray:
        if self._rows is None:
            inside = np.zeros(self.d.n_blocks, bool)
            inside[self.blocks] = True
            self._rows = np.flatnonzero(inside[self.d.block])
        return self._rows

    def __getitem__(self, idx):
        if isinstance(idx, tuple):
            return self._entries(idx)
        if isinstance(idx, slice) and idx == slice(None):
            return self
        return BlockGram(self.d, self.key, self.blocks[idx], self._shared)

    def _entries(self, idx):
        """G[:, :, :, k] -> (b, g, p) and G[:, :, k, k] -> (b, g) on this block subset."""
        if len(idx) != 4 or idx[0] != slice(None) or idx[1] != slice(None):
            raise IndexError("unsupported BlockGram index")
        k = idx[3]
        rows = self.rows()
        key = self.key[rows]
        size = self.d.n_blocks * self.ng
        shape = (self.d.n_blocks, self.ng)
        xk = take(self.cols[k], rows)
        if idx[2] == slice(None):
            out = np.zeros(shape + (len(self.cols),))
            for j, col in enumerate(self.cols):
                out[:, :, j] = np.bincount(key, take(col, rows) * xk, minlength=size).reshape(shape)
            return out[self.blocks]
        j = idx[2]
        return np.bincount(key, take(self.cols[j], rows) * xk, minlength=size).reshape(shape)[self.blocks]

    def sum(self, axis):
        total, per = self._totals()
        full = len(self.blocks) == self.d.n_blocks and np.array_equal(self.blocks, np.arange(self.d.n_blocks))
        if axis == 0 or tuple(axis) == (0,):
            if full:
                return per.copy()
            raise ValueError("BlockGram.sum(axis=0) only over all blocks")
        if tuple(axis) != (0, 1):
            raise ValueError("unsupported BlockGram.sum axis")
        if full:
            return total.copy()
        ck = ("sum", self.blocks.tobytes())
        if ck not in self._shared:
            rows = self.rows()
            if 2 * len(rows) <= len(self.d.y):
                self._shared[ck] = gram(self.cols, rows)
            else:
                out = np.ones(len(self.d.y), bool)
                out[rows] = False
                self._shared[ck] = total - gram(self.cols, np.flatnonzero(out))
        return self._shared[ck].copy()

    def quad(self, cols: Sequence[int], th: np.ndarray) -> np.ndarray:
        """theta^T G_bg[cols, cols] theta per (block of this subset, group): (b, g)."""
        rows = self.rows()
        r = np.zeros(len(rows))
        for j, k in enumerate(cols):
            if th[j] != 0.0:
                c = self.cols[k]
                if isinstance(c, Band):
                    i0, i1 = np.searchsorted(rows, [c.lo, c.hi])
                    r[i0:i1] += th[j] * c.vals[rows[i0:i1] - c.lo]
                else:
                    r += th[j] * c[rows]
        size = self.d.n_blocks * self.ng
        q = np.bincount(self.key[rows], r * r, minlength=size).reshape(self.d.n_blocks, self.ng)
        return q[self.blocks]
