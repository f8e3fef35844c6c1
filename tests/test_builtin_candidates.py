"""The built-in effects' own adapters: crosswind, Magic Formula, tire saturation."""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.model.effects import REGISTRY, EffectSet
from vdps_hil.workbench import builtin_candidates as B
from vdps_hil.workbench import candidates as C


def test_crosswind_parameter_is_the_wind_across_the_mean_heading():
    c = C.candidate_for(REGISTRY["crosswind"])
    c.heading = 0.0  # driving east
    e = c.effect([8.0])
    assert e.wind_speed_mps == 8.0 and math.isclose(e.wind_to_rad, math.pi / 2)  # toward the left: north
    e = c.effect([-5.0])
    assert math.isclose(e.wind_to_rad, -math.pi / 2)
    rep = c.report_params(np.array([6.0]), np.array([0.1]))
    assert rep["wind_speed_mps"][0] == 6.0
    assert not c.plausible([41.0]) and c.material([2.0]) and not c.material([0.5])
    assert c.clip_phi([60.0])[0] == 40.0


def test_magic_formula_parameters():
    c = C.candidate_for(REGISTRY["magic_formula_tire"])
    assert c.to_phi([1.0])[0] == c.mu0
    assert c.to_phi([4.0])[0] == c.mu0 / 2.0
    assert c.to_phi([-1.0])[0] == c.profile_range[1]  # no saturation seen: the weakest in range
    assert c.phi_effect([0.8]).peak_friction == 0.8
    assert c.phi_plausible([1.0]) and not c.phi_plausible([2.0])
    assert c.material([1.0]) and not c.material([1.59])


def test_the_ranking_judges_tire_saturation_by_its_linear_column():
    """default_candidates offers the Magic Formula as the saturation column (linear in s); --add
    (candidate_for) keeps fitting the peak friction itself."""
    c = next(c for c in C.default_candidates(EffectSet()) if c.name == "magic_formula_tire")
    assert isinstance(c, B.TireSaturationCandidate) and c.linear
    rep = c.report_params(np.array([0.25]), np.array([0.05]))
    assert rep["peak_friction"][0] == 2.0 * c.mu0  # s = (mu_0 / mu)^2
    assert math.isclose(rep["peak_friction"][1], 0.5 * 2.0 * 0.05 / 0.25)
    assert c.effect([4.0]).peak_friction == c.mu0 / 2.0
    assert c.plausible([0.4]) and not c.plausible([-0.1]) and not c.plausible([0.0])
    assert c.material([0.5]) and not c.material([0.05])


def test_saturation_column_is_the_magic_formula_departure_from_the_linear_tire():
    """One row, one tire: the column is d(model)/dF_b (lateral_unit / -alpha) times F_MF - C alpha
    (1e-12 relative), zero at zero slip, and about cubic in small slip (ratio of two slips 0.001
    and 0.002 rad: 8 within 1 %)."""
    from types import SimpleNamespace

    mf = REGISTRY["magic_formula_tire"]()
    ca, fz, fz0 = 60000.0, 4200.0, 4000.0
    unit = np.zeros((1, 14, 4))

    def col(alpha):
        unit[0, :, 0] = 0.0
        unit[0, 1, 0], unit[0, 5, 0] = -alpha, -1.2 * alpha  # lateral force at x = 1.2 m, times alpha
        q = {"slip_angle_rad_1": alpha, "normal_load_n_1": fz, "static_load_n_1": fz0,
             "cornering_stiffness_nprad_1": ca}
        return B.saturation_columns(SimpleNamespace(t_s=np.zeros(1), lateral_unit=unit.copy(), quantities=[q]), mf)[0]

    a = 0.06
    dF = mf.tire_forces(fz, fz0, 0.0, a, 1.0, ca)[1] - ca * a
    out = col(a)
    assert dF < 0 and math.isclose(out[1], dF, rel_tol=1e-12) and math.isclose(out[5], 1.2 * dF, rel_tol=1e-12)
    assert np.all(col(0.0) == 0.0)
    assert math.isclose(col(0.002)[1] / col(0.001)[1], 8.0, rel_tol=0.01)
