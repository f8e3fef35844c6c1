"""The chi-square CDF and quantile of the EKF's innovation gate against scipy, and the estimator
chain's start-up without scipy.stats."""

import math

import pytest
from scipy.stats import chi2

from vdps_hil.estimation.chi2 import chi2_cdf, chi2_quantile


@pytest.mark.parametrize("dof", range(1, 7))
def test_chi2_gate_quantile_agrees_with_scipy(dof):
    """The gate's chi-square quantile (computed without importing scipy.stats): within 1e-13
    relative of scipy's chi2.ppf over p in [1e-3, 1 - 1e-5], within 4 ulp at the default gate
    probability 0.9999 (upper tail solved against the exact 1 - p); the CDF within 1e-15; bad
    arguments refused."""
    for p in (1e-3, 0.01, 0.05, 0.2, 0.5, 0.6, 0.9, 0.95, 0.99, 0.999, 0.9999, 0.99999):
        assert chi2_quantile(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-13, abs=0)
    g = chi2_quantile(0.9999, dof)
    assert abs(g - chi2.ppf(0.9999, dof)) <= 4 * math.ulp(g)
    for x in (0.0, 0.1, 1.0, 3.0, 7.5, 15.0, 40.0):
        assert chi2_cdf(x, dof) == pytest.approx(chi2.cdf(x, dof), rel=0, abs=1e-15)
    for bad in ((0.0, dof), (1.0, dof), (0.5, 0), (0.5, 1.5)):
        with pytest.raises(ValueError):
            chi2_quantile(*bad)


def test_the_estimator_chain_does_not_import_scipy_stats():
    """Importing the system (estimator, identifier, predictor) leaves scipy.stats out: it would
    cost every replay, bench and logger process ~0.4 s of start-up (fresh interpreter)."""
    import subprocess
    import sys

    code = ("import sys, vdps_hil.pipeline.node, vdps_hil.app.replay, vdps_hil.cli.replay_cmd; "
            "print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
