"""Which effect is missing: candidates ranked by held-out explained fraction, forward selection,
fitted parameters with sigmas, plausibility, excitation and equivalence groups.

The linear model of the residuals (``residuals``: r = measured - model at the identified model)::

    r = N eta + B delta_p + sum_c X_c theta_c + e

N: nuisance -- per row the estimator's body-velocity and slip directions (projected out row by
row) and, for the GNSS innovations, the initial attitude, velocity and position (9 columns);
B: the ten identified parameters (eq 20-23, re-identified with every fit, weak prior
delta_p ~ N(0, (0.5 p)^2) so a parameter the drive does not excite stays where it was);
X_c: the columns of candidate c (``candidates``). Every row is divided by its equation's noise
sigma (inverse noise variance weighting per equation; GNSS rows by their sigma).

Explained fraction (``explained_fraction``): the partial R^2 of a candidate on held-out data,
blocked cross-validation::

    EF_c = 1 - SSE_cv(S + c) / SSE_cv(S)

S = the base model (N, B) plus the effects already selected. The drive is cut into micro blocks
of ``micro_block_s`` grouped into ``folds`` contiguous folds; each fold is predicted from a fit
on the other folds minus the micro blocks next to it (a gap, so the autocorrelated noise on
either side of the border does not leak). Per equation the same ratio over that equation's rows.

Forward selection: the candidate with the largest EF is added when (a) its BIC on the effective
sample size improves by more than ``bic_margin``::

    dBIC = n_eff ln(SSE(S + c) / SSE(S)) + p_c ln(n_eff),   n_eff = sum_g n_g / tau_g

(tau_g the integrated autocorrelation time of equation g's residual), (b) EF_c >=
``min_explained_overall`` -- or, for a sensor effect, >= ``min_explained_innovations`` of the
GNSS/IMU innovations, where a sensor error must show (on the force balance alone a sensor effect
needs >= ``min_explained_sensor_balance`` overall); or, for a non-sensor effect whose own equations are
all force/moment balances (no wheel-speed rows), >= ``min_explained_dynamics`` of the ten balance
equations (the kinematic wheel-speed rows, whose whitened misfit dominates the total on a
circle, do not dilute it) -- and >= ``min_explained`` on the candidate's own equations (those
holding >= 10 % of its prior-size contribution), (c) the fitted parameters are physically
plausible (``ParamSpec`` ranges: negative drag and so on are rejected) and (d) the drive excites it: at its generic prior
magnitude the effect would stand ``excitation_z`` noise sigmas (effective) above zero. The first
selected effect is the ``recommendation``.

Equivalence groups: another candidate or an identified parameter A is equivalent to c when A's
columns reproduce c's fitted contribution d_c with R^2 >= ``corr_threshold``^2 (|correlation|
>= 0.95 for one column; a large variance inflation for several) with plausible values. A
re-identified parameter that moved from the model file's value is an entry of its own (its
explained fraction is that of its re-identification) and the effects that would explain the same
change form its group -- e.g. the front cornering stiffness and steering compliance, which a drive
in the linear range cannot tell apart. The recommendation's group also takes in a rival that
passed every selection test on its own (first round) and whose fitted contribution the
recommendation reproduces: both explain the residual, so the drive does not tell them apart
(e.g. tire saturation and load-dependent stiffness on a 5 m/s^2 sine sweep, where either wins the
held-out comparison depending on the seed). Sigmas: (X'X)^-1 s^2 n / n_eff.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import Effect, ImuKinematics
from vdps_hil.model.params import Vehicle

from .candidates import BASE_PARAMS, PARAM_ALIASES, PARAM_LABELS, Candidate, ParameterCandidate, default_candidates
from .dataset import DriveTable
from .residuals import (DYNAMIC_EQUATIONS, EQUATIONS, EquationResiduals, Innovations, RowStates, compute_innovations,
                        compute_residuals, parameter_columns, row_states)

__all__ = ["RankingConfig", "Ranking", "RankEntry", "Context", "Design", "rank", "identify_base",
           "GROUP_NAMES", "SEPARATING_MANEUVERS"]

INNOVATION_GROUPS = ("innov_att", "innov_vel", "innov_pos")
GROUP_NAMES: tuple[str, ...] = EQUATIONS + INNOVATION_GROUPS
"""Row groups: the 14 equations then the GNSS innovations (attitude, velocity, position)."""
_INN_GROUP = {0: 14, 1: 14, 2: 14, 3: 15, 4: 15, 5: 16, 6: 16, 7: 16}


@dataclass(frozen=True)
class RankingConfig:
    """Thresholds of the ranking (module docstring).

    The evidence thresholds were set from the hidden-effect study (seeds 100-103, every effect
    and every nothing-hidden maneuver): the smallest explained fraction of a true hit on its
    evidence path was 0.29 (tire saturation, balance equations; every other effect >= 0.47
    overall or >= 0.95 of the innovations), the largest of a false recommendation 0.16 (IMU
    lever arm on the weaving straight, overall and balance) and 0.56 of the innovations (IMU
    bias on accel-coast). ``min_explained_overall`` = ``min_explained_dynamics`` = 0.2 and
    ``min_explained_innovations`` = 0.8 sit between the two. A sensor effect judged on the force
    balance instead of its innovations needs ``min_explained_sensor_balance`` = 0.3 overall: on
    the weaving straight with nothing hidden the lever arm reached 0.15-0.20 (seeds 102, 1000,
    1004), on the lane change with 0.5 m hidden it explains 0.55-0.73."""

    micro_block_s: float = 0.5
    nuisance_knot_s: float = 2.0
    velocity_sigma_floor_mps: float = 0.02
    velocity_fast_sigma_mps: float = 0.003
    excite_lat_mps2: float = 0.5
    excite_angacc_radps2: float = 0.05
    excite_torque_nm: float = 20.0
    structure_terms: bool = False
    folds: int = 8
    gap_blocks: int = 1
    bic_margin: float = 10.0
    min_explained: float = 0.05
    min_explained_overall: float = 0.2
    min_explained_innovations: float = 0.8
    min_explained_dynamics: float = 0.2
    min_explained_sensor_balance: float = 0.3
    material_fraction: float = 0.1
    corr_threshold: float = 0.95
    excitation_z: float = 5.0
    base_iterations: int = 2
    base_prior_rel_sigma: float = 0.5
    base_bounds: tuple[float, float] = (0.2, 5.0)
    max_effects: int = 3
    shortlist: int = 3
    joint_iterations: int = 1
    profile_steps: int = 5
    identify: tuple[str, ...] = BASE_PARAMS


# ----------------------------------------------------------------------------------- context
class Context:
    """Everything candidates need to build columns at the current (identified) model."""

    def __init__(self, table: DriveTable, vehicle: Vehicle, effects: EffectSet, states: RowStates,
                 res: EquationResiduals, inn: Innovations, fast_sigma_mps: float = 0.003):
        self.table = table
        self.vehicle = vehicle
        self.effects = effects
        self.states = states
        self.res = res
        self.inn = inn
        self.avail = res.available & np.isfinite(res.sigma) & (res.sigma > 0)
        self.rows = np.all(np.isfinite(res.values[:, self.avail]), axis=1)
        sig = res.sigma[self.avail]
        self.sig = sig
        self.y_dyn = res.values[self.rows][:, self.avail] / sig
        jw = res.nuisance[self.rows][:, self.avail, 2:] / sig[None, :, None]
        if len(jw):
            u, s, _ = np.linalg.svd(jw, full_matrices=False)
            keep = s > 1e-9 * np.maximum(s.max(axis=1, keepdims=True), 1e-300)
            self._u = u * keep[:, None, :]
        else:
            self._u = np.zeros((0, int(self.avail.sum()), 4))
        # fast (row to row) body-velocity errors: a soft projection, i.e. whitening with the
        # noise covariance I + J S J^T, J = d r / d(v_x, v_y) (whitened), S = sigma_fast^2
        jv = res.nuisance[self.rows][:, self.avail, :2] / sig[None, :, None]
        self._us = np.zeros((len(jv), int(self.avail.sum()), 2))
        self._fs = np.zeros((len(jv), 2))
        if len(jv) and fast_sigma_mps > 0:
            jv = self._hard(jv) * fast_sigma_mps
            u2, s2, _ = np.linalg.svd(jv, full_matrices=False)
            self._us = u2
            self._fs = 1.0 - 1.0 / np.sqrt(1.0 + s2 * s2)
        self.y_dyn = self.project(self.y_dyn[:, :, None])[:, :, 0]

    def _hard(self, a: np.ndarray, sl: slice = slice(None)) -> np.ndarray:
        u = self._u[sl]
        return a - np.einsum("nek,nkp->nep", u, np.einsum("nek,nep->nkp", u, a))

    def project(self, a: np.ndarray, sl: slice = slice(None)) -> np.ndarray:
        """Remove the row-wise nuisance directions from whitened columns (n, E, p): the
        longitudinal tire forces exactly, the fast velocity errors in proportion to their sigma.
        ``sl``: the used rows ``a`` holds (all by default)."""
        a = self._hard(a, sl)
        us = self._us[sl]
        u = us * self._fs[sl][:, None, :]
        return a - np.einsum("nek,nkp->nep", u, np.einsum("nek,nep->nkp", us, a))

    def smooth_bands(self, knot_s: float, floor_mps: float = 0.02) -> tuple[list, np.ndarray]:
        """The estimator's slowly varying body-velocity errors (delta v_x, delta v_y) as
        piecewise-linear functions of time (hat functions every ``knot_s``), and their prior
        sigmas: the estimator's own velocity sigma near each knot (floored). Each hat function is
        non-zero over two knot intervals only, so each of the 2(K+1) columns is returned whitened
        and projected on the used rows it touches, [(first used row, (r, E))], never as a dense
        (rows, 14, 2(K+1)) array (that grew with the square of the drive's length)."""
        t = self.res.t_s
        if not len(t):
            return [], np.zeros(0)
        tsig, tc = self.table.sigma, self.table.columns
        idx = self.res.index
        sv = np.hypot(tsig["vel_g_mps_e"], tsig["vel_g_mps_n"])[idx] / math.sqrt(2.0)
        speed = np.hypot(tc["vel_g_mps_e"], tc["vel_g_mps_n"])[idx]
        # the body lateral velocity also inherits the heading error: v sigma_psi
        svy = np.hypot(sv, speed * tsig["yaw_g_rad"][idx])
        t0, t1 = float(t[0]), float(t[-1])
        k = max(1, int(math.ceil((t1 - t0) / knot_s)))
        knots = np.linspace(t0, t1, k + 1)
        dk = knots[1] - knots[0] if k else 1.0
        used = np.flatnonzero(self.rows)
        bands, sig = [], np.zeros(2 * (k + 1))
        for j, tk in enumerate(knots):
            i0, i1 = np.searchsorted(t, tk - dk, side="left"), np.searchsorted(t, tk + dk, side="right")
            phi_all = np.clip(1.0 - np.abs(t[i0:i1] - tk) / dk, 0.0, None)
            r0, r1 = np.searchsorted(used, [i0, i1])
            rows = used[r0:r1]
            phi = np.clip(1.0 - np.abs(t[rows] - tk) / dk, 0.0, None)
            for c, sc in enumerate((sv, svy)):
                scn = sc[i0:i1]
                near = (phi_all > 0) & np.isfinite(scn)
                sig[2 * j + c] = max(float(np.median(scn[near])) if near.any() else floor_mps, floor_mps)
                a = self.res.nuisance[rows][:, self.avail, c] * phi[:, None] / self.sig[None, :]
                bands.append((int(r0), self.project(np.nan_to_num(a)[:, :, None], slice(r0, r1))[:, :, 0]))
        return bands, sig

    def whiten_project(self, x14: np.ndarray) -> np.ndarray:
        """(n_all, 14, p) in equation units -> whitened, projected (n, E, p) on the used rows."""
        a = x14[self.rows][:, self.avail, :] / self.sig[None, :, None]
        return self.project(np.nan_to_num(a))

    # --- column builders (equation units, all residual rows)
    def dyn_from_regressors(self, eff: Effect, params: Sequence[str]) -> np.ndarray:
        n = len(self.res.t_s)
        x = np.zeros((n, 14, len(params)))
        idx = {e: k for k, e in enumerate(EQUATIONS)}
        pidx = {p: j for j, p in enumerate(params)}
        for j, q in enumerate(self.res.quantities):
            try:
                regs = eff.regressors(q)
            except (KeyError, ZeroDivisionError, ValueError):
                continue
            for eq, d in regs.items():
                k = idx.get(eq)
                if k is None:
                    continue
                for p, v in d.items():
                    if p in pidx and math.isfinite(v):
                        x[j, k, pidx[p]] = v
        return x

    def dyn_from_fields(self, eff, params: Sequence[str]) -> np.ndarray:
        n = len(self.res.t_s)
        x = np.zeros((n, 14, len(params)))
        c = self.table.columns
        m = self.vehicle.params.mass_kg
        for j, k in enumerate(self.res.index):
            kin = ImuKinematics(0.0, tuple(c[f"specific_force_b_mps2_{a}"][k] for a in "xyz"),
                                tuple(c[f"rate_b_radps_{a}"][k] for a in "xyz"),
                                tuple(c[f"angular_accel_b_radps2_{a}"][k] for a in "xyz"))
            regs = eff.regressors(kin)
            for q, a in enumerate("xyz"):
                d = regs.get(f"specific_force_mps2_{a}", {})
                for pj, p in enumerate(params):
                    x[j, q, pj] = m * d.get(p, 0.0)
        return x

    def dyn_contribution(self, eff: Effect) -> np.ndarray:
        """What the model gains from the effect, in residual units: r(model) - r(model + eff)."""
        eff_set = self.effects + eff if eff.name not in self.effects else self.effects.without(eff.name) + eff
        with_e = compute_residuals(self.table, self.vehicle, eff_set, states=self.states, with_nuisance=False,
                                   with_quantities=False)
        return np.nan_to_num(self.res.values - with_e.values)[:, :, None][:, :, 0]

    def removal(self, name: str) -> np.ndarray:
        """r(model without the named effect) - r(model), equation units (n, 14)."""
        wo = compute_residuals(self.table, self.vehicle, self.effects.without(name), states=self.states,
                               with_nuisance=False, with_quantities=False)
        return np.nan_to_num(wo.values - self.res.values)

    def innovation_columns(self, eff, params) -> np.ndarray:
        if not len(self.inn):
            return np.zeros((0, len(params)))
        return self.inn.effect_columns(eff, params)

    def param_columns(self, param: str) -> np.ndarray:
        return parameter_columns(self.res, param, self.table)[:, :, None]

    def fit_gain(self, x14: np.ndarray) -> float:
        a = self.whiten_project(x14)
        xx = a.reshape(-1, a.shape[2])
        yy = self.y_dyn.reshape(-1)
        g = xx.T @ xx
        c = xx.T @ yy
        try:
            return float(c @ np.linalg.lstsq(g, c, rcond=None)[0])
        except np.linalg.LinAlgError:
            return 0.0


# ----------------------------------------------------------------------------------- design
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
            g_inn = np.array([_INN_GROUP[int(c)] for c in inn.channel])
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
            nu = inn.nuisance / inn.sigma[:, None]
            self.add_block("_nuisance", None, nu)
        sm, sm_sig = ctx.smooth_bands(config.nuisance_knot_s, config.velocity_sigma_floor_mps)
        if sm:
            self._add_band_block("_smooth", sm, sm_sig)

    def _add_band_block(self, name: str, bands, prior_sigma) -> None:
        """Add columns non-zero on a run of dynamic rows only ([(first used row, (r, E))], whitened
        and projected), stored as :class:`_Band` (memory linear in the drive length)."""
        e = self.ctx.y_dyn.shape[1]
        n = len(self.y)
        idx = []
        for j, (r0, a) in enumerate(bands):
            v = a.reshape(-1)
            s = float(np.sqrt(np.sum(v * v) / n)) if n else 0.0
            s = s if s > 0 else 1.0
            self.scale.append(s)
            self.cols.append(_Band(n, r0 * e, v / s))
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
        return any(s > 0 and np.any(_vals(self.cols[k]) != 0) for k in self.blocks[name] for s in [self.scale[k]])

    # --- sufficient statistics
    def stats(self):
        """(G, c, yy, cnt) per (micro block, row group): G a :class:`_BlockGram` (X_bg^T X_bg
        without the dense (blocks, groups, p, p) array), c = X_bg^T y_bg, yy = y_bg^T y_bg, rows."""
        if self._stats is None:
            ng = len(GROUP_NAMES)
            key = self.block * ng + self.group
            shape = (self.n_blocks, ng)
            size = self.n_blocks * ng
            c = np.zeros(shape + (len(self.cols),))
            for j, col in enumerate(self.cols):
                c[:, :, j] = _keysum(key, col, self.y, size).reshape(shape)
            yy = np.bincount(key, self.y * self.y, minlength=size).reshape(shape)
            cnt = np.bincount(key, minlength=size).reshape(shape).astype(float)
            self._stats = (_BlockGram(self, key), c, yy, cnt)
        return self._stats

    def folds(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(held-out micro blocks, training micro blocks) per fold."""
        nb = self.n_blocks
        k = max(2, min(self.cfg.folds, nb // 2))
        edges = np.linspace(0, nb, k + 1).round().astype(int)
        out = []
        for i in range(k):
            held = np.arange(edges[i], edges[i + 1])
            if not len(held):
                continue
            lo, hi = held[0] - self.cfg.gap_blocks, held[-1] + self.cfg.gap_blocks
            train = np.array([b for b in range(nb) if b < lo or b > hi])
            out.append((held, train))
        return out

    def _solve(self, G, c, cols):
        """MAP estimate: (G + W) theta = c + W theta_c (Gaussian priors on some columns)."""
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
        G, c, yy, _ = self.stats()
        cols = list(cols)
        sel = slice(None) if blocks is None else blocks
        Gs = G[sel].sum(axis=(0, 1))
        cs = c[sel].sum(axis=(0, 1))
        if not cols:
            per = yy[sel].sum(axis=0)
            return np.zeros(0), float(per.sum()), per
        th = self._solve(Gs, cs, cols)
        per = self._sse_groups(G[sel], c[sel], yy[sel], cols, th)
        return th, float(per.sum()), per

    def _sse_groups(self, G, c, yy, cols, th):
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
            th = self._solve(G[train].sum(axis=(0, 1)), c[train].sum(axis=(0, 1)), cols)
            out += self._sse_groups(G[held], c[held], yy[held], cols, th)
        return out

    def columns_of(self, names: Sequence[str]) -> list[int]:
        return [k for n in names for k in self.blocks.get(n, [])]

    def matrix(self, cols: Sequence[int]) -> np.ndarray:
        return np.column_stack([_dense(self.cols[k]) for k in cols]) if cols else np.zeros((len(self.y), 0))

    def predict(self, cols: Sequence[int], th) -> np.ndarray:
        """X[:, cols] theta without forming X."""
        out = np.zeros(len(self.y))
        for k, v in zip(cols, th):
            c = self.cols[k]
            if isinstance(c, _Band):
                out[c.lo:c.hi] += v * c.vals
            else:
                out += v * c
        return out


class _Band:
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


def _dense(col) -> np.ndarray:
    return col.dense() if isinstance(col, _Band) else col


def _vals(col) -> np.ndarray:
    return col.vals if isinstance(col, _Band) else col


def _take(col, rows: np.ndarray) -> np.ndarray:
    """col[rows] for sorted row indices (a band without expanding it)."""
    if not isinstance(col, _Band):
        return col[rows]
    out = np.zeros(len(rows))
    i0, i1 = np.searchsorted(rows, [col.lo, col.hi])
    out[i0:i1] = col.vals[rows[i0:i1] - col.lo]
    return out


def _keysum(key: np.ndarray, col, w: np.ndarray, size: int) -> np.ndarray:
    """sum of col * w per key value (bincount; a band over its rows only)."""
    if isinstance(col, _Band):
        return np.bincount(key[col.lo:col.hi], col.vals * w[col.lo:col.hi], minlength=size)
    return np.bincount(key, col * w, minlength=size)


def _gram(cols: Sequence, rows: np.ndarray) -> np.ndarray:
    """X[rows]^T X[rows] for sorted row indices: dense columns as a matrix product, band
    columns only against what overlaps them (linear in the drive length)."""
    p = len(cols)
    g = np.zeros((p, p))
    dense = [k for k, c in enumerate(cols) if not isinstance(c, _Band)]
    bands = [k for k, c in enumerate(cols) if isinstance(c, _Band)]
    d = np.column_stack([cols[k][rows] for k in dense]) if dense else np.zeros((len(rows), 0))
    if dense:
        g[np.ix_(dense, dense)] = d.T @ d
    seg = []
    for k in bands:
        c = cols[k]
        i0, i1 = (int(i) for i in np.searchsorted(rows, [c.lo, c.hi]))
        v = c.vals[rows[i0:i1] - c.lo]
        seg.append((i0, i1, v, k))
        if dense:
            gd = d[i0:i1].T @ v
            g[dense, k] = gd
            g[k, dense] = gd
    seg.sort(key=lambda z: z[0])
    for a, (i0, i1, va, ka) in enumerate(seg):
        for j0, j1, vb, kb in seg[a:]:
            if j0 >= i1:
                break
            lo, hi = max(i0, j0), min(i1, j1)
            if lo < hi:
                g[ka, kb] = g[kb, ka] = float(va[lo - i0:hi - i0] @ vb[lo - j0:hi - j0])
    return g


class _BlockGram:
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

    def __init__(self, d: "Design", key: np.ndarray, blocks: np.ndarray | None = None, shared: dict | None = None):
        self.d = d
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
                    per[g] = _gram(self.cols, rows)
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
        return _BlockGram(self.d, self.key, self.blocks[idx], self._shared)

    def _entries(self, idx):
        """G[:, :, :, k] -> (b, g, p) and G[:, :, k, k] -> (b, g) on this block subset."""
        if len(idx) != 4 or idx[0] != slice(None) or idx[1] != slice(None):
            raise IndexError("unsupported _BlockGram index")
        k = idx[3]
        rows = self.rows()
        key = self.key[rows]
        size = self.d.n_blocks * self.ng
        shape = (self.d.n_blocks, self.ng)
        xk = _take(self.cols[k], rows)
        if idx[2] == slice(None):
            out = np.zeros(shape + (len(self.cols),))
            for j, col in enumerate(self.cols):
                out[:, :, j] = np.bincount(key, _take(col, rows) * xk, minlength=size).reshape(shape)
            return out[self.blocks]
        j = idx[2]
        return np.bincount(key, _take(self.cols[j], rows) * xk, minlength=size).reshape(shape)[self.blocks]

    def sum(self, axis):
        total, per = self._totals()
        full = len(self.blocks) == self.d.n_blocks and np.array_equal(self.blocks, np.arange(self.d.n_blocks))
        if axis == 0 or tuple(axis) == (0,):
            if full:
                return per.copy()
            raise ValueError("_BlockGram.sum(axis=0) only over all blocks")
        if tuple(axis) != (0, 1):
            raise ValueError("unsupported _BlockGram.sum axis")
        if full:
            return total.copy()
        ck = ("sum", self.blocks.tobytes())
        if ck not in self._shared:
            rows = self.rows()
            if 2 * len(rows) <= len(self.d.y):
                self._shared[ck] = _gram(self.cols, rows)
            else:
                out = np.ones(len(self.d.y), bool)
                out[rows] = False
                self._shared[ck] = total - _gram(self.cols, np.flatnonzero(out))
        return self._shared[ck].copy()

    def quad(self, cols: Sequence[int], th: np.ndarray) -> np.ndarray:
        """theta^T G_bg[cols, cols] theta per (block of this subset, group): (b, g)."""
        rows = self.rows()
        r = np.zeros(len(rows))
        for j, k in enumerate(cols):
            if th[j] != 0.0:
                c = self.cols[k]
                if isinstance(c, _Band):
                    i0, i1 = np.searchsorted(rows, [c.lo, c.hi])
                    r[i0:i1] += th[j] * c.vals[rows[i0:i1] - c.lo]
                else:
                    r += th[j] * c[rows]
        size = self.d.n_blocks * self.ng
        q = np.bincount(self.key[rows], r * r, minlength=size).reshape(self.d.n_blocks, self.ng)
        return q[self.blocks]


# ----------------------------------------------------------------------------------- results
@dataclass
class RankEntry:
    """One ranked candidate (an effect or an identified parameter)."""

    effect: str
    kind: str
    explained_fraction: float
    explained_by_equation: dict[str, float]
    parameters: dict[str, tuple[float, float]]
    plausible: bool
    excited: bool
    excitation_z: float
    group: list[str]
    selected: bool = False
    delta_bic: float = math.nan
    message: str = ""
    reference: dict[str, float] = field(default_factory=dict)
    explained_gain_by_equation: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"effect": self.effect, "kind": self.kind, "explained_fraction": _num(self.explained_fraction),
                "explained_by_equation": {k: _num(v) for k, v in self.explained_by_equation.items()},
                "parameters": {k: {"value": _num(v), "sigma": _num(s)} for k, (v, s) in self.parameters.items()},
                "plausible": bool(self.plausible), "excited": bool(self.excited),
                "excitation_z": _num(self.excitation_z), "group": list(self.group), "selected": bool(self.selected),
                "delta_bic": _num(self.delta_bic), "message": self.message}


def _num(v):
    return None if v is None or not math.isfinite(float(v)) else float(v)


@dataclass
class Ranking:
    """The outcome (``to_json`` has the issue's keys ``ranking``, ``recommendation``,
    ``equivalent_to``; ``before``/``after`` are added by the CLI)."""

    entries: list[RankEntry]
    parameters: list[RankEntry]
    recommendation: str | None
    equivalent_to: list[str]
    selected: list[str]
    groups: list[dict]
    messages: list[str]
    n_eff: float
    n_rows: int
    base_vehicle: Vehicle
    reference_vehicle: Vehicle
    effects: EffectSet
    context: Context = field(repr=False, default=None)
    design: Design = field(repr=False, default=None)
    candidates: dict = field(repr=False, default_factory=dict)
    thetas: dict = field(repr=False, default_factory=dict)

    def entry(self, name: str) -> RankEntry | None:
        for e in self.entries + self.parameters:
            if e.effect == name:
                return e
        return None

    def to_json(self) -> dict:
        return {"ranking": [e.to_json() for e in self.entries],
                "recommendation": self.recommendation, "equivalent_to": list(self.equivalent_to),
                "selected": list(self.selected), "groups": self.groups,
                "identified_parameters": [e.to_json() for e in self.parameters],
                "messages": list(self.messages), "n_eff": self.n_eff}


# ----------------------------------------------------------------------------------- identification
def _base_columns(ctx: Context, params: Sequence[str]) -> dict[str, np.ndarray]:
    return {p: ctx.param_columns(p) for p in params}


def identify_base(table: DriveTable, vehicle: Vehicle, effects: EffectSet, states: RowStates,
                  inn: Innovations, config: RankingConfig, reference: Vehicle | None = None) -> tuple[Vehicle, dict[str, float]]:
    """Batch re-identification of the ten parameters on the residual equations: Gauss-Newton on
    the MAP objective (weak prior around ``reference``, the model file's values) with step
    halving, until the objective improves by less than 0.1 %. Returns (vehicle, sigmas)."""
    point, d, cols, sig = _identify(table, vehicle, effects, states, inn, config, reference)
    return point.base, sig


def _identify(table, vehicle, effects, states, inn, config, reference=None, phis=None, selected=None):
    ref = reference or vehicle
    selected = selected or {}
    point = _Point(vehicle, effects, dict(phis or {}))
    _, d, cols = _build(table, states, inn, ref, point, config, selected)
    th, obj = d.objective(cols)
    for _ in range(config.base_iterations):
        new = _apply_base(point, d, cols, th, config, ref)
        step, accepted = 1.0, None
        for _h in range(3):
            nb = new if step == 1.0 else _interp_base(point.base, new, step, config)
            pt = _Point(nb, effects, dict(point.phis))
            _, d2, cols2 = _build(table, states, inn, ref, pt, config, selected)
            th2, obj2 = d2.objective(cols2)
            if obj2 <= obj * 1.001 + 1e-9 or step < 0.3:
                accepted = (pt, d2, cols2, th2, obj2)
                break
            step *= 0.5
        improved = obj - accepted[4]
        point, d, cols, th, obj_new = accepted
        done = improved < 1e-3 * max(obj, 1e-300)
        obj = obj_new
        if done:
            break
    G = d.stats()[0].sum(axis=(0, 1))
    pw = np.array(d.prior_w) * d.prior_scale
    A = G[np.ix_(cols, cols)] + np.diag(pw[cols])
    try:
        cov = np.linalg.inv(A + np.eye(len(A)) * 1e-12 * np.trace(A) / len(A))
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(A)
    pos = {k: j for j, k in enumerate(cols)}
    sig = {p: math.sqrt(max(cov[pos[d.blocks[p][0]], pos[d.blocks[p][0]]], 0.0)) / d.scale[d.blocks[p][0]]
           for p in config.identify if p in d.blocks}
    return point, d, cols, sig


def _row_mask(d: Design, ctx: Context, mask: np.ndarray) -> np.ndarray:
    """Design rows whose time falls on table rows where ``mask`` is True."""
    tmask = np.asarray(mask, bool)
    t_ok = ctx.table.t_s[tmask]
    if not len(t_ok):
        return np.zeros(len(d.y), bool)
    lo, hi = t_ok[0], t_ok[-1]
    n, e = ctx.y_dyn.shape
    t_dyn = np.repeat(ctx.res.t_s[ctx.rows], e)
    t_inn = ctx.inn.t_s if len(ctx.inn) else np.zeros(0)
    t_all = np.concatenate([t_dyn, t_inn])
    return (t_all >= lo) & (t_all <= hi)


# ----------------------------------------------------------------------------------- ranking
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


def _n_eff(d: Design, resid: np.ndarray) -> float:
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


@dataclass
class _Point:
    """A linearisation point: identified parameters and the model's effects (incl. selected)."""

    base: Vehicle
    effects: EffectSet
    phis: dict


@dataclass
class _Joint:
    name: str
    phi: np.ndarray
    sigma: np.ndarray
    point: "_Point"
    sse: float
    cv: np.ndarray
    design: "Design"
    cols: list
    sse_without: float = math.nan  # the same linearisation point without the candidate
    cv_without: np.ndarray | None = None


def _effects_with(effects: EffectSet, eff: Effect) -> EffectSet:
    return (effects.without(eff.name) if eff.name in effects else effects) + eff


def _build(table, states, inn, ref: Vehicle, point: _Point, cfg: RankingConfig, selected: dict,
           screen: Sequence[Candidate] = ()):
    """Design at a linearisation point: nuisance, the ten parameters, the selected effects'
    change columns (always on) and the screening columns of ``screen``."""
    res = compute_residuals(table, point.base, point.effects, states=states)
    ctx = Context(table, point.base, point.effects, states, res, inn, cfg.velocity_fast_sigma_mps)
    d = Design(ctx, cfg)
    d.prior_scale = states.prior_scale if getattr(states, "prior_scale", None) is not None else 1.0
    if getattr(states, "excited_params", None) is None:
        states.excited_params = excited_parameters(table, states, cfg)
    for p in cfg.identify:
        if p not in states.excited_params:
            continue
        pv = getattr(ref.params, p)
        d.add_block(p, ctx.param_columns(p), None, prior_sigma=[cfg.base_prior_rel_sigma * abs(pv)],
                    prior_center=[pv - getattr(point.base.params, p)])
    names = ["_nuisance", "_smooth", *cfg.identify]
    if cfg.structure_terms:
        d.add_block("_structure", structure_columns(res), None)
        names.insert(2, "_structure")
    for name, c in selected.items():
        phi = point.phis[name]
        xd, xi = c.delta_columns(ctx, phi)
        if xi is not None:
            d.shift_innovations(xi, phi)
        ps = c.phi_prior_sigma()
        if ps is not None:
            centre = c.to_phi(c.prior_theta()) - np.asarray(phi, dtype=float)
            d.add_block(name, xd, xi, prior_sigma=list(ps), prior_center=list(centre))
        else:
            d.add_block(name, xd, xi)
        names.append(name)
    if getattr(states, "prior_scale", None) is None:
        # the residual rows are autocorrelated: their weight against the (independent) priors is
        # n_eff / n, measured once per drive on the residual of this first fit
        cols = d.columns_of(names)
        th, _ = d.objective(cols)
        states.prior_scale = max(1.0, len(d.y) / _n_eff(d, d.y - d.predict(cols, th)))
        d.prior_scale = states.prior_scale
        d._stats = None
    for c in screen:
        xd, xi = c.columns(ctx)
        d.add_block(c.name, xd, xi)
    return ctx, d, d.columns_of(names)


def structure_columns(res: EquationResiduals) -> np.ndarray:
    """Known simplifications of the paper's reduced model, absorbed so that they are not taken
    for a missing effect (always fitted, no prior): the unsprung masses (about 10 % of the mass)
    ride with the body in eq 13 but stay on the road when the body rolls, which adds a lateral
    force ~ m_u h p_dot. Column: lateral equation ~ roll acceleration."""
    n = len(res.t_s)
    out = np.zeros((n, 14, 1))
    if n and res.meas is not None:
        out[:, 1, 0] = res.meas[:, 3]
    return out


def excited_parameters(table: DriveTable, states: RowStates, cfg: RankingConfig) -> set[str]:
    """The identified parameters this drive excites (as the paper's RLS gates its rows): a
    parameter whose driving signal hardly varies is held at the model file's value.

    ===============================  ===========================================================
    parameter                        excited when (std over the usable rows)
    ===============================  ===========================================================
    mass                             always (eq 20: the suspension carries it at rest)
    cornering stiffnesses            lateral specific force >= ``excite_lat_mps2``
    roll / pitch / yaw inertia       angular acceleration about that axis >= ``excite_angacc_radps2``
    slip stiffness of wheel i        its wheel torque >= ``excite_torque_nm``
    ===============================  ===========================================================
    """
    c = table.columns
    idx = states.index
    out = {"mass_kg"}

    def sd(name):
        v = c[name][idx]
        v = v[np.isfinite(v)]
        return float(np.std(v)) if len(v) > 10 else 0.0

    if sd("specific_force_b_mps2_y") >= cfg.excite_lat_mps2:
        out |= {"cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad"}
    for a, p in zip("xyz", ("inertia_x_kgm2", "inertia_y_kgm2", "inertia_z_kgm2")):
        if sd(f"angular_accel_b_radps2_{a}") >= cfg.excite_angacc_radps2:
            out.add(p)
    for i in range(1, 5):
        if sd(f"wheel_torque_nm_{i}") >= cfg.excite_torque_nm:
            out.add(f"tracking_stiffness_{i}_n")
    return out & set(cfg.identify)


def _apply_base(point: _Point, d: Design, cols, th, cfg: RankingConfig, ref: Vehicle) -> Vehicle:
    pos = {k: j for j, k in enumerate(cols)}
    lo, hi = cfg.base_bounds
    changes = {}
    for p in cfg.identify:
        if p not in d.blocks or d.blocks[p][0] not in pos:
            continue
        k = d.blocks[p][0]
        pv = getattr(ref.params, p)
        changes[p] = min(max(getattr(point.base.params, p) + th[pos[k]] / d.scale[k], lo * pv), hi * pv)
    return point.base.with_params(**changes)


def _joint(table, states, inn, ref, point: _Point, selected: dict, c: Candidate, theta0, cfg: RankingConfig,
           ratio: float, obj0: float, cv0: np.ndarray) -> _Joint | None:
    """A nonlinear candidate (one parameter): profile of the MAP objective over its parameter
    with the ten parameters (and selected effects) re-fitted at every value (golden section in
    log phi over ``c.profile_range``); the design at the best value gives its evidence, compared
    with the current model (``obj0``, ``cv0``)."""
    cache: dict[float, tuple] = {}

    def build(logphi: float):
        key = round(logphi, 6)
        if key in cache:
            return cache[key]
        phi = np.array([math.exp(logphi)])
        try:
            eff = _effects_with(point.effects, c.phi_effect(phi))
        except ValueError:
            cache[key] = None
            return None
        pt = _Point(point.base, eff, {**point.phis, c.name: phi})
        _, d, always = _build(table, states, inn, ref, pt, cfg, selected)
        th, obj = d.objective(always)
        cache[key] = (obj, pt, d, always, phi)
        return cache[key]

    def f(logphi):
        r = build(logphi)
        return r[0] if r is not None else math.inf

    lo, hi = (math.log(v) for v in getattr(c, "profile_range", (0.3, 3.0)))
    gr = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    x1, x2 = b - gr * (b - a), a + gr * (b - a)
    f1, f2 = f(x1), f(x2)
    for _ in range(cfg.profile_steps):
        if f1 < f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - gr * (b - a)
            f1 = f(x1)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + gr * (b - a)
            f2 = f(x2)
    best = min((v for v in cache.values() if v is not None), key=lambda v: v[0], default=None)
    if best is None:
        return None
    obj, pt, d, always, phi = best
    xd, xi = c.delta_columns(d.ctx, phi)
    d.add_block(c.name, xd, xi)
    cols = always + d.blocks[c.name]
    _, obj_c = d.objective(cols)
    s2 = obj_c / max(len(d.y) - len(cols), 1)
    sig = _sigma_of(d, c.name, cols, s2, ratio)
    return _Joint(c.name, phi, sig, pt, obj, d.cv(always), d, cols, obj0, cv0)


def _linear_joint(d: Design, always, c: Candidate, theta, point: _Point, cfg: RankingConfig, ref: Vehicle,
                  ratio: float) -> _Joint:
    """A candidate whose columns do not depend on its parameters: the screening design already
    is its joint fit (the ten parameters enter linearly)."""
    cols = always + d.blocks[c.name]
    th, obj = d.objective(cols)
    phi = _theta_of(d, c.name, cols, th)
    s2 = obj / max(len(d.y) - len(cols), 1)
    sig = _sigma_of(d, c.name, cols, s2, ratio)
    base = _apply_base(point, d, cols, th, cfg, ref)
    try:
        eff = _effects_with(point.effects, c.phi_effect(phi))
    except ValueError:
        eff = point.effects
    pt = _Point(base, eff, {**point.phis, c.name: phi})
    return _Joint(c.name, phi, sig, pt, obj, d.cv(cols), d, cols)


def _interp_base(a: Vehicle, b: Vehicle, w: float, cfg: RankingConfig) -> Vehicle:
    return a.with_params(**{p: getattr(a.params, p) + w * (getattr(b.params, p) - getattr(a.params, p))
                            for p in cfg.identify})


def _prior_contribution(G: np.ndarray, base: list, d, name: str, c) -> tuple[float, float]:
    """(v, v_base) of candidate ``name`` at its generic prior magnitude: v = th' G_cc th, its
    weighted sum of squares over the drive, and v_base = g' G_bb^+ g (g = G_bc th), the part of
    it the ``base`` columns reproduce (0 without base columns)."""
    cols = d.blocks[name]
    th = c.prior_theta() * np.array([d.scale[k] for k in cols])
    vv = float(th @ G[np.ix_(cols, cols)] @ th)
    if not len(base):
        return vv, 0.0
    gbv = G[np.ix_(base, cols)] @ th
    return vv, float(gbv @ np.linalg.lstsq(G[np.ix_(base, base)], gbv, rcond=None)[0])


def rank(table: DriveTable, vehicle: Vehicle, effects: EffectSet | Sequence[Effect] = (), *,
         candidates: Sequence[Candidate] | None = None, user_effects: Sequence[type[Effect]] = (),
         config: RankingConfig | None = None, mask: np.ndarray | None = None) -> Ranking:
    """Identify the model on the drive, then rank the effect candidates (module docstring).

    ``vehicle``: the model vehicle (its parameters are the reference/priors); ``effects``: the
    model's effects (from ``--model``); ``candidates``: default every registered effect not in the
    model plus ``user_effects``; ``mask``: table rows to use (default all)."""
    cfg = config or RankingConfig()
    effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
    if mask is not None:
        table = table.slice(mask)
    states = row_states(table, vehicle)
    if len(states.index) < 50:
        raise ValueError("too few usable rows (moving faster than 5 m/s with every signal present)")
    inn = compute_innovations(table)
    point, d, always, _ = _identify(table, vehicle, effects, states, inn, cfg, reference=vehicle)
    cands = list(candidates) if candidates is not None else default_candidates(effects, user_effects)
    by_name: dict[str, Candidate] = {c.name: c for c in cands}
    selected: dict[str, Candidate] = {}
    ctx = d.ctx
    for c in cands:
        xd, xi = c.columns(ctx)
        d.add_block(c.name, xd, xi)
    th0, sse_cur = d.objective(always)
    r0 = d.y - d.predict(always, th0)
    n_eff = _n_eff(d, r0)
    n_rows = len(d.y)
    ratio = n_eff / n_rows
    cv_cur = d.cv(always)
    # excitation of every candidate at its generic prior magnitude (beyond what the base absorbs)
    excit = {}
    G = d.stats()[0].sum(axis=(0, 1))
    for name, c in by_name.items():
        vv, vb = _prior_contribution(G, always, d, name, c)
        excit[name] = math.sqrt(max(vv - vb, 0.0) * ratio)
    # an effect that acts through the tires' lateral forces cannot be judged when the tires carry
    # no lateral load: the slip angles are then the estimator's noise (as for the cornering
    # stiffnesses, ``excited_parameters``)
    Gg = d.stats()[0].sum(axis=0)
    lateral = [GROUP_NAMES.index(g) for g in ("lat", "roll", "yaw")]
    lat_ok = "cornering_stiffness_front_nprad" in (states.excited_params or set()) or \
        "cornering_stiffness_front_nprad" not in cfg.identify
    # a candidate whose prior-size contribution the ten parameters reproduce (R^2 >= 0.95^2) is
    # the same as a re-identification on this drive (e.g. steering compliance and the front
    # cornering stiffness in the linear range): never a recommendation, reported as a group
    base_cols = d.columns_of(list(cfg.identify))
    base_equiv: dict[str, float] = {}
    if base_cols:
        for name, c in by_name.items():
            vv, vb = _prior_contribution(G, base_cols, d, name, c)
            if vv > 0:
                base_equiv[name] = vb / vv
    own_groups: dict[str, np.ndarray] = {}
    for name, c in by_name.items():
        cols = d.blocks[name]
        th = c.prior_theta() * np.array([d.scale[k] for k in cols])
        e_g = np.array([float(th @ Gg[g][np.ix_(cols, cols)] @ th) for g in range(len(GROUP_NAMES))])
        # the candidate's own equations: where its prior-size contribution has >= 10 % of its energy
        own_groups[name] = e_g >= 0.1 * e_g.sum() if e_g.sum() > 0 else np.zeros(len(GROUP_NAMES), bool)
        if e_g.sum() > 0 and e_g[lateral].sum() >= 0.5 * e_g.sum() and not lat_ok:
            excit[name] = 0.0
    joints: dict[str, _Joint] = {}
    steps: dict[str, dict] = {}
    for _ in range(cfg.max_effects):
        screen = []
        for name, c in by_name.items():
            if name in selected or not d.has_signal(name) or excit[name] < cfg.excitation_z:
                continue
            cols = always + d.blocks[name]
            ef = 1.0 - d.cv(cols).sum() / max(cv_cur.sum(), 1e-300)
            th, _, _ = d.fit(cols)
            screen.append((ef, name, _theta_of(d, name, cols, th)))
        screen.sort(key=lambda t: -t[0])
        best = None
        short = [t for t in screen[:cfg.shortlist] if t[0] > 0.0]
        # nonlinear candidates are judged by their joint fit in any case: at a linearisation
        # point far from the truth their screening column can hide them
        short += [t for t in screen[cfg.shortlist:] if not by_name[t[1]].linear
                  and (t[1] not in steps or steps[t[1]]["ef"] > 0.5 * cfg.min_explained)]
        for ef_s, name, theta in short:
            c = by_name[name]
            if c.linear:
                j = _linear_joint(d, always, c, theta, point, cfg, vehicle, ratio)
            else:
                j = _joint(table, states, inn, vehicle, point, selected, c, theta, cfg, ratio, sse_cur, cv_cur)
            if j is None:
                continue
            cvb = j.cv_without if j.cv_without is not None else cv_cur
            sseb = j.sse_without if math.isfinite(j.sse_without) else sse_cur
            ef = 1.0 - j.cv.sum() / max(cvb.sum(), 1e-300)
            own = own_groups.get(name)
            ef_own = 1.0 - j.cv[own].sum() / max(cvb[own].sum(), 1e-300) if own is not None and own.any() else ef
            dbic = n_eff * math.log(max(j.sse, 1e-300) / max(sseb, 1e-300)) + len(j.phi) * math.log(n_eff)
            steps[name] = {"ef": ef, "ef_own": ef_own, "dbic": dbic, "joint": j, "cv_before": cvb}
            if os.environ.get("VDPS_WB_DEBUG"):
                print(f"[ranking] {name}: ef {ef:.3f} own {ef_own:.3f} dbic {dbic:.1f} phi {j.phi} "
                      f"inn {1.0 - j.cv[-3:].sum() / max(cvb[-3:].sum(), 1e-300):.3f} "
                      f"plausible {c.phi_plausible(j.phi)} material {c.material(j.phi, cfg.material_fraction)}")
            joints[name] = j
            inn_g = np.array([GROUP_NAMES.index(g) for g in INNOVATION_GROUPS])
            ef_inn = 1.0 - j.cv[inn_g].sum() / max(cvb[inn_g].sum(), 1e-300)
            steps[name]["ef_innovations"] = ef_inn
            # enough of the residual overall -- or, for a sensor effect, of the GNSS/IMU
            # innovations, where a sensor error shows even when the force balance hardly sees it
            # or, for an effect on the force balance alone (no kinematic rows among its own
            # equations), of the ten balance equations of eq 13
            dyn_g = np.arange(len(DYNAMIC_EQUATIONS))
            ef_dyn = 1.0 - j.cv[dyn_g].sum() / max(cvb[dyn_g].sum(), 1e-300)
            steps[name]["ef_dynamics"] = ef_dyn
            balance_only = own is not None and own.any() and not own[len(DYNAMIC_EQUATIONS):].any()
            if c.family == "measurement":
                # a sensor error shows in the innovations; through the force balance alone it
                # must explain more, as its several parameters also fit the reduced model's own
                # shortcomings (a lateral force lagging the slip looks like a lever arm on a weave)
                evidence = ef_inn >= cfg.min_explained_innovations or ef >= max(
                    cfg.min_explained_overall, cfg.min_explained_sensor_balance)
            else:
                evidence = ef >= cfg.min_explained_overall or (balance_only and ef_dyn >= cfg.min_explained_dynamics)
            if os.environ.get("VDPS_WB_DEBUG"):
                print(f"[ranking] {name}: ef_dyn {ef_dyn:.3f} balance_only {balance_only}")
            if base_equiv.get(name, 0.0) >= cfg.corr_threshold ** 2:
                evidence = False  # the same as re-identifying a parameter: reported as a group
            ok = (dbic < -cfg.bic_margin and ef_own >= cfg.min_explained and ef > 0.0 and evidence
                  and c.phi_plausible(j.phi) and c.material(j.phi, cfg.material_fraction))
            if not selected:
                steps[name]["eligible_first"] = bool(ok)
            if ok and (best is None or ef > best[1]):
                best = (name, ef, j)
        if best is None:
            break
        name, ef, j = best
        selected[name] = by_name[name]
        point = j.point
        rest = [c for n, c in by_name.items() if n not in selected]
        ctx, d, always = _build(table, states, inn, vehicle, point, cfg, selected, rest)
        th_c, sse_cur = d.objective(always)
        cv_cur = d.cv(always)
    # final entries on the design at the final point
    th_fin, sse_fin, _ = d.fit(always)
    s2 = sse_fin / max(n_rows - len(always), 1)
    entries = []
    thetas = {}
    for name, c in by_name.items():
        if name in selected:
            st = steps[name]
            j = st["joint"]
            cvb = st["cv_before"]
            per, gain = {}, {}
            for g, gname in enumerate(GROUP_NAMES):
                if cvb[g] > 0 and _group_has_signal(j.design, name, g):
                    per[gname] = float(1.0 - j.cv[g] / cvb[g])
                    gain[gname] = float(cvb[g] - j.cv[g])
            phi = point.phis[name]
            sig = _sigma_of(d, name, always, s2, ratio)
            thetas[name] = np.array([t * 0 for t in phi])
            entries.append(RankEntry(effect=name, kind=c.kind, explained_fraction=st["ef"], explained_by_equation=per,
                                     parameters=c.phi_report(phi, sig), plausible=c.phi_plausible(phi),
                                     excited=True, excitation_z=excit[name], group=[], selected=True,
                                     delta_bic=st["dbic"], explained_gain_by_equation=gain))
            continue
        cols = always + d.blocks[name]
        cv_w = d.cv(cols)
        ef = 1.0 - cv_w.sum() / max(cv_cur.sum(), 1e-300)
        per, gain = {}, {}
        for g, gname in enumerate(GROUP_NAMES):
            if cv_cur[g] > 0 and _group_has_signal(d, name, g):
                per[gname] = float(1.0 - cv_w[g] / cv_cur[g])
                gain[gname] = float(cv_cur[g] - cv_w[g])
        th, sse_w, _ = d.fit(cols)
        theta = _theta_of(d, name, cols, th)
        sig = _sigma_of(d, name, cols, s2, ratio)
        thetas[name] = theta
        jt = joints.get(name)
        if jt is not None and name in steps:
            dbic = steps[name]["dbic"]
            params = c.phi_report(jt.phi, jt.sigma)
            plaus = c.phi_plausible(jt.phi)
        else:
            dbic = n_eff * math.log(max(sse_w, 1e-300) / max(sse_fin, 1e-300)) + len(d.blocks[name]) * math.log(n_eff)
            params = c.report_params(theta, sig)
            plaus = c.plausible(theta)
        entries.append(RankEntry(effect=name, kind=c.kind, explained_fraction=ef, explained_by_equation=per,
                                 parameters=params, plausible=plaus,
                                 excited=excit[name] >= cfg.excitation_z, excitation_z=excit[name], group=[],
                                 selected=False, delta_bic=dbic, explained_gain_by_equation=gain))
    order = list(selected)
    entries.sort(key=lambda e: (order.index(e.effect) if e.effect in order else len(order),
                                -(e.explained_fraction if math.isfinite(e.explained_fraction) else -1)))
    params = _parameter_entries(d, d.ctx, vehicle, point.base, always, ratio, s2, cfg)
    _groups(d, by_name, entries, params, always, thetas, cfg, n_eff, sse_fin, selected, point.phis)
    groups = _group_list(entries, params)
    rec = order[0] if order else None
    eq_to = []
    if rec:
        rec_e = next(e for e in entries if e.effect == rec)
        # a rival that passed every selection test on its own in the first round and whose fitted
        # contribution the recommendation reproduces: both explain the residual, the drive does
        # not tell them apart (the one with the larger held-out explained fraction leads)
        for e in entries:
            if (e.effect != rec and rec in e.group and steps.get(e.effect, {}).get("eligible_first")
                    and e.effect not in rec_e.group):
                rec_e.group = (rec_e.group or [rec]) + [e.effect]
        eq_to = [g for g in rec_e.group if g != rec]
        groups = _group_list(entries, params)
    rk = Ranking(entries=entries, parameters=params, recommendation=rec, equivalent_to=eq_to, selected=order,
                 groups=groups, messages=[], n_eff=n_eff, n_rows=n_rows, base_vehicle=point.base,
                 reference_vehicle=vehicle, effects=point.effects, context=d.ctx, design=d, candidates=by_name,
                 thetas=thetas)
    from .words import describe_ranking
    rk.messages = describe_ranking(rk)
    for e in rk.entries + rk.parameters:
        e.message = rk_message(rk, e)
    return rk


def rk_message(rk: Ranking, e: RankEntry) -> str:
    from .words import describe_entry
    return describe_entry(rk, e)


def _group_has_signal(d: Design, name: str, g: int) -> bool:
    rows = d.group == g
    rows = np.flatnonzero(rows)
    return any(np.any(_take(d.cols[k], rows) != 0) for k in d.blocks[name])


def _theta_of(d: Design, name: str, cols: Sequence[int], th: np.ndarray) -> np.ndarray:
    pos = {k: j for j, k in enumerate(cols)}
    return np.array([th[pos[k]] / d.scale[k] for k in d.blocks[name]])


def _sigma_of(d: Design, name: str, cols: Sequence[int], s2: float, ratio: float) -> np.ndarray:
    G, _, _, _ = d.stats()
    A = G.sum(axis=(0, 1))[np.ix_(cols, cols)] + np.diag([d.prior_w[k] * d.prior_scale for k in cols])
    try:
        cov = np.linalg.inv(A + np.eye(len(cols)) * 1e-12 * np.trace(A) / max(len(cols), 1))
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(A)
    pos = {k: j for j, k in enumerate(cols)}
    return np.array([math.sqrt(max(cov[pos[k], pos[k]] * s2 / ratio, 0.0)) / d.scale[k] for k in d.blocks[name]])


def _parameter_entries(d: Design, ctx: Context, ref: Vehicle, base: Vehicle, current, ratio, s2,
                       cfg: RankingConfig) -> list[RankEntry]:
    """The identified parameters as entries: value, sigma, explained fraction of moving each
    from the reference (model file) value to the identified one."""
    out = []
    G, c, yy, _ = d.stats()
    th_all, _, _ = d.fit(current)
    pos = {k: j for j, k in enumerate(current)}
    for p in cfg.identify:
        ref_v = getattr(ref.params, p)
        cur = getattr(base.params, p)
        if p not in d.blocks:
            out.append(RankEntry(effect=PARAM_ALIASES[p], kind="parameter", explained_fraction=0.0,
                                 explained_by_equation={}, parameters={p: (cur, math.nan)}, plausible=cur > 0,
                                 excited=False, excitation_z=math.nan, group=[], reference={p: ref_v}))
            continue
        k = d.blocks[p][0]
        # residual with the parameter back at the reference: y + X_p (ref - cur) ... in scaled units
        shift = (ref_v - cur) * d.scale[k]
        others = [j for j in current if j != k]
        cv_ref = _cv_shifted(d, others, k, shift)
        cv_fit = d.cv(current)
        ef = 1.0 - cv_fit.sum() / max(cv_ref.sum(), 1e-300)
        sig = _sigma_of(d, p, current, s2, ratio)[0]
        val = cur + th_all[pos[k]] / d.scale[k]
        e = RankEntry(effect=PARAM_ALIASES[p], kind="parameter", explained_fraction=ef, explained_by_equation={},
                      parameters={p: (val, sig)}, plausible=val > 0, excited=True, excitation_z=math.nan,
                      group=[], reference={p: ref_v})
        out.append(e)
    out.sort(key=lambda e: -e.explained_fraction)
    return out


def _cv_shifted(d: Design, cols, k: int, shift: float) -> np.ndarray:
    """Held-out SSE per group with column k fixed at -shift (i.e. y replaced by y + shift x_k)."""
    G, c, yy, _ = d.stats()
    # y' = y + s x_k: c' = c + s G[:, k], yy' = yy + 2 s c_k + s^2 G_kk
    c2 = c + shift * G[:, :, :, k]
    yy2 = yy + 2.0 * shift * c[:, :, k] + shift * shift * G[:, :, k, k]
    out = np.zeros(len(GROUP_NAMES))
    cols = list(cols)
    for held, train in d.folds():
        th = d._solve(G[train].sum(axis=(0, 1)), c2[train].sum(axis=(0, 1)), cols)
        cc = c2[held][:, :, cols]
        v = yy2[held] - 2.0 * np.einsum("bgp,p->bg", cc, th) + G[held].quad(cols, th)
        out += v.sum(axis=0)
    return out


def _groups(d: Design, by_name, entries, params, current, thetas, cfg: RankingConfig, n_eff: float = 1.0,
            sse: float = 1.0, selected=(), phis: dict | None = None) -> None:
    """Fill each entry's ``group`` (module docstring), in Gram-matrix form with the GNSS
    nuisance partialled out."""
    r2min = cfg.corr_threshold ** 2
    # a selected nonlinear effect: its whole contribution (the residual it removes), not the
    # direction of a change of its parameter
    contrib = {}
    for e in entries:
        if e.selected and not by_name[e.effect].linear and e.effect in d.ctx.effects:
            contrib[e.effect] = d.add_block(f"_contrib:{e.effect}", d.ctx.removal(e.effect)[:, :, None], None)
    G = d.stats()[0].sum(axis=(0, 1))
    nu = d.columns_of(["_nuisance", "_smooth", "_structure"])
    if nu:
        gnn = G[np.ix_(nu, nu)]
        gp = G - G[:, nu] @ np.linalg.lstsq(gnn, G[nu, :], rcond=None)[0]
    else:
        gp = G

    def mimic(th_a, cols_a, name, significance: bool = True) -> tuple[float, np.ndarray]:
        cols = d.blocks[name]
        vv = float(th_a @ gp[np.ix_(cols_a, cols_a)] @ th_a)
        if vv <= 0:
            return 0.0, np.zeros(len(cols))
        goo = gp[np.ix_(cols, cols)]
        goa = gp[np.ix_(cols, cols_a)] @ th_a
        th = np.linalg.lstsq(goo, goa, rcond=None)[0]
        r2 = float(goa @ th) / vv
        # a fitted effect: not told apart only if the alternative is not significantly worse
        # (BIC on n_eff); a prior-size direction or a parameter's move: correlation alone
        if significance:
            worse = n_eff * math.log1p(max(1.0 - r2, 0.0) * vv / max(sse, 1e-300))
            if worse > cfg.bic_margin:
                r2 = min(r2, r2min - 1e-9)
        return r2, np.array([t / d.scale[k] for t, k in zip(th, cols)])

    names = list(by_name)
    for e in entries:
        if not e.excited:
            continue
        cols = d.blocks[e.effect]
        c = by_name[e.effect]
        fitted = e.selected or e.explained_fraction >= cfg.min_explained
        if e.effect in contrib:
            cols = contrib[e.effect]
            th = np.array([d.scale[k] for k in cols])
        elif e.selected:
            # the selected effect's contribution: its change columns times its value (linear
            # candidates) or its prior-size direction (nonlinear ones)
            if phis and e.effect in phis:
                phi = np.asarray(phis[e.effect], dtype=float)
            else:
                phi = np.array([v for v, _ in list(e.parameters.values())[:len(cols)]])
            th = (phi if c.linear and len(phi) == len(cols) else np.ones(len(cols))) * np.array([d.scale[k] for k in cols])
        else:
            theta = thetas[e.effect]
            th = np.array([t * d.scale[k] for t, k in zip(theta, cols)])
            if not fitted:
                th = c.prior_theta() * np.array([d.scale[k] for k in cols])
        grp = [e.effect]
        for other in names:
            if other == e.effect:
                continue
            r2, th_o = mimic(th, cols, other, fitted)
            if os.environ.get("VDPS_WB_DEBUG") and r2 > 0.5:
                print(f"[groups] {e.effect} ~ {other}: r2 {r2:.3f} plausible {by_name[other].plausible(th_o)}")
            if r2 >= r2min and by_name[other].plausible(th_o):
                grp.append(other)
        for p in params:
            pname = next(iter(p.parameters))
            if pname not in d.blocks:
                continue
            r2, th_o = mimic(th, cols, pname, fitted)
            cur = next(iter(p.parameters.values()))[0]
            if r2 >= r2min and cur + th_o[0] > 0:
                grp.append(p.effect)
        e.group = grp if len(grp) > 1 else []
    # parameter entries: which effects would explain their move from the reference
    for p in params:
        pname = next(iter(p.parameters))
        if pname not in d.blocks:
            continue
        k = d.blocks[pname][0]
        ref_v = p.reference[pname]
        cur = next(iter(p.parameters.values()))[0]
        if p.explained_fraction < cfg.min_explained:
            continue
        th = np.array([(cur - ref_v) * d.scale[k]])
        grp = [p.effect]
        for other in names:
            r2, th_o = mimic(th, [k], other, False)
            if r2 >= r2min and by_name[other].plausible(th_o):
                grp.append(other)
        p.group = grp if len(grp) > 1 else []


def _group_list(entries, params) -> list[dict]:
    """Equivalence groups with at least one effect, largest explained fraction first."""
    seen = set()
    out = []
    for e in sorted(entries + params, key=lambda e: -(e.explained_fraction if math.isfinite(e.explained_fraction) else -1)):
        if len(e.group) < 2:
            continue
        key = frozenset(e.group)
        if key in seen:
            continue
        if not any(g for g in e.group if g not in PARAM_ALIASES.values()):
            continue
        seen.add(key)
        out.append({"members": list(e.group), "lead": e.effect, "explained_fraction": _num(e.explained_fraction)})
    return out


SEPARATING_MANEUVERS: dict[frozenset, str] = {}
"""Filled by :mod:`~vdps_hil.workbench.words`."""


def with_params(vehicle: Vehicle, values: dict[str, float]) -> Vehicle:
    return vehicle.with_params(**values)


def replace_config(cfg: RankingConfig, **kw) -> RankingConfig:
    return replace(cfg, **kw)
