"""A sensor effect's parameters from its own evidence: the GNSS innovations (:func:`sensor_fit`).

A measurement effect (``imu_bias``, ``imu_lever_arm``) changes the IMU readings, so it leaves its
mark in two places: the GNSS innovations of the open-loop strapdown (``innovations``), where it
is the only thing besides the initial state (the nuisance) that moves them, and the force
balance of eq 13, where the measured specific force and rates enter the equations beside every
shortcoming of the reduced model. Fitted on all rows together, the balance rows win: there are
ten times as many, and their residual is the model's error (several times their noise sigma), so
the sensor's parameters end where they best absorb that error (measured on a sine sweep with the
default biases: a vertical accelerometer bias of -1.17 m/s^2 for a true +0.05, the innovations
it leaves 3.5 times worse held out) instead of where the sensor says.

So a sensor effect is fitted on the innovation rows alone: whitened innovations y (``Design``'s
innovation rows), the columns with innovation rows among the always-on ones (the nuisance of the
initial attitude, velocity and position, the selected sensor effects) and the candidate's;
ordinary least squares. Its held-out figure is the same blocked cross-validation as the design's
(``Design.folds``: the fold's micro blocks out, ``gap_blocks`` beside it out of the training):
per innovation group, the held-out SSE without and with the candidate. The balance rows then
judge it at that value, held fixed (``identification.linear_joint_fit``): rows it was not fitted
on.

Its held-out test (:meth:`SensorFit.held_out_dbic`) gives each kind of innovation (attitude,
velocity, position) its own residual variance: the whitening's sigmas are nominal, and the kinds
end at different levels (a CommonRoad lane change: whitened held-out SSE per row 1.16 attitude,
0.3-0.5 velocity, 0.9 position). With one variance pooled over the three, a lever arm that took
37 % off the velocity innovations (the only kind an accelerometer's lever arm reaches besides
the position) scored 4 % of the pooled sum and failed its BIC; with a variance per kind, the
log-likelihood ratio is the sum of m_g ln(SSE_with,g / SSE_without,g) (each variance profiled
out). The share it explains (:meth:`SensorFit.own_fraction`) is read on the kinds its columns
reach, in the same model (Cox-Snell R^2).

Sigmas: sqrt(diag((A^T A)^-1) s^2) with s^2 the residual variance of the whitened rows, in the
candidate's units.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .config import GROUP_NAMES
from .gram import dense

__all__ = ["SensorFit", "held_at", "sensor_fit"]


@dataclass
class SensorFit:
    """``phi`` (the candidate's parameters, its units), ``sigma``, ``th`` (scaled columns of the
    candidate's block), per row group the held-out SSE without (``cv_without``) and with
    (``cv_with``) the candidate (zero outside the innovation groups), rows used, per row group
    the rows (``group_rows``) and whether the candidate's columns reach it (``reaches``)."""

    phi: np.ndarray
    sigma: np.ndarray
    th: np.ndarray
    cv_without: np.ndarray
    cv_with: np.ndarray
    rows: int
    group_rows: np.ndarray | None = None
    reaches: np.ndarray | None = None

    def held_out_dbic(self) -> float:
        """sum_g m_g ln(SSE_cv,with,g / SSE_cv,without,g) + p ln m over the innovation groups g
        (a residual variance per group, module docstring): below minus the ranking's
        ``bic_margin`` the candidate's held-out gain is worth its p parameters."""
        m = max(self.rows, 2)
        counts = self.group_rows
        if counts is None:  # one pooled variance
            s0, s1 = float(self.cv_without.sum()), float(self.cv_with.sum())
            if s0 <= 0.0 or s1 <= 0.0:
                return math.inf
            return m * math.log(s1 / s0) + len(self.phi) * math.log(m)
        ll = 0.0
        for g in np.flatnonzero(counts > 0):
            s0, s1 = float(self.cv_without[g]), float(self.cv_with[g])
            if s0 <= 0.0 or s1 <= 0.0:
                return math.inf
            ll += counts[g] * math.log(s1 / s0)
        return ll + len(self.phi) * math.log(m)

    def own_fraction(self) -> float:
        """The share of the held-out innovations it explains on the groups its columns reach, in the
        same per-group-variance model as :meth:`held_out_dbic` (Cox and Snell's R^2,
        1 - (L_without / L_with)^(2/n)): 1 - exp(sum_g m_g ln(SSE_with,g / SSE_without,g) / sum_g m_g).
        With one group it is 1 - SSE_with / SSE_without; a large group it leaves unchanged does
        not dilute it the way a pooled ratio would."""
        counts = self.group_rows
        reach = self.reaches if self.reaches is not None and self.reaches.any() else None
        if counts is None or reach is None:
            return 1.0 - float(self.cv_with.sum()) / max(float(self.cv_without.sum()), 1e-300)
        groups = np.flatnonzero(reach & (counts > 0))
        n = float(counts[groups].sum())
        if n <= 0 or np.any(self.cv_without[groups] <= 0.0) or np.any(self.cv_with[groups] <= 0.0):
            return 0.0
        ll = sum(counts[g] * math.log(self.cv_with[g] / self.cv_without[g]) for g in groups)
        return 1.0 - math.exp(ll / n)


def _innovation_columns(d, cols: Sequence[int]) -> tuple[list[int], np.ndarray]:
    """The columns among ``cols`` non-zero on the innovation rows, and their innovation part."""
    n0 = d.n_dyn_rows
    keep, parts = [], []
    for k in cols:
        v = dense(d.cols[k])[n0:]
        if np.any(v != 0.0):
            keep.append(k)
            parts.append(v)
    return keep, (np.column_stack(parts) if parts else np.zeros((len(d.y) - n0, 0)))


def _lstsq(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(a, y, rcond=None)[0] if a.shape[1] else np.zeros(0)


def sensor_fit(d, always: Sequence[int], name: str) -> SensorFit | None:
    """The candidate ``name`` of design ``d`` fitted on the innovation rows (module docstring);
    None when the design has no innovation rows or the candidate no column on them."""
    n0 = d.n_dyn_rows
    m = len(d.y) - n0
    if m <= 0:
        return None
    base, xb = _innovation_columns(d, always)
    own = list(d.blocks[name])
    xc = np.column_stack([dense(d.cols[k])[n0:] for k in own])
    if not np.any(xc != 0.0):
        return None
    y = d.y[n0:]
    a = np.hstack([xb, xc])
    th = _lstsq(a, y)
    r = y - a @ th
    dof = max(m - a.shape[1], 1)
    s2 = float(r @ r) / dof
    try:
        cov = np.linalg.inv(a.T @ a)
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(a.T @ a)
    nb = len(base)
    th_c = th[nb:]
    scale = np.array([d.scale[k] for k in own])
    phi = th_c / scale
    sig = np.array([math.sqrt(max(cov[nb + j, nb + j] * s2, 0.0)) for j in range(len(own))]) / scale
    blocks, groups = d.block[n0:], d.group[n0:]
    cv0 = np.zeros(len(GROUP_NAMES))
    cv1 = np.zeros(len(GROUP_NAMES))
    for held, train in d.folds():
        h = np.isin(blocks, held)
        t = np.isin(blocks, train)
        if not h.any() or not t.any():
            continue
        r0 = y[h] - xb[h] @ _lstsq(xb[t], y[t])
        r1 = y[h] - a[h] @ _lstsq(a[t], y[t])
        np.add.at(cv0, groups[h], r0 * r0)
        np.add.at(cv1, groups[h], r1 * r1)
    counts = np.bincount(groups, minlength=len(GROUP_NAMES))
    reaches = np.array([bool(np.any(xc[groups == g] != 0.0)) for g in range(len(GROUP_NAMES))])
    if os.environ.get("VDPS_WB_DEBUG"):
        print(f"[sensor_fit] {name}: held-out SSE per innovation group without {cv0[-3:].round(1)} "
              f"with {cv1[-3:].round(1)}, rows {counts[-3:]}, reached {reaches[-3:].astype(int)}")
    return SensorFit(phi, sig, th_c, cv0, cv1, m, counts, reaches)


def held_at(d, name: str, th_c: np.ndarray):
    """A copy of design ``d`` whose residual holds block ``name`` at ``th_c`` (scaled columns):
    y - X_name th_c; the other columns are then fitted without it."""
    other = type(d).__new__(type(d))
    other.__dict__.update(d.__dict__)
    y = d.y.copy()
    for k, v in zip(d.blocks[name], th_c):
        if v != 0.0:
            y -= v * dense(d.cols[k])
    other.y = y
    other.invalidate_stats()
    return other
