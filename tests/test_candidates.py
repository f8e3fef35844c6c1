"""Candidates: the right adapter per effect and the candidates a ranking considers."""

from __future__ import annotations

from vdps_hil.model.effects import REGISTRY, DynamicsEffect, EffectSet, ParamSpec
from vdps_hil.workbench import candidate_base as CB
from vdps_hil.workbench import candidates as C


def test_adapters_per_built_in_effect():
    kinds = {n: type(C.candidate_for(cls)).__name__ for n, cls in REGISTRY.items() if n != "linear_tire"}
    assert kinds == {"magic_formula_tire": "MagicFormulaCandidate", "aero_drag": "RegressorCandidate",
                     "rolling_resistance": "RegressorCandidate",
                     "load_dependent_cornering_stiffness": "NumericCandidate",
                     "low_pressure_tire": "LowPressureCandidate", "crosswind": "CrosswindCandidate",
                     "steering_compliance": "NumericCandidate", "roll_stiffness": "RegressorCandidate",
                     "imu_bias": "MeasurementCandidate",
                     "imu_lever_arm": "MeasurementCandidate", "steering_offset": "SteeringOffsetCandidate"}
    # a sensor effect whose evidence is the balance rows: fitted and judged as a dynamics effect
    so = C.candidate_for(REGISTRY["steering_offset"])
    assert so.family == "dynamics" and REGISTRY["steering_offset"].family == "measurement"


def test_default_candidates_skip_the_models_effects_and_the_linear_tire():
    names = [c.name for c in C.default_candidates(EffectSet([REGISTRY["aero_drag"]()]))]
    assert "aero_drag" not in names and "linear_tire" not in names and len(names) == 9
    assert "steering_offset" not in names and set(C.ADD_ONLY) == {"steering_offset"}  # --add only (ADD_ONLY)


def test_user_effect_without_regressors_is_numeric():
    class Push(DynamicsEffect):
        name = "push"
        HOOKS = ("body_wrench",)
        PARAMS = (ParamSpec("force_n", "N", 100.0, "x force", 0.0, 1000.0),)

        def body_wrench(self, vel_b, omega_b, air_b):
            return (self.force_n, 0.0, 0.0, 0.0, 0.0, 0.0)

    c = C.candidate_for(Push)
    assert isinstance(c, CB.NumericCandidate) and c.params == ("force_n",) and c.linear
    assert C.default_candidates(EffectSet(), [Push])[-1].name == "push"
