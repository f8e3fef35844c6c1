"""Where it fails: worst windows and residuals over the regime (synthetic residuals with a known
defect, and a real drive's regime variables)."""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.experiments.workbench_study import cached_drive
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import regimes as G
from vdps_hil.workbench.dataset import load_drive
from vdps_hil.workbench.residuals import EQUATIONS, EquationResiduals, compute_residuals

VEH = load_vehicle("sedan-model")


def _res(values, t):
    n = len(t)
    return EquationResiduals(t_s=t, index=np.arange(n), values=values, sigma=np.ones(14), nuisance=None,
                             quantities=[], available=np.ones(14, bool), vehicle=VEH, effects=EffectSet())


def test_worst_windows_find_the_defects_in_order():
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20.0, 0.02)
    v = rng.normal(0, 1, (len(t), 14))
    v[(t > 5.0) & (t < 6.0), EQUATIONS.index("lat")] += 6.0
    v[(t > 12.0) & (t < 13.0), EQUATIONS.index("yaw")] += 4.0
    w = G.worst_windows(_res(v, t), window_s=1.0, n=2)
    assert [x.equation for x in w] == ["lat", "yaw"]
    assert w[0].t_start_s == pytest.approx(5.0, abs=0.1) and w[1].t_start_s == pytest.approx(12.0, abs=0.1)
    assert w[0].misfit > w[1].misfit


@pytest.fixture(scope="module")
def drive(drive_cache):
    path = cached_drive(drive_cache, "step-steer", (), seed=5)
    tab = load_drive(path, VEH)
    return tab, compute_residuals(tab, VEH, EffectSet())


def test_regime_variables_and_bins(drive):
    tab, res = drive
    v = G.regime_variables(tab, res)
    assert set(G.REGIME_LABELS) == set(v)
    assert np.nanmax(v["ay_mps2"]) == pytest.approx(4.0, abs=0.6)  # the step to 4 m/s^2
    assert np.nanmax(v["slip_angle_front_deg"]) > 0.5
    bins = G.regime_bins(tab, res, n_bins=5)
    b = bins["ay_mps2"]
    assert b.counts.sum() == np.isfinite(v["ay_mps2"]).sum()
    assert np.all(np.diff(b.edges) >= 0) and b.rms.shape[1] == 14
    # the top bin's RMS is the RMS of the rows with the largest lateral accelerations
    lat = EQUATIONS.index("lat")
    ay = v["ay_mps2"]
    top = np.isfinite(ay) & (ay >= b.edges[-2])
    assert b.rms[-1, lat] == pytest.approx(np.sqrt(np.mean(res.values[top, lat] ** 2)), rel=1e-9)
    assert set(b.to_json()) == {"variable", "edges", "centres", "counts", "rms"}
