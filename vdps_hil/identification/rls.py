"""Weighted and scaled recursive least squares, paper eq 18-19, with forgetting, bounds,
excitation gating, a NaN guard, calibrated per-parameter sigmas and an identifiability figure.

Problem (eq 18)::

    Q A W W^-1 x = Q b          A_Q = Q A W,   x_Q = W^-1 x,   y = Q b

Update (eq 19, sign corrected, optional forgetting factor lambda in (0, 1])::

    v      = Q b - A_Q x_Q(k)                      a priori innovation (k rows)
    S      = lambda I + A_Q P(k) A_Q^T             k x k, S >= lambda I: never singular
    K      = P(k) A_Q^T S^-1
    x_Q(k+1) = x_Q(k) + K v   =  x_Q(k) + P(k+1) A_Q^T v      (for any lambda)
    P(k+1) = (P(k) - P(k) A_Q^T S^-1 A_Q P(k)) / lambda       (lambda = 1: eq 19's P line)

**Misprint in eq 19**: the paper prints ``x_Q(k+1) = x_Q(k) - P(k+1) A_Q^T [Q b - A_Q x_Q(k)]``.
With P(k+1) as printed (positive definite) the minus sign moves x *away* from the least-squares
solution (the error obeys e(k+1) = (I + P A^T A) e(k), which diverges); the algebra of Chong & Zak
(the paper's ref [29]) has ``+``. We implement ``+``; the tests check convergence.

Two numerically careful forms, equal in exact arithmetic (tests compare them to 1e-9):

* ``form = "covariance"`` (default, eq 19): the P line is evaluated in Joseph form
  ``P(k+1) = (I - K A_Q) (P/lambda) (I - K A_Q)^T + K K^T`` (the Kalman update with unit
  measurement noise and the prediction P/lambda), then symmetrised. It stays symmetric positive
  definite under round-off, where the printed difference can lose definiteness.
* ``form = "sqrt_information"``: R with R^T R = P^-1 and z = R x_Q; one update is the QR
  factorisation of ``[[sqrt(lambda) R, sqrt(lambda) z], [A_Q, Q b]]``. No subtraction of large
  numbers: best with very weak priors or ill-conditioned data.

Scaling W only changes the numerics: the prior is given physically (``sigma0``, physical units)
and P(0) = W^-1 diag(sigma0^2) W^-1, so x(k) = W x_Q(k) is the same for every W in exact
arithmetic. Weighting Q changes the solution: x minimises
``lambda-discounted sum ||Q (b - A x)||^2 + (x - x0)^T P0^-1 (x - x0)``; with Q_ii = 1 / (noise
sd of row i) the RLS is the Bayesian posterior and P the covariance. W and Q are diagonal, as in
every problem of the paper (eq 20-23); they are given as vectors.

Diagnostics
-----------
* **Residual variance** s^2 = J* / (N - n): J* is the minimum of the weighted cost, updated
  exactly by J*(k+1) = lambda J*(k) + lambda v^T S^-1 v (covariance form) or by the QR residual
  (sqrt form); N counts the rows used (discounted by lambda). Until N - n >= ``min_dof``, s^2 = 1
  (the design assumption that Q whitens the rows).
* **Sigma** per parameter: sigma_j = sqrt(s^2 f_j (W P W)_jj). The full P is used, so
  correlation between regressor columns (e.g. I_x, I_y, I_z sharing omega products) widens each
  sigma correctly. f_j >= 1 corrects for time-correlated residuals (estimator outputs are
  filtered, so the equation errors are coloured): an AR(1) approximation
  f_j = (1 + rho_j) / (1 - rho_j), clipped to [1, 100], where rho_j is the lag-1
  autocorrelation of the score sequence g_j(k) = (A_Q^T e(k))_j with the a posteriori residual
  e(k) = Q b - A_Q x_Q(k+1). Because the score includes the regressor, slowly varying regressors
  with white noise give f ~ 1, and coloured noise with slowly varying regressors gives the
  classical (1 + rho)/(1 - rho). ``sigma_autocorr = False`` sets f = 1. Calibration is checked by
  Monte Carlo in ``tests/test_rls.py`` (fraction of seeds with |error| <= 2 sigma).
* **Jackknife covariance** (``jackknife_blocks`` > 0): the delete-a-block jackknife of the
  solution over consecutive blocks of updates (``jackknife``, Kuensch 1989), a covariance that
  assumes no noise model; ``jackknife_covariance``. The ``Identifier`` reports the larger of it
  and the model-based variance above.
* **Consider covariance**: when b is built from other problems' estimates theta (eq 22 uses
  m and C_lambda, eq 23's moments use C_lambda and C_alpha), their errors move x by
  dx = J dtheta with J = W P sum_k A_Q^T Q db/dtheta (exact for least squares, accumulated with
  lambda like P^-1); ``consider_covariance(cov_theta)`` = J cov_theta J^T is added to the
  problem's own covariance by the ``Identifier``.
* **Identifiability** (paper section 8, Table 3): the minimum eigenvalue of the accumulated
  (lambda-discounted) ``sum A^T Q^T Q A`` with the physical A (no W), as the paper defines it.
  ``identifiability_scaled`` is the same for A_Q (includes W), i.e. the information in P^-1.

Guards
------
* **Excitation gating**: the caller passes ``rows`` (a boolean mask); unexcited rows are left
  out. A call with no usable row changes nothing and counts ``not_excited`` (forgetting is not
  applied either, so P does not wind up while the vehicle is not excited).
* **NaN guard**: rows with a non-finite entry in A or b are left out and counted (``nan_rows``).
* **Bounds** (physical, ``lower``/``upper``): ``bounds_mode = "clamp"`` clips x after the update
  and keeps P (counted ``clamped``); ``"reject"`` restores the state from before the update
  (counted ``rejected``).
* **Anti-windup** with lambda < 1: if the largest eigenvalue of P exceeds the largest of P(0),
  the eigenvalues of P are clipped to it (P <= P(0)_max I), so unexcited directions cannot
  blow up.

Symbols: n parameters, k rows used in one update, m rows of the problem. Units: x and sigma in
the parameters' units, A row i in (unit of b_i)/(unit of x), Q_ii in 1/(unit of b_i).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vdps_hil import jit
from vdps_hil.identification import rls_kernels as RK
from vdps_hil.identification.jackknife import BlockJackknife

FORMS = ("covariance", "sqrt_information")
BOUNDS_MODES = ("clamp", "reject")
MAX_INFLATION = 100.0


@dataclass(frozen=True)
class RLSCounters:
    """Counts since construction (``resets`` survives a reset; the rest is cleared by it)."""

    updates: int = 0  # calls that changed the estimate
    rows_used: int = 0  # rows that entered an update
    not_excited: int = 0  # calls with no usable row (gated or all NaN)
    nan_rows: int = 0  # rows left out for non-finite values
    clamped: int = 0  # updates whose result was clipped to the bounds
    rejected: int = 0  # updates undone because the result left the bounds
    resets: int = 0


def _vector(name: str, v, n: int | None = None) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        want = f"({n},)" if n is not None else "1-D"
        raise ValueError(f"{name} must have shape {want}, got {np.shape(v)}")
    return a


class WeightedRLS:
    """Eq 19 for one problem ``Q A W W^-1 x = Q b`` with n parameters and m rows.

    ``x0``: initial estimate (physical units); ``sigma0``: prior standard deviation of each
    parameter (physical units, > 0); ``q``: diagonal of Q (m values, > 0); ``w``: diagonal of W
    (n values, > 0; default |x0|, so x_Q ~ 1); ``lower``/``upper``: physical bounds.
    """

    def __init__(self, x0, sigma0, q, w=None, *, forgetting: float = 1.0, lower=None, upper=None,
                 bounds_mode: str = "clamp", form: str = "covariance",
                 sigma_autocorr: bool = True, min_dof: int = 5, names=None, jackknife_blocks: int = 0,
                 jackknife_span: int = 50):
        self._x0 = _vector("x0", x0)
        n = self._x0.shape[0]
        self._sigma0 = _vector("sigma0", sigma0, n)
        self._q = _vector("q", q)
        if w is None:
            w = np.where(np.abs(self._x0) > 0.0, np.abs(self._x0), 1.0)
        self._w = _vector("w", w, n)
        if not (np.all(np.isfinite(self._x0)) and np.all(self._sigma0 > 0) and np.all(self._q > 0)
                and np.all(self._w > 0) and np.all(np.isfinite(self._sigma0))
                and np.all(np.isfinite(self._q)) and np.all(np.isfinite(self._w))):
            raise ValueError("x0 must be finite and sigma0, q, w finite and positive")
        if not (0.0 < forgetting <= 1.0):
            raise ValueError(f"forgetting factor must be in (0, 1], got {forgetting}")
        if form not in FORMS:
            raise ValueError(f"form must be one of {FORMS}, got {form!r}")
        if bounds_mode not in BOUNDS_MODES:
            raise ValueError(f"bounds_mode must be one of {BOUNDS_MODES}, got {bounds_mode!r}")
        self._lower = np.full(n, -np.inf) if lower is None else _vector("lower", lower, n)
        self._upper = np.full(n, np.inf) if upper is None else _vector("upper", upper, n)
        if np.any(self._lower > self._upper):
            raise ValueError("lower bound above upper bound")
        self.n = n
        self.m = self._q.shape[0]
        self.forgetting = float(forgetting)
        self.form = form
        self.bounds_mode = bounds_mode
        self.sigma_autocorr = bool(sigma_autocorr)
        self.min_dof = int(min_dof)
        self.names = tuple(names) if names is not None else tuple(f"x{i}" for i in range(n))
        if len(self.names) != n:
            raise ValueError("names must have one entry per parameter")
        self._jack = BlockJackknife(n, jackknife_blocks, jackknife_span) if jackknife_blocks else None
        """The block sums of ``jackknife_covariance`` (None: off)."""
        self._compiled = jit.ENABLED and form == "covariance"
        """Covariance-form updates through the compiled ``rls_kernels`` (numpy with VDPS_JIT=0)."""
        self._all_rows = np.ones(self.m, dtype=bool)  # ``rows`` None (never written)
        self._scratch = np.empty((self.m, self.n)), np.empty((self.m, self.n)), np.empty(self.m)  # Q A, A_Q, Q b
        self._ww = np.outer(self._w, self._w)  # W_ii W_jj
        self._resets = -1
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, x0=None) -> None:
        """Back to the prior (or to ``x0`` with the prior sigmas); counters cleared but
        ``resets``."""
        if x0 is not None:
            self._x0 = _vector("x0", x0, self.n)
        xq = np.clip(self._x0, self._lower, self._upper) / self._w
        p_diag = (self._sigma0 / self._w) ** 2
        self._p0_max = float(np.max(p_diag))
        self._xq = xq
        self._xq0, self._p0_inv = xq.copy(), np.diag(1.0 / p_diag)  # the prior, for the jackknife
        if self._jack is not None:
            self._jack.reset()
        self._P = np.diag(p_diag)  # covariance form
        self._R = np.diag(1.0 / np.sqrt(p_diag))  # sqrt-information form
        self._z = self._R @ xq
        self._info = np.zeros((self.n, self.n))
        self._info_scaled = np.zeros((self.n, self.n))
        self._rss = 0.0
        self._nrows = 0.0
        self._gg = np.zeros(self.n)
        self._g1 = np.zeros(self.n)
        self._sens: np.ndarray | None = None  # sum A_Q^T Q db/dtheta (consider parameters)
        self._g_prev: np.ndarray | None = None
        self._c = dict(updates=0, rows_used=0, not_excited=0, nan_rows=0, clamped=0, rejected=0)
        self._resets += 1

    # ----------------------------------------------------------------- update
    def update(self, a, b, rows=None, q=None, db_dtheta=None) -> bool:
        """One step of eq 19 with the rows of ``A`` (m x n, physical) and ``b`` (m) selected by
        the boolean mask ``rows`` (default all). ``q`` overrides the diagonal of Q for this
        step (eq 19 allows Q(k+1)). ``db_dtheta`` (m x p) is the sensitivity of b to p
        *consider* parameters (estimates of other problems used to build b); it feeds
        ``consider_covariance``. Returns True if the estimate was updated."""
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        if a.shape != (self.m, self.n) or b.shape != (self.m,):
            raise ValueError(f"A must be ({self.m}, {self.n}) and b ({self.m},); got {a.shape}, {b.shape}")
        sel = self._all_rows if rows is None else np.asarray(rows, dtype=bool).reshape(self.m)
        qv = self._q if q is None else _vector("q", q, self.m)
        if self._compiled:
            return self._update_compiled(a, b, sel, qv, db_dtheta)
        finite = np.isfinite(a).all(axis=1) & np.isfinite(b)
        self._c["nan_rows"] += int(np.count_nonzero(sel & ~finite))
        sel = sel & finite
        k = int(np.count_nonzero(sel))
        if k == 0:
            return self._not_excited()
        qa = qv[sel, None] * a[sel]  # Q A (physical), k x n
        aq = qa * self._w[None, :]  # A_Q = Q A W
        y = qv[sel] * b[sel]  # Q b
        lam = self.forgetting

        # Compute the candidate state without touching self; commit only if it is accepted.
        if self.form == "covariance":
            xq_new, p_new, drss = self._step_covariance(aq, y, lam)
            r_new = None
        else:
            xq_new, r_new, drss = self._step_sqrt(aq, y, lam)
            p_new = None
        xq_new = self._bounded(xq_new, drss, k)
        if xq_new is None:
            return False

        self._xq = xq_new
        if p_new is not None:
            self._P = p_new
        else:
            self._R = r_new
            self._z = r_new @ xq_new
        self._commit_common(drss, k)
        self._info = lam * self._info + qa.T @ qa
        self._info_scaled = lam * self._info_scaled + aq.T @ aq
        e_post = y - aq @ xq_new  # a posteriori residual
        g = aq.T @ e_post  # score
        self._gg = lam * self._gg + g * g
        if self._g_prev is not None:
            self._g1 = lam * self._g1 + g * self._g_prev
        self._g_prev = g
        if self._jack is not None:
            self._jack.add(aq, y, lam)
        if db_dtheta is not None:
            ds = self._sensitivity(db_dtheta)[sel]
            self._add_sensitivity(aq, qv[sel, None] * np.where(np.isfinite(ds), ds, 0.0))
        return True

    def _update_compiled(self, a, b, sel, qv, db_dtheta) -> bool:
        """``update`` in covariance form through the compiled ``rls_kernels`` (equal to the numpy
        lines of ``update`` within 1e-12; ``tests/test_rls_kernels.py``)."""
        n, lam = self.n, self.forgetting
        qa, aq, y = self._scratch
        xq_new, p_new = np.empty(n), np.empty((n, n))
        c = np.ascontiguousarray
        has_prev = self._g_prev is not None
        g = np.zeros(n) if not has_prev else self._g_prev
        k, nan_rows, drss, done = RK.update_inside(c(a), c(b), c(sel), c(qv), self._w, self._xq, self._P, lam,
                                                   self._lower, self._upper, qa, aq, y, xq_new, p_new, self._info,
                                                   self._info_scaled, self._gg, self._g1, g, has_prev)
        self._c["nan_rows"] += nan_rows
        if k == 0:
            return self._not_excited()
        if not done:  # the bounds' cases
            xq_new = self._bounded(xq_new, drss, k)
            if xq_new is None:
                return False
            RK.accumulate(qa, aq, y, k, xq_new, lam, self._info, self._info_scaled, self._gg, self._g1, g, has_prev)
        self._xq, self._P = xq_new, p_new
        self._commit_common(drss, k)
        self._g_prev = g
        if self._jack is not None:
            self._jack.add(aq[:k], y[:k], lam)
        if db_dtheta is not None:
            d = self._sensitivity(db_dtheta)
            qd = np.empty(d.shape)
            RK.consider_rows(c(a), c(b), c(sel), c(qv), c(d), qd)
            self._add_sensitivity(aq[:k], qd[:k])
        return True

    def _not_excited(self) -> bool:
        self._c["not_excited"] += 1
        self._g_prev = None
        return False

    def _bounded(self, xq_new, drss: float, k: int):
        """The candidate x_Q within the bounds (clamped), or None: non-finite or rejected."""
        if not (np.isfinite(xq_new).all() and math.isfinite(drss)):
            self._c["nan_rows"] += k  # cannot happen with finite rows; never keep it
            self._g_prev = None
            return None
        x_new = xq_new * self._w
        if (x_new < self._lower).any() or (x_new > self._upper).any():
            if self.bounds_mode == "reject":
                self._c["rejected"] += 1
                self._g_prev = None
                return None
            x_new = np.clip(x_new, self._lower, self._upper)
            xq_new = x_new / self._w
            self._c["clamped"] += 1
        return xq_new

    def _commit_common(self, drss: float, k: int) -> None:
        lam = self.forgetting
        if lam < 1.0:
            self._anti_windup()
        self._rss = lam * self._rss + drss
        self._nrows = lam * self._nrows + k
        self._c["updates"] += 1
        self._c["rows_used"] += k

    def _sensitivity(self, db_dtheta) -> np.ndarray:
        d = np.asarray(db_dtheta, dtype=float)
        if d.ndim != 2 or d.shape[0] != self.m:
            raise ValueError(f"db_dtheta must be ({self.m}, p), got {d.shape}")
        return d

    def _add_sensitivity(self, aq, qd) -> None:
        """sum A_Q^T Q db/dtheta += this update's (``qd``: Q db/dtheta on the used rows, non-finite
        entries 0)."""
        contrib = aq.T @ qd
        if self._sens is None or self._sens.shape != contrib.shape:
            self._sens = np.zeros_like(contrib)
        self._sens = self.forgetting * self._sens + contrib

    def _step_covariance(self, aq, y, lam):
        """Eq 19 (sign corrected), P line in Joseph form. Returns (x_Q, P, J increment)."""
        P = self._P
        v = y - aq @ self._xq  # a priori innovation
        pa = P @ aq.T  # n x k
        S = lam * np.eye(aq.shape[0]) + aq @ pa  # k x k, >= lam I: never singular
        s_inv = np.linalg.inv(S)  # k <= 4, condition number <= 1 + |A_Q P A_Q^T| / lam
        K = pa @ s_inv  # P A_Q^T S^-1
        xq_new = self._xq + K @ v
        ika = np.eye(self.n) - K @ aq
        p_new = ika @ (P / lam) @ ika.T + K @ K.T
        p_new = 0.5 * (p_new + p_new.T)
        drss = float(lam * v @ s_inv @ v)
        return xq_new, p_new, drss

    def _step_sqrt(self, aq, y, lam):
        """Square-root information form: QR of [[sqrt(lam) R, sqrt(lam) z], [A_Q, Q b]]."""
        n = self.n
        sl = np.sqrt(lam)
        top = np.hstack([sl * self._R, sl * self._z[:, None]])
        bottom = np.hstack([aq, y[:, None]])
        r = np.linalg.qr(np.vstack([top, bottom]), mode="r")
        r_new = r[:n, :n]
        drss = float(r[n, n] ** 2)  # n + k >= n + 1 rows, so r is (n+1) x (n+1)
        xq_new = _solve_upper(r_new, r[:n, n])
        return xq_new, r_new, drss

    def _anti_windup(self) -> None:
        P = self.covariance_scaled
        evals, evecs = np.linalg.eigh(P)
        if evals[-1] <= self._p0_max:
            return
        P = (evecs * np.minimum(evals, self._p0_max)) @ evecs.T
        P = 0.5 * (P + P.T)
        if self.form == "covariance":
            self._P = P
        else:
            self._R = np.linalg.cholesky(np.linalg.inv(P)).T
            self._z = self._R @ self._xq

    # ------------------------------------------------------------ read-only
    @property
    def x(self) -> np.ndarray:
        """Current estimate, physical units (a copy)."""
        return self._xq * self._w

    @property
    def covariance_scaled(self) -> np.ndarray:
        """P of eq 19 (scaled coordinates x_Q), unit residual variance."""
        if self.form == "covariance":
            return self._P.copy()
        rinv = _solve_upper(self._R, np.eye(self.n))
        return rinv @ rinv.T

    @property
    def covariance(self) -> np.ndarray:
        """W P W: the covariance of x for unit weighted residual variance (physical units)."""
        return (self._P if self.form == "covariance" else self.covariance_scaled) * self._ww

    @property
    def residual_variance(self) -> float:
        """s^2: the weighted residual variance estimate (1 until ``min_dof`` rows beyond n)."""
        dof = self._nrows - self.n
        if dof < self.min_dof:
            return 1.0
        return max(self._rss / dof, 0.0)

    @property
    def autocorr_inflation(self) -> np.ndarray:
        """f_j >= 1 of the docstring (ones if ``sigma_autocorr`` is off or no data yet)."""
        if not self.sigma_autocorr:
            return np.ones(self.n)
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = np.where(self._gg > 0.0, self._g1 / self._gg, 0.0)
        rho = np.clip(rho, 0.0, 0.99)
        return np.clip((1.0 + rho) / (1.0 - rho), 1.0, MAX_INFLATION)

    @property
    def sigma(self) -> np.ndarray:
        """Per-parameter standard deviation, physical units (see the module docstring)."""
        var = self.residual_variance * self.autocorr_inflation * np.diag(self.covariance)
        return np.sqrt(np.maximum(var, 0.0))

    @property
    def parameter_covariance(self) -> np.ndarray:
        """s^2 F^1/2 (W P W) F^1/2 with F = diag(f): the covariance behind ``sigma``."""
        sf = np.sqrt(self.residual_variance * self.autocorr_inflation)
        return self.covariance * np.outer(sf, sf)

    @property
    def jackknife_covariance(self) -> np.ndarray | None:
        """W V_J W: the delete-a-block jackknife covariance of x (``jackknife``; physical units),
        measured from the spread of the solution over the drive, no noise model assumed. None when
        off (``jackknife_blocks = 0``) or below ``jackknife.MIN_BLOCKS`` blocks."""
        if self._jack is None:
            return None
        v = self._jack.variance(self._p0_inv, self._xq0)
        return None if v is None else v * self._ww

    def consider_covariance(self, cov_theta) -> np.ndarray:
        """Covariance of x caused by the uncertainty ``cov_theta`` (p x p) of the consider
        parameters: J cov_theta J^T with J = dx/dtheta = W P sum(A_Q^T Q db/dtheta) (the
        least-squares sensitivity; a Schmidt "consider" covariance). Zero before any
        ``db_dtheta`` was given."""
        if self._sens is None:
            return np.zeros((self.n, self.n))
        c = np.asarray(cov_theta, dtype=float)
        j = (self.covariance_scaled @ self._sens) * self._w[:, None]
        out = j @ c @ j.T
        return 0.5 * (out + out.T)

    @property
    def information(self) -> np.ndarray:
        """Accumulated sum of A^T Q^T Q A (physical A, lambda-discounted)."""
        return self._info.copy()

    @property
    def identifiability(self) -> float:
        """Minimum eigenvalue of ``information`` (paper section 8, Table 3)."""
        return float(np.linalg.eigvalsh(self._info)[0])

    @property
    def identifiability_scaled(self) -> float:
        """Minimum eigenvalue of the accumulated A_Q^T A_Q (includes W)."""
        return float(np.linalg.eigvalsh(self._info_scaled)[0])

    @property
    def rows_seen(self) -> float:
        """Rows used so far (lambda-discounted)."""
        return self._nrows

    @property
    def counters(self) -> RLSCounters:
        return RLSCounters(resets=self._resets, **self._c)

    @property
    def w(self) -> np.ndarray:
        return self._w.copy()

    @property
    def lower(self) -> np.ndarray:
        """The physical lower bounds (a copy)."""
        return self._lower.copy()

    @property
    def upper(self) -> np.ndarray:
        """The physical upper bounds (a copy)."""
        return self._upper.copy()

    @property
    def q(self) -> np.ndarray:
        return self._q.copy()


def _solve_upper(r: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Back substitution for an upper-triangular r (n is at most 4 here)."""
    n = r.shape[0]
    out = np.array(rhs, dtype=float, copy=True)
    for i in range(n - 1, -1, -1):
        out[i] = (out[i] - r[i, i + 1:] @ out[i + 1:]) / r[i, i]
    return out
