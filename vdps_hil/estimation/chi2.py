"""Chi-square distribution for the EKF's innovation gate: the CDF and the quantile of an
integer number of degrees of freedom, in closed form (no ``scipy.stats``).

The gate of an update with ``dof`` rows rejects NIS > chi2_quantile(p_gate, dof) (``ekf``
module docstring). With h = x / 2 the tails are the regularised incomplete gamma functions of
(dof / 2, h), summed as finite series (:func:`_chi2_tails`); the quantile is found by bisection
to adjacent doubles (:func:`chi2_quantile`).
"""

from __future__ import annotations

import math


def _chi2_tails(x: float, dof: int) -> tuple[float, float]:
    """(lower, upper) tail of the chi-square distribution with integer ``dof`` >= 1 at ``x``,
    each in closed form without cancellation: with h = x/2 and the series
    s = e^-h sum_{i<dof/2} h^i / i! (even dof) or e^-h sum_{i<(dof-1)/2} h^(i+1/2) / Gamma(i+3/2)
    (odd dof), upper = s (even) or erfc(sqrt h) + s (odd); lower = 1 - s (even) or
    erf(sqrt h) - s (odd) (the regularised incomplete gamma functions of dof/2, h)."""
    if not x > 0.0:
        return 0.0, 1.0
    h = 0.5 * x
    if dof % 2 == 0:
        term = total = 1.0
        for i in range(1, dof // 2):
            term *= h / i
            total += term
        s = math.exp(-h) * total
        return 1.0 - s, s
    r = math.sqrt(h)
    s = 0.0
    if dof > 1:
        term = total = r / math.gamma(1.5)
        for i in range(1, dof // 2):
            term *= h / (i + 0.5)
            total += term
        s = math.exp(-h) * total
    return math.erf(r) - s, math.erfc(r) + s


def chi2_cdf(x: float, dof: int) -> float:
    """Chi-square CDF for an integer ``dof`` >= 1 (:func:`_chi2_tails`)."""
    return _chi2_tails(x, dof)[0]


def chi2_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of the chi-square distribution with integer ``dof`` (the innovation
    gate), by bisection to adjacent doubles on the lower tail (p <= 0.5) or on the upper tail
    against 1 - p (exact in floating point for p > 0.5), so a gate probability near 1 keeps its
    precision. Tested against scipy's ``chi2.ppf``; computed here because importing
    ``scipy.stats`` costs every replay, bench and logger process ~0.4 s."""
    if not 0.0 < p < 1.0 or int(dof) != dof or dof < 1:
        raise ValueError(f"chi2_quantile needs 0 < p < 1 and an integer dof >= 1, got p={p!r}, dof={dof!r}")
    upper = p > 0.5
    q = 1.0 - p if upper else p

    def below(x: float) -> bool:  # is x below the quantile?
        lo_tail, up_tail = _chi2_tails(x, dof)
        return up_tail > q if upper else lo_tail < q

    lo, hi = 0.0, float(dof) + 10.0
    while below(hi):
        lo, hi = hi, 2.0 * hi
    while True:
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:  # adjacent doubles
            return hi
        if below(mid):
            lo = mid
        else:
            hi = mid
