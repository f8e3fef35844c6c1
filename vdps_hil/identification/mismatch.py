"""The model-mismatch test of one identification problem: are its residuals what its noise model
predicts?

Each update of a problem's RLS (``rls.WeightedRLS``, eq 19) has, before the update, the
estimate x(k) and its covariance C(k) = W P(k) W (unit residual variance). The a priori
residual of a used row i and the variance the problem's own noise model predicts for it are::

    v_i = b_i - A_i x(k),     s_i = 1 / Q_ii^2 + A_i C(k) A_i^T,     r_i = v_i / sqrt(s_i)

(Q_ii = 1 / noise sd of row i: the design assumption of ``configs/identification``). With the
right model the normalised residuals r_i are the recursive residuals of least squares (Brown,
Durbin & Evans 1975): zero mean, unit variance and, beyond the short correlation the filtered
inputs give them, uncorrelated. A model that does not hold (a missing anti-roll bar in the roll
row, a saturating tire in the lateral row) leaves a residual that follows the maneuver: large
against its predicted variance and correlated over the maneuver's time scale. Per row:

* **variance**: the mean of r_i^2 over the drive; a row fails when it exceeds
  ``mismatch_variance_max``;
* **whiteness**: the residuals are averaged in bins of ``mismatch_lag_s`` (longer than the
  filters' correlation, shorter than a maneuver) and the lag-1 autocorrelation of the bin means
  is taken, rho = sum (m_k - mbar)(m_k+1 - mbar) / sum (m_k - mbar)^2 over consecutive bins; a
  row fails when rho exceeds ``mismatch_whiteness_max``.

* **long-run variance** (batch means): tau = (sum_k n_k (m_k - rbar)^2 / (K - 1)) / var(r)
  over the K bins (n_k residuals, mean m_k each); 1 for uncorrelated residuals, the factor by
  which residuals correlated over the maneuver shrink the information the RLS counted. The
  identifier multiplies a problem's covariance by ``variance_scale`` = max(1, tau) over its
  rows; where tau exceeds the RLS's own AR(1) inflation f_j the identifier scales the
  parameter's variance by tau / f_j (``Identifier.covariances``): the sigmas stay honest when
  the residuals are correlated over the maneuver, not only from sample to sample.
* **integrated autocorrelation time** (issue 17, second session): tau_int = 1 + 2 sum_k rho_k
  of the residual sequence itself (Sokal's automatic window, lags up to ``MAX_LAG``), the
  factor N / N_eff between the residuals counted and the effectively independent ones
  (Priestley 1981, the variance of a mean of correlated samples; Sokal 1997 for the window).
  The variance scale is max(1, tau, tau_int): the bins of the batch means see correlation over
  more than a bin only coarsely (on a CommonRoad circle whose speed ramps over 55 s the lateral
  row had tau 49 and tau_int 675). What neither can see: a model error proportional to the
  regressor (a camber force growing with a_y, a spring figure off by a factor) is absorbed by
  the estimate and leaves white residuals; that bias stays outside the sigma.

A row is tested once it has ``mismatch_min_rows`` residuals; the problem is a **model
mismatch** when any of its rows fails, and the report names those rows (``ROW_NAMES``), so the
model workbench can take over (which effect explains them). The thresholds
(``configs/identification/default.toml`` ``[status]``) were chosen on the drives of
``experiments.ident_study.TUNING_SEEDS`` and are checked on other seeds
(``tools/ident_study.py``).

Symbols: v [unit of b_i]; s [unit of b_i^2]; r, rho [-]; Q [1/unit of b_i].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vdps_hil.identification.mismatch_kernels import add_residual

__all__ = ["CROSS_CHECKS", "ROW_NAMES", "MismatchMonitor", "RowTest"]

ROW_NAMES: dict[str, tuple[str, ...]] = {
    "mass": ("vertical",),
    "tracking": ("wheel_1", "wheel_2", "wheel_3", "wheel_4"),
    "cornering": ("longitudinal", "lateral", "yaw"),  # yaw: only with the yaw row (problems)
    "inertia": ("roll", "pitch", "yaw"),
}
"""The rows of each problem's regressor (eq 20-23) by name."""

