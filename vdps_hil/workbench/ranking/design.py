"""The design matrix of the ranking: every whitened row stacked, named column blocks with their
priors, and per (micro block, row group) sufficient statistics for the fits and the blocked
cross-validation (:class:`Design`).

The linear model of the residuals (``residuals``: r = measured - model at the identified
model)::

    r = N eta + B delta_p + sum_c X_c theta_c + e

N: nuisance -- per row the estimator's body-velocity and slip directions (projected out row by
row, :class:`~vdps_hil.workbench.ranking.context.Context`) and, for the GNSS innovations, the
initial attitude, velocity and position (9 columns, block ``_nuisance``); the slowly varying
body-velocity errors (block ``_smooth``); B: the ten identified parameters (eq 20-23, blocks
named by parameter, weak prior delta_p ~ N(0, (0.5 p)^2)); X_c: the columns of candidate c
(``candidates``). Every row is divided by its equation's noise sigma (GNSS rows by their sigma);
every column is scaled to unit RMS (``scale``).

MAP fit on a set of columns: (X^T X + W) theta = X^T y + W theta_c, W the prior weights times
``prior_scale`` = n / n_eff (the data rows are autocorrelated, the priors are not).
Blocked cross-validation (``cv``): the drive is cut into micro blocks of ``micro_block_s``
grouped into ``folds`` contiguous folds; each fold is predicted from a fit on the other folds
minus the ``gap_blocks`` micro blocks next to it, and the held-out SSE is kept per row group.

Effective sample size (``n_eff``): n_eff = sum_g n_g / tau_g, tau_g the integrated
autocorrelation time of row group g's residual (one per equation, one per innovation channel).
Sigmas (``sigma_of``): sqrt(diag((X^T X + W)^-1) s^2 n / n_eff).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from .config import GROUP_NAMES, INNOVATION_GROUP_OF_CHANNEL, RankingConfig
from .context import Context
from .gram import Band, BlockGram, dense, keysum, stored_values

__all__ = ["Design", "effective_sample_size", "theta_of", "sigma_of"]


class Design:
    """Stacked whitened rows (dynamics, projected; GNSS innovations) and named column blocks, with
    per (micro block, row group) sufficient statistics for fast blocked cross-validation."""

    def __init__(self, ctx: Context, config: RankingConfig):
        self.ctx = ctx
        self.cfg = config
        n, e = ctx.y_dyn.shape
        inn = ctx.inn
        self.n_dyn_rows = n * e
        t_dyn = np.repeat(ctx.res.t_s[ctx.rows], e)
        eq_ids = np.flatnonzero(ctx.avail)
        g_dyn = np.tile(eq_ids, n)
        if len(inn):
            y_inn = inn.values / inn.sigma
            t_inn = inn.t_s
            g_inn = np.array([INNOVATION_GROUP_OF_CHANNEL[int(c)] for c in inn.channel])
        else:
            y_inn, t_inn, g_inn = np.zeros(0), np.zeros(0), np.zeros(0, int)
        self.y = np.concatenate([ctx.y_dyn.reshape(-1), y_inn])
        t_all = np.concatenate([t_dyn, t_inn])
        t0 = float(ctx.table.t_s[0])
        self.block = np.floor((t_all - t0) / config.micro_block_s).astype(int)
        self.n_blocks = int(self.block.max()) + 1 if len(self.block) else 0
        self.group = np.concatenate([g_dyn, g_inn]).astype(int)
        self.cols: list[np.ndarray] = []
        self.names: list[str] = []
        self.blocks: dict[str, list[int]] = {}
        self.scale: list[float] = []
        self.prior_w: list[float] = []  # prior weight per column (0 = none), scaled units
        self.prior_c: list[float] = []  # prior centre per column, scaled units
        self.prior_scale = 1.0  # n / n_eff: the data rows are correlated, the priors are not
        self._stats = None
        if len(inn):
            self.add_block("_nuisance", None, inn.nuisance)  # unwhitened: add_block divides by sigma
        sm, sm_sig = ctx.smooth_bands(config.nuisance_knot_s, config.velocity_sigma_floor_mps)
        boost = getattr(ctx.states, "band_weight", None)  # ``identification.cap_nuisance``
        if sm and boost is not None and len(boost) == len(sm_sig):
            sm_sig = np.asarray(sm_sig) / np.sqrt(boost)
        if sm:
            self._add_band_block("_smooth", sm, sm_sig)

    def _add_band_block(self, name: str, bands, prior_sigma) -> None:
        """Add columns non-zero on a run of dynamic rows only ([(first used row, (r, E))], whitened
        and projected), stored as :class:`Band` (memory linear in the drive length)."""
        e = self.ctx.y_dyn.shape[1]
        n = len(self.y)
        idx = []
        for j, (r0, a) in enumerate(bands):
            v = a.reshape(-1)
            s = float(np.sqrt(np.sum(v * v) / n)) if n else 0.0
            s = s if s > 0 else 1.0
            self.scale.append(s)
            self.cols.append(Band(n, r0 * e, v / s))
            self.prior_w.append(1.0 / (prior_sigma[j] * s) ** 2 if prior_sigma[j] > 0 else 0.0)
            self.prior_c.append(0.0)
            self.names.append(f"{name}[{j}]")
            idx.append(len(self.cols) - 1)
        self.blocks[name] = idx
        self._stats = None

    def add_block(self, name: str, x_dyn: np.ndarray | None, x_inn: np.ndarray | None,
                  prior_sigma: Sequence[float] | None = None, prior_center: Sequence[float] | None = None) -> list[int]:
        """Add a candidate's columns (x_dyn: (n_all, 14, p) equation units; x_inn: (m, p)
        unwhitened innovation units). Returns the column indices."""
        p = (x_dyn.shape[2] if x_dyn is not None else x_inn.shape[1])
        ctx = self.ctx
        dyn = ctx.whiten_project(x_dyn).reshape(-1, p) if x_dyn is not None else np.zeros((self.n_dyn_rows, p))
        m = len(self.y) - self.n_dyn_rows
        if x_inn is not None and m:
            inn = np.nan_to_num(x_inn / ctx.inn.sigma[:, None])
        else:
            inn = np.zeros((m, p))
        full = np.vstack([dyn, inn])
        idx = []
        for j in range(p):
            col = full[:, j]
            s = float(np.sqrt(np.mean(col * col))) if len(col) else 0.0
            self.scale.append(s if s > 0 else 1.0)
            self.cols.append(col / (s if s > 0 else 1.0))
            self.prior_w.append(0.0 if prior_sigma is None else 1.0 / (prior_sigma[j] * (s if s > 0 else 1.0)) ** 2
                                if prior_sigma[j] > 0 else 0.0)
            self.prior_c.append(0.0 if prior_center is None else float(prior_center[j]) * (s if s > 0 else 1.0))
            self.names.append(f"{name}[{j}]")
            idx.append(len(self.cols) - 1)
        self.blocks[name] = idx
        self._stats = None
        return idx

    def with_y_shift(self, dyn14: np.ndarray, x_inn, phi) -> "Design":
        """A copy whose residual is y + (whitened, projected) ``dyn14`` on the dynamic rows and
        + X_inn phi on the innovation rows (the model without an effect it holds)."""
        other = Design.__new__(Design)
        other.__dict__.update(self.__dict__)
        y = self.y.copy()
        a = self.ctx.whiten_project(dyn14[:, :, None])[:, :, 0].reshape(-1)
        y[:self.n_dyn_rows] += a
        m = len(y) - self.n_dyn_rows
        if m and x_inn is not None and len(x_inn) == m:
            y[self.n_dyn_rows:] += np.nan_to_num(x_inn @ np.asarray(phi, dtype=float) / self.ctx.inn.sigma)
        other.y = y
        other._stats = None
        return other

    def shift_innovations(self, x_inn: np.ndarray, phi) -> None:
        """The model holds a sensor effect at phi: the GNSS innovations it leaves are
        e - X_inn phi (the innovations are computed from the raw readings)."""
        m = len(self.y) - self.n_dyn_rows
        if m and x_inn is not None and len(x_inn) == m:
            self.y[self.n_dyn_rows:] -= np.nan_to_num(x_inn @ np.asarray(phi, dtype=float) / self.ctx.inn.sigma)
            self._stats = None

    def replace_block(self, name: str, x_dyn, x_inn) -> None:
        idx = self.blocks[name]
        tmp = Design.__new__(Design)
        tmp.__dict__.update(self.__dict__)
        tmp.cols, tmp.scale, tmp.prior_w, tmp.prior_c, tmp.names, tmp.blocks = [], [], [], [], [], {}
        Design.add_block(tmp, name, x_dyn, x_inn)
        for j, k in enumerate(idx):
            self.cols[k] = tmp.cols[j]
            self.scale[k] = tmp.scale[j]
        self._stats = None

    def has_signal(self, name: str) -> bool:
        return any(s > 0 and np.any(stored_values(self.cols[k]) != 0) for k in self.blocks[name]
                   for s in [self.scale[k]])

    # --- sufficient statistics
    def invalidate_stats(self) -> None:
        """Forget the sufficient statistics (taken again at the next :meth:`stats`)."""
        self._stats = None

    def stats(self):
        """(G, c, yy, cnt) per (micro block, row group): G a :class:`BlockGram` (X_bg^T X_bg
        without the dense (blocks, groups, p, p) array), c = X_bg^T y_bg, yy = y_bg^T y_bg, rows."""
        if self._stats is None:
            ng = len(GROUP_NAMES)
            key = self.block * ng + self.group
            shape = (self.n_blocks, ng)
            size = self.n_blocks * ng
            c = np.zeros(shape + (len(self.cols),))
            for j, col in enumerate(self.cols):
                c[:, :, j] = keysum(key, col, self.y, size).reshape(shape)
            yy = np.bincount(key, self.y * self.y, minlength=size).reshape(shape)
            cnt = np.bincount(key, minlength=size).reshape(shape).astype(float)
            self._stats = (BlockGram(self, key), c, yy, cnt)
        return self._stats

    def folds(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(held-out micro blocks, training micro blocks) per fold. Raises ``ValueError`` (one
        line) when a fold would leave no block to fit on: the drive is too short to judge."""
        nb = self.n_blocks
        k = max(2, min(self.cfg.folds, nb // 2))
        edges = np.linspace(0, nb, k + 1).round().astype(int)
        out = []
        for i in range(k):
            held = np.arange(edges[i], edges[i + 1])
            if not len(held):
                continue
            lo, hi = held[0] - self.cfg.gap_blocks, held[-1] + self.cfg.gap_blocks
            train = np.array([b for b in range(nb) if b < lo or b > hi], dtype=int)
            if not len(train):
                raise ValueError(
                    f"the drive is too short to judge an effect on held-out time blocks: {nb * self.cfg.micro_block_s:g} s "
                    f"({nb} blocks of {self.cfg.micro_block_s:g} s), and holding {len(held)} out with {self.cfg.gap_blocks} "
                    f"beside them leaves none to fit on")
            out.append((held, train))
        return out

    def solve(self, G, c, cols):
        """MAP estimate: (G + W) theta = c + W theta_c (Gaussian priors on some columns; W the
        prior weights times ``prior_scale``, theta_c their centres)."""
        prior = np.array([self.prior_w[k] for k in cols]) * self.prior_scale
        centre = np.array([self.prior_c[k] for k in cols])
        A = G[np.ix_(cols, cols)] + np.diag(prior)
        tr = np.trace(A) / max(len(cols), 1)
        A = A + np.eye(len(cols)) * 1e-10 * max(tr, 1e-300)
        rhs = c[cols] + prior * centre
        try:
            return np.linalg.solve(A, rhs)
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(A, rhs, rcond=None)[0]

    def penalty(self, cols, th) -> float:
        """Prior term of the MAP objective at theta."""
        w = np.array([self.prior_w[k] for k in cols]) * self.prior_scale
        c = np.array([self.prior_c[k] for k in cols])
        return float(np.sum(w * (np.asarray(th) - c) ** 2))

    def objective(self, cols) -> tuple[np.ndarray, float]:
        """(theta, SSE + prior term) on all data: comparable between linearisation points."""
        th, sse, _ = self.fit(cols)
        return th, sse + self.penalty(cols, th)

    def fit(self, cols: Sequence[int], blocks: np.ndarray | None = None):
        """(theta (scaled columns), SSE over the chosen blocks, per-group SSE)."""
        G, c, yy, _ = self.stats()  # per (block, group): X^T X, X^T y, y^T y (``stats``)
        cols = list(cols)
        sel = slice(None) if blocks is None else blocks
        Gs = G[sel].sum(axis=(0, 1))
        cs = c[sel].sum(axis=(0, 1))
        if not cols:
            per = yy[sel].sum(axis=0)
            return np.zeros(0), float(per.sum()), per
        th = self.solve(Gs, cs, cols)
        per = self._sse_groups(G[sel], c[sel], yy[sel], cols, th)
        return th, float(per.sum()), per

    def _sse_groups(self, G, c, yy, cols, th):
        """Per group: sum over the blocks of |y - X theta|^2 = y^T y - 2 theta^T X^T y + theta^T X^T X theta."""
        cc = c[:, :, cols]
        v = yy - 2.0 * np.einsum("bgp,p->bg", cc, th) + G.quad(cols, th)
        return v.sum(axis=0)

    def cv(self, cols: Sequence[int]) -> np.ndarray:
        """Held-out SSE per row group (blocked cross-validation, module docstring)."""
        G, c, yy, _ = self.stats()
        cols = list(cols)
        out = np.zeros(len(GROUP_NAMES))
        for held, train in self.folds():
            if not cols:
                out += yy[held].sum(axis=0)
                continue
            th = self.solve(G[train].sum(axis=(0, 1)), c[train].sum(axis=(0, 1)), cols)
            out += self._sse_groups(G[held], c[held], yy[held], cols, th)
        return out

    def columns_of(self, names: Sequence[str]) -> list[int]:
        return [k for n in names for k in self.blocks.get(n, [])]

    def matrix(self, cols: Sequence[int]) -> np.ndarray:
        return np.column_stack([dense(self.cols[k]) for k in cols]) if cols else np.zeros((len(self.y), 0))

    def predict(self, cols: Sequence[int], th) -> np.ndarray:
        """X[:, cols] theta without forming X."""
        out = np.zeros(len(self.y))
        for k, v in zip(cols, th):
            c = self.cols[k]
            if isinstance(c, Band):
                out[c.lo:c.hi] += v * c.vals
            else:
                out += v * c
        return out


def _tau(v: np.ndarray, max_lag: int = 200) -> float:
    """Integrated autocorrelation time (sum of the autocorrelation up to its first drop below
    0.05), >= 1."""
    v = v - v.mean()
    n = len(v)
    if n < 10 or not np.any(v):
        return 1.0
    f = np.fft.rfft(v, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:n]
    ac = ac / ac[0]
    tau = 1.0
    for k in range(1, min(max_lag, n - 1)):
        if ac[k] < 0.05:
            break
        tau += 2.0 * ac[k]
    return max(tau, 1.0)


def effective_sample_size(d: Design, resid: np.ndarray) -> float:
    """n_eff = sum_g n_g / tau_g of the residual ``resid`` (module docstring): one term per
    equation and one per innovation channel, >= 1."""
    ctx = d.ctx
    n, e = ctx.y_dyn.shape
    tot = 0.0
    if n:
        r = resid[:d.n_dyn_rows].reshape(n, e)
        for k in range(e):
            tot += n / _tau(r[:, k])
    if len(ctx.inn):
        ri = resid[d.n_dyn_rows:]
        for ch in np.unique(ctx.inn.channel):
            m = ctx.inn.channel == ch
            tot += m.sum() / _tau(ri[m])
    return max(tot, 1.0)


def theta_of(d: Design, name: str, cols: Sequence[int], th: np.ndarray) -> np.ndarray:
    """Block ``name``'s parameters in its own units from a fit ``th`` on ``cols`` (scaled columns)."""
    pos = {k: j for j, k in enumerate(cols)}
    return np.array([th[pos[k]] / d.scale[k] for k in d.blocks[name]])


def sigma_of(d: Design, name: str, cols: Sequence[int], s2: float, ratio: float) -> np.ndarray:
    """Sigmas of block ``name``'s parameters (its own units) in the MAP fit on ``cols``:
    sqrt(diag(A^-1) s^2 / ratio), A = G + W (G = X^T X, W the prior weights), ratio = n_eff / n."""
    G, _, _, _ = d.stats()
    A = G.sum(axis=(0, 1))[np.ix_(cols, cols)] + np.diag([d.prior_w[k] * d.prior_scale for k in cols])
    try:
        cov = np.linalg.inv(A + np.eye(len(cols)) * 1e-12 * np.trace(A) / max(len(cols), 1))
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(A)
    pos = {k: j for j, k in enumerate(cols)}
    return np.array([math.sqrt(max(cov[pos[k], pos[k]] * s2 / ratio, 0.0)) / d.scale[k] for k in d.blocks[name]])
