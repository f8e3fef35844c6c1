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
