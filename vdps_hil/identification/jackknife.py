"""The delete-a-block jackknife variance of one RLS problem's estimate: a sigma that does not
trust the noise model (issue 17, "sigmas that are honest on data it was not tuned on").

The RLS covariance W P W (``rls``) is the estimate's covariance only if the rows' errors are
white with the design noise 1 / Q. On a vehicle that is not the model they are neither: the
filtered estimator outputs colour them, and a model error that follows the maneuver (a load
transfer the model books elsewhere, a tire that saturates) moves the least-squares solution
differently in each part of the drive. The jackknife measures the spread of the solution over
the drive itself instead of predicting it.

The used rows (scaled coordinates of eq 18: A_Q = Q A W, y = Q b, x_Q = W^-1 x) are summed in
consecutive blocks k = 1..K of equal numbers of updates::

    I_k = sum_(rows in k) A_Q^T A_Q,      r_k = sum_(rows in k) A_Q^T y
    x_(-k) = (P0^-1 + I - I_k)^-1 (P0^-1 x_Q0 + r - r_k)        (drive without block k)
    V_J    = (K - 1) / K  sum_k (x_(-k) - xbar)(x_(-k) - xbar)^T,  xbar = mean_k x_(-k)

(I = sum_k I_k, r = sum_k r_k, P0 and x_Q0 the RLS's prior; x = (P0^-1 + I)^-1 (P0^-1 x_Q0 + r)
is the RLS's own estimate without forgetting and clamping). V_J is the delete-a-group jackknife
variance (Quenouille 1956, Tukey 1958; Efron & Tibshirani, "An Introduction to the Bootstrap",
1993, eq 11.5), for time series the block jackknife (Kuensch 1989, Ann. Statist. 17: 1217):
consistent for the estimate's variance under serially correlated and heteroscedastic errors when
the blocks are longer than the errors' correlation, the least-squares sandwich
(A^T A)^-1 A^T Omega A (A^T A)^-1 without a model of Omega (Newey & West 1987 estimate the same
long-run covariance with a kernel). With white errors of the design noise it equals W P W up to
its sampling error (K - 1 degrees of freedom).

Blocks: the first holds ``span`` updates; when 2 K blocks are filled, neighbours are merged
pairwise and the span doubles (the batch-means schedule of Schmeiser 1982, "Batch size effects
in the analysis of simulation output", Oper. Res. 30: 556: 10-30 batches), so K stays between
``blocks`` and 2 ``blocks`` - 1 and each block grows with the drive: correlation over any time
shorter than a block is counted. The memory and the cost per update are fixed (2 K n x n sums,
one n x n rank-k update); V_J costs K solves of n x n and is computed only when read. With
forgetting lambda < 1 the blocks are discounted like P^-1.

Symbols: n parameters; K blocks; I_k [-] and r_k [-] in scaled units; V_J in scaled units
(physical: W V_J W, unit of x^2).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BlockJackknife"]

MIN_BLOCKS = 4
"""Fewer filled blocks than this: no jackknife variance (its K - 1 degrees of freedom)."""


class BlockJackknife:
    """Block sums of one problem's used rows and their jackknife variance (module docstring).
    ``blocks``: the target K (2 K blocks are kept before merging); ``span``: updates in a first
    block."""

    def __init__(self, n: int, blocks: int = 10, span: int = 50):
        if blocks < MIN_BLOCKS or span < 1:
            raise ValueError(f"blocks must be >= {MIN_BLOCKS} and span >= 1, got {blocks}, {span}")
        self.n, self.blocks, self.first_span = int(n), int(blocks), int(span)
        self.reset()

    def reset(self) -> None:
        self._info = np.zeros((2 * self.blocks, self.n, self.n))
        self._score = np.zeros((2 * self.blocks, self.n))
        self._span = self.first_span
        self._updates = 0

    def add(self, aq: np.ndarray, y: np.ndarray, lam: float = 1.0) -> None:
        """The rows (scaled, k x n and k) of one update."""
        k = self._updates // self._span
        if k == 2 * self.blocks:  # merge neighbours, double the span
            self._info[:self.blocks] = self._info[0::2] + self._info[1::2]
            self._score[:self.blocks] = self._score[0::2] + self._score[1::2]
            self._info[self.blocks:] = 0.0
            self._score[self.blocks:] = 0.0
            self._span *= 2
            k = self._updates // self._span
        if lam < 1.0:
            self._info *= lam
            self._score *= lam
        info, score = self._info[k], self._score[k]  # views: added to in place
        at = aq.T
        info += at @ aq
        score += at @ y
        self._updates += 1

    @property
    def filled(self) -> int:
        """Blocks holding at least one update."""
        return 0 if self._updates == 0 else (self._updates - 1) // self._span + 1

    def variance(self, p0_inv: np.ndarray, xq0: np.ndarray) -> np.ndarray | None:
        """V_J (scaled coordinates, n x n) with the prior information ``p0_inv`` and prior mean
        ``xq0``; None below ``MIN_BLOCKS`` filled blocks."""
        kb = self.filled
        if kb < MIN_BLOCKS:
            return None
        info, score = self._info[:kb], self._score[:kb]
        tot_info = p0_inv + info.sum(axis=0)
        tot_score = p0_inv @ xq0 + score.sum(axis=0)
        x_del = np.linalg.solve(tot_info[None, :, :] - info, (tot_score[None, :] - score)[:, :, None])[:, :, 0]
        d = x_del - x_del.mean(axis=0)
        v = (kb - 1) / kb * (d.T @ d)
        return 0.5 * (v + v.T)