CROSS_CHECKS: dict[str, tuple[tuple[str, str], ...]] = {"cornering": (("inertia", "yaw"),)}
"""Rows of a downstream problem that test a problem's parameters too: eq 22 fits the sum of the
axle forces (F_f + F_r = m a_y), and only eq 23's yaw row weighs one axle against the other
(M_z = l_f F_f - l_r F_r, the eq 15 forces of the identified C_alpha, ``forces``). A failed yaw
row therefore marks the cornering problem a mismatch too (named "inertia.yaw"): the front/rear
split it found does not balance the yaw moment."""


@dataclass(frozen=True)
class RowTest:
    """One row's statistics: ``n`` residuals, ``variance`` = mean r^2, ``mean`` = mean r,
    ``whiteness`` = lag-1 autocorrelation of the bin means and ``long_run`` = tau (both None
    below 4 bins), ``failed``."""

    name: str
    n: int
    variance: float
    mean: float
    whiteness: float | None
    long_run: float | None
    failed: bool

    def to_json(self) -> dict:
        return {"row": self.name, "n": self.n, "variance": self.variance, "mean": self.mean,
                "whiteness": self.whiteness, "long_run": self.long_run, "failed": self.failed}


MAX_LAG = 400
"""Longest lag of the integrated autocorrelation time (``_Row.tau_int``), in residuals (4 s at
the identifier's 100 Hz): a few cycles of the slowest maneuver (the 1 Hz sine)."""


class _Row:
    __slots__ = ("n", "s1", "s2", "bin", "bin_sum", "bin_n", "means", "counts", "nb", "ring", "lag_sums")

    def __init__(self):
        self.n, self.s1, self.s2 = 0, 0.0, 0.0
        self.bin, self.bin_sum, self.bin_n = None, 0.0, 0
        # the closed bins' means and residual counts in means[:nb], counts[:nb]; the buffers keep
        # one slot beyond them for the open bin (``_bins``) and double when full: the tests read
        # them as views at every status (50-100 Hz), and lists turned into arrays there cost
        # 0.5 ms per row after an hour of 0.5 s bins (7200 bins)
        self.means = np.empty(64)
        self.counts = np.empty(64)
        self.nb = 0
        # the last MAX_LAG residuals, each at ring[i] and ring[i + MAX_LAG] (i = n % MAX_LAG when
        # written), so the newest m are the contiguous ring[j + MAX_LAG - m : j + MAX_LAG]
        self.ring = np.zeros(2 * MAX_LAG)
        self.lag_sums = np.zeros(MAX_LAG + 1)  # lag_sums[k] = sum_t r_t r_(t-k), k = 1..MAX_LAG

    def add(self, k_bin: int, r: float) -> None:
        add_residual(self.lag_sums, self.ring, self.n, r)  # lags 1..min(n, MAX_LAG), r into the ring
        self.n += 1
        self.s1 += r
        self.s2 += r * r
        if k_bin != self.bin:
            self.close()
            self.bin = k_bin
        self.bin_sum += r
        self.bin_n += 1

    def close(self) -> None:
        if self.bin_n:
            k = self.nb
            if k + 1 >= len(self.means):  # keep the spare slot for the open bin
                self.means = np.concatenate([self.means, np.empty(len(self.means))])
                self.counts = np.concatenate([self.counts, np.empty(len(self.counts))])
            self.means[k] = self.bin_sum / self.bin_n
            self.counts[k] = self.bin_n
            self.nb = k + 1
        self.bin_sum, self.bin_n = 0.0, 0

    def _bins(self) -> tuple[np.ndarray, np.ndarray]:
        """(bin means, residual counts), the open bin last: views of the buffers, valid until the
        next ``add``."""
        k = self.nb
        if self.bin_n:
            self.means[k] = self.bin_sum / self.bin_n
            self.counts[k] = self.bin_n
            k += 1
        return self.means[:k], self.counts[:k]

    def whiteness(self) -> float | None:
        m, _ = self._bins()
        if len(m) < 4:
            return None
        a = m - float(np.mean(m))
        den = float(a @ a)
        return float(a[1:] @ a[:-1]) / den if den > 0.0 else 0.0

    def tau_int(self) -> float | None:
        """The integrated autocorrelation time tau = 1 + 2 sum_(k=1..M) rho_k of the residuals,
        rho_k = (lag_sums[k] / (n - k) - rbar^2) / var, summed up to the first M >= 5 tau
        (Sokal's window; at most ``MAX_LAG``); None below 4 MAX_LAG residuals."""
        n = self.n
        if n < 4 * MAX_LAG:
            return None
        rbar = self.s1 / n
        var = self.s2 / n - rbar * rbar
        if not var > 0.0:
            return None
        k = np.arange(1, MAX_LAG + 1)
        rho = (self.lag_sums[1:] / (n - k) - rbar * rbar) / var
        tau = 1.0 + 2.0 * np.cumsum(rho)
        stop = np.flatnonzero(k >= 5.0 * tau)
        return float(max(tau[stop[0]] if len(stop) else tau[-1], 1.0))

    def long_run(self) -> float | None:
        m, c = self._bins()
        if len(m) < 4 or self.n < 2:
            return None
        rbar = self.s1 / self.n
        var = (self.s2 - self.n * rbar * rbar) / (self.n - 1)
        if not var > 0.0:
            return None
        return float(np.sum(c * (m - rbar) ** 2) / (len(m) - 1)) / var


