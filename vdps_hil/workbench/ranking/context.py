"""The residual rows at the current (identified) model, whitened and freed of the estimator's
errors, and the column builders the candidates call (:class:`Context`).

Whitening: every equation's row is divided by its noise sigma (``EquationResiduals.sigma``,
inverse noise-variance weighting per equation). Nuisance, per row (``EquationResiduals.nuisance``,
columns (v_x, v_y, F_a,1..4)):

* the four longitudinal tire forces F_a,i are projected out exactly: with U the left singular
  vectors of the whitened force columns J_F, a column a becomes (I - U U^T) a (the longitudinal
  forces are then taken from the measured spin balance instead of eq 15);
* the fast (row to row) body-velocity errors (delta v_x, delta v_y) are projected out in
  proportion to their sigma sigma_fast (``velocity_fast_sigma_mps``): whitening with the noise
  covariance I + J S J^T, J = d r / d(v_x, v_y) (whitened, the forces already projected out),
  S = sigma_fast^2 I, i.e.
  a -> a - U_s diag(1 - 1/sqrt(1 + s^2)) U_s^T a with J sigma_fast = U_s diag(s) V^T;
* the slow body-velocity errors are columns of their own (hat functions every
  ``nuisance_knot_s``, :meth:`Context.smooth_bands`) with a prior of the estimator's own sigma
  (tightened where the base fit takes them far beyond it, ``identification.cap_nuisance``).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import Effect, ImuKinematics
from vdps_hil.model.params import Vehicle

from ..dataset import DriveTable
from ..innovations import Innovations
from ..residuals import EQUATIONS, EquationResiduals, RowStates, compute_residuals, parameter_columns

__all__ = ["Context"]


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
