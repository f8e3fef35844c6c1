"""The chi-square quantile of the EKF's innovation gate against scipy's chi2.ppf (the default
gate's table and every other probability), and the estimator chain's start-up without scipy."""

import math

import pytest
from scipy.stats import chi2

from vdps_hil.estimation.chi2 import GATE_TABLE, chi2_quantile


@pytest.mark.parametrize("dof", range(1, 7))
def test_chi2_gate_quantile_agrees_with_scipy(dof):
    """The table within 4 ulp of chi2.ppf; other probabilities (scipy.special.chdtri) within
    1e-12 relative over p in [1e-3, 1 - 1e-5]; bad arguments refused."""
    for p, row in GATE_TABLE.items():
        g = chi2_quantile(p, dof)
        assert g == row[dof - 1]
        assert abs(g - chi2.ppf(p, dof)) <= 4 * math.ulp(g)
    for p in (1e-3, 0.01, 0.05, 0.2, 0.5, 0.6, 0.9, 0.95, 0.99, 0.999, 0.99999):
        assert chi2_quantile(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-12, abs=0)
    for bad in ((0.0, dof), (1.0, dof), (0.5, 0), (0.5, 1.5)):
        with pytest.raises(ValueError):
            chi2_quantile(*bad)


def test_beyond_the_table_s_sizes():
    assert chi2_quantile(0.9999, 9) == pytest.approx(chi2.ppf(0.9999, 9), rel=1e-12)


def test_the_estimator_chain_does_not_import_scipy_special():
    """Importing the system (estimator, identifier, predictor) and building it with its default
    gate and aiding monitor leaves scipy's subpackages out: importing scipy.special alone costs
    each process over a second here (``estimation.chi2`` docstring). numba imports the bare
    ``scipy`` package (its version check, ~17 ms): only ``scipy`` and its ``_lib``/config
    modules are allowed."""
    import subprocess
    import sys

    code = ("import sys, vdps_hil.pipeline.node, vdps_hil.app.replay, vdps_hil.cli.replay_cmd; "
            "from vdps_hil.pipeline.node import VdpsSystem, SystemConfig; "
            "from vdps_hil.model.params import load_vehicle; "
            "VdpsSystem(load_vehicle('sedan-model', 'model'), SystemConfig()); "
            "print(' '.join(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    heavy = [m for m in out.split() if m != "scipy" and m.split(".")[1] not in
             ("__config__", "_cyutility", "_distributor_init", "_lib", "version")]
    assert heavy == [], heavy