class MismatchMonitor:
    """The residual statistics of one problem (module docstring). ``observe`` after each
    update that used rows; ``tests()`` / ``failed_rows`` / ``mismatch`` read them."""

    def __init__(self, problem: str, status_config, q):
        self.problem = problem
        self.config = status_config
        self._q = np.asarray(q, dtype=float)
        self._q_inv2 = 1.0 / self._q ** 2  # the design noise variance of each row
        self.names = ROW_NAMES[problem][:len(self._q)]
        self._bin_ns = max(int(round(status_config.mismatch_lag_s * 1e9)), 1)
        self.reset()

    def reset(self) -> None:
        self._rows = [_Row() for _ in self.names]
        self._tests: tuple[RowTest, ...] | None = None  # ``tests()`` until the next observe/reset

    def observe(self, t_ns: int, reg, x_prior: np.ndarray, c_prior: np.ndarray) -> None:
        """The normalised a priori residuals of the rows ``reg`` used (module docstring)."""
        a, b = reg.a, reg.b
        use = reg.used
        if True not in use:
            return
        k_bin = t_ns // self._bin_ns
        v = (b - a @ x_prior).tolist()
        s = (self._q_inv2 + np.einsum("ij,jk,ik->i", a, c_prior, a)).tolist()
        self._tests = None
        rows = self._rows
        for i, u in enumerate(use):
            if u:
                rows[i].add(k_bin, v[i] / math.sqrt(s[i]))

    def tests(self) -> tuple[RowTest, ...]:
        """The rows' tests, computed once per change of the residuals (the identifier reads them
        several times per estimate: ``failed_rows``, ``variance_scale``)."""
        if self._tests is None:
            self._tests = self._compute_tests()
        return self._tests

    def _compute_tests(self) -> tuple[RowTest, ...]:
        cfg = self.config
        out = []
        for name, row in zip(self.names, self._rows):
            n = row.n
            var = row.s2 / n if n else math.nan
            mean = row.s1 / n if n else math.nan
            white = row.whiteness()
            tested = n >= cfg.mismatch_min_rows and cfg.mismatch_test
            failed = bool(tested and (var > cfg.mismatch_variance_max
                                      or (white is not None and white > cfg.mismatch_whiteness_max)))
            out.append(RowTest(name, n, var, mean, white, row.long_run(), failed))
        return tuple(out)

    @property
    def variance_scale(self) -> float:
        """max(1, tau, tau_int) over the rows with ``mismatch_min_rows`` residuals (module
        docstring)."""
        taus = [t.long_run for t in self.tests() if t.long_run is not None and t.n >= self.config.mismatch_min_rows]
        taus += [v for v in (r.tau_int() for r in self._rows) if v is not None]
        return max([1.0, *taus])

    @property
    def failed_rows(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.tests() if t.failed)

    @property
    def mismatch(self) -> bool:
        return bool(self.failed_rows)
