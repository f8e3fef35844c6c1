"""What the identifier may claim about each parameter: identified, or why not.

A parameter x_j of a problem (bounds lo_j < hi_j, ``config.bounds_factor`` x prior; prior
sigma sigma0_j; posterior covariance C = W P W of ``rls.WeightedRLS`` at unit residual variance;
reported sigma_j, upstream included) gets the first of these that applies::

    "not excited"       the problem has made no update (its gates refused every input)
    "at bound"          x_j <= lo_j + m (hi_j - lo_j)  or  x_j >= hi_j - m (hi_j - lo_j)
                        (m = ``status.bound_margin``): unexcited or model mismatch, never a value
    "model mismatch"    the problem's residual test failed (``mismatch.MismatchMonitor``)
    "not identifiable"  sigma0_j^2 / C_jj < ``status.min_variance_ratio``: the drive taught
                        less than that factor over the prior (the value is mostly the prior)
    "not converged"     fewer than ``min_updates_converged`` updates, or sigma_j / |x_j| >=
                        ``converged_rel_sigma``
    "identified"        none of these

A problem is "converged" when every parameter of it is identified; otherwise its status is the
first cause among its parameters in the order above. The bound test comes before the others: a
clamped value's covariance says nothing about its error (the clamp keeps P, ``rls``), so no
sigma may vouch for it.

Symbols: x, lo, hi, sigma [unit of the parameter]; m, ratio [-].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CAUSES", "IDENTIFIED", "ParamStatus", "ProblemStatus", "problem_status", "cause_without_sigma"]

IDENTIFIED = "identified"
CAUSES = ("not excited", "at bound", "model mismatch", "not identifiable", "not converged")
"""The reasons a parameter is not identified, in the order they are tested."""


@dataclass(frozen=True)
class ParamStatus:
    """One parameter: ``status`` (``IDENTIFIED`` or one of ``CAUSES``), its value, its sigma
    (the corrected one, ``Identifier.sigmas``), the variance ratio prior / posterior (unit residual
    variance) and ``sigma_raw``, the sigma of white residuals with the configured noise
    (``Identifier.sigmas_raw``; NaN when not given)."""

    name: str
    status: str
    value: float
    sigma: float
    variance_ratio: float
    sigma_raw: float = math.nan

    @property
    def identified(self) -> bool:
        return self.status == IDENTIFIED

    def to_json(self) -> dict:
        return {"status": self.status, "value": self.value, "sigma": self.sigma,
                "sigma_raw": self.sigma_raw if math.isfinite(self.sigma_raw) else None,
                "variance_ratio": self.variance_ratio}


@dataclass(frozen=True)
class ProblemStatus:
    """One problem: ``status`` ("converged" or the first cause), its parameters, the rows the
    mismatch test names, the updates it made and the inputs each excitation gate refused."""

    problem: str
    status: str
    params: tuple[ParamStatus, ...]
    mismatch_rows: tuple[str, ...]
    updates: int
    gated: dict

    @property
    def converged(self) -> bool:
        return self.status == "converged"

    def to_json(self) -> dict:
        return {"status": self.status, "params": {p.name: p.to_json() for p in self.params},
                "mismatch_rows": list(self.mismatch_rows), "updates": self.updates, "gated": dict(self.gated)}


def _param_cause(x, lo, hi, ratio, rel, *, updates, mismatch, cfg) -> str:
    """The first cause that applies (module docstring), or ``IDENTIFIED``."""
    st = cfg.status
    if updates == 0:
        return "not excited"
    span = hi - lo
    if x <= lo + st.bound_margin * span or x >= hi - st.bound_margin * span:
        return "at bound"
    if mismatch:
        return "model mismatch"
    if ratio < st.min_variance_ratio:
        return "not identifiable"
    if updates < cfg.min_updates_converged or not rel < cfg.converged_rel_sigma:
        return "not converged"
    return IDENTIFIED


def problem_status(problem: str, names, rls, sigma0, sigmas, mismatch_rows, gated, cfg,
                   sigmas_raw=None) -> ProblemStatus:
    """The status of one problem (module docstring). ``rls``: its ``WeightedRLS``; ``sigma0``:
    the prior sigmas (physical units); ``sigmas``: name -> reported sigma (upstream included);
    ``mismatch_rows``: the rows its residual test failed; ``cfg``: the ``IdentConfig``;
    ``sigmas_raw``: name -> the noise model's sigma, carried beside it."""
    x = rls.x
    lo, hi = rls.lower, rls.upper
    var = np.diag(rls.covariance)
    updates = rls.counters.updates
    params = []
    for j, n in enumerate(names):
        ratio = _variance_ratio(sigma0[j], var[j])
        sig = float(sigmas[n])
        rel = sig / max(abs(float(x[j])), 1e-300)
        cause = _param_cause(float(x[j]), float(lo[j]), float(hi[j]), ratio, rel, updates=updates,
                             mismatch=bool(mismatch_rows), cfg=cfg)
        raw = float(sigmas_raw[n]) if sigmas_raw is not None else math.nan
        params.append(ParamStatus(n, cause, float(x[j]), sig, ratio, raw))
    causes = [p.status for p in params if not p.identified]
    status = "converged" if not causes else min(causes, key=CAUSES.index)
    return ProblemStatus(problem, status, tuple(params), tuple(mismatch_rows), int(updates), dict(gated))


def cause_without_sigma(rls, sigma0, mismatch_rows, cfg) -> str | None:
    """The first cause (module docstring) of a problem's parameters that does not need the
    reported sigma -- every cause but sigma_j / |x_j| >= ``converged_rel_sigma`` -- or None. A
    problem with such a cause is not converged whatever its sigma, so its convergence is
    decided without the corrected covariances (``Identifier.converged_of``); the tests are
    ``problem_status``'s own, on the same numbers."""
    x = rls.x
    lo, hi = rls.lower, rls.upper
    var = np.diag(rls.covariance)
    updates = rls.counters.updates
    for j in range(len(x)):
        cause = _param_cause(float(x[j]), float(lo[j]), float(hi[j]), _variance_ratio(sigma0[j], var[j]), 0.0,
                             updates=updates, mismatch=bool(mismatch_rows), cfg=cfg)
        if cause != IDENTIFIED:
            return cause
    return None


def _variance_ratio(sigma0_j, var_j) -> float:
    """sigma0_j^2 / C_jj: what the drive taught over the prior (inf for a zero variance)."""
    return float(sigma0_j ** 2 / var_j) if var_j > 0.0 else math.inf
