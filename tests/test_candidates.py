"""Candidates: the right adapter per effect, parameter spaces, plausibility and materiality."""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.model.effects import REGISTRY, DynamicsEffect, EffectSet, ParamSpec
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import candidates as C


def test_adapters_per_built_in_effect():
    kinds = {n: type(C.candidate_for(cls)).__name__ for n, cls in REGISTRY.items() if n != "linear_tire"}
    assert kinds == {"magic_formula_tire": "MagicFormulaCandidate", "aero_drag": "RegressorCandidate",
                     "rolling_resistance": "RegressorCandidate",
                     "load_dependent_cornering_stiffness": "NumericCandidate",
                     "low_pressure_tire": "LowPressureCandidate", "crosswind": "CrosswindCandidate",
                     "steering_compliance": "NumericCandidate", "imu_bias": "MeasurementCandidate",
                     "imu_lever_arm": "MeasurementCandidate"}


def test_default_candidates_skip_the_models_effects_and_the_linear_tire():
    names = [c.name for c in C.default_candidates(EffectSet([REGISTRY["aero_drag"]()]))]
    assert "aero_drag" not in names and "linear_tire" not in names and len(names) == 8


def test_user_effect_without_regressors_is_numeric():
    class Push(DynamicsEffect):
        name = "push"
        HOOKS = ("body_wrench",)
        PARAMS = (ParamSpec("force_n", "N", 100.0, "x force", 0.0, 1000.0),)

        def body_wrench(self, vel_b, omega_b, air_b):
            return (self.force_n, 0.0, 0.0, 0.0, 0.0, 0.0)

    c = C.candidate_for(Push)
    assert isinstance(c, C.NumericCandidate) and c.params == ("force_n",) and c.linear
    assert C.default_candidates(EffectSet(), [Push])[-1].name == "push"


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


def test_plausibility_and_materiality():
    drag = C.candidate_for(REGISTRY["aero_drag"])
    assert drag.plausible([0.7]) and not drag.plausible([-0.1])
    assert drag.material([0.7]) and not drag.material([0.02])
    assert drag.clip_phi([-0.3])[0] == 0.0
    lp = C.candidate_for(REGISTRY["low_pressure_tire"])
    assert not lp.material([0.0003]) and lp.material([0.015])


def test_parameter_candidate():
    p = C.ParameterCandidate("mass_kg", load_vehicle("sedan-model"))
    assert p.name == "mass" and p.kind == "parameter" and p.plausible([1.0]) and not p.plausible([-1.0])


def test_the_ranking_judges_tire_saturation_by_its_linear_column():
    """default_candidates offers the Magic Formula as the saturation column (linear in s); --add
    (candidate_for) keeps fitting the peak friction itself."""
    c = next(c for c in C.default_candidates(EffectSet()) if c.name == "magic_formula_tire")
    assert isinstance(c, C.TireSaturationCandidate) and c.linear
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
        return C.saturation_columns(SimpleNamespace(t_s=np.zeros(1), lateral_unit=unit.copy(), quantities=[q]), mf)[0]

    a = 0.06
    dF = mf.tire_forces(fz, fz0, 0.0, a, 1.0, ca)[1] - ca * a
    out = col(a)
    assert dF < 0 and math.isclose(out[1], dF, rel_tol=1e-12) and math.isclose(out[5], 1.2 * dF, rel_tol=1e-12)
    assert np.all(col(0.0) == 0.0)
    assert math.isclose(col(0.002)[1] / col(0.001)[1], 8.0, rel_tol=0.01)
