"""Effect interface: parameters with units, immutability, EffectSet composition, a user effect
in a registry of its own, regressors equal to the contributions of effects linear in their
parameters."""

import pytest

from vdps_hil.model.effects import (REGISTRY, DynamicsEffect, EffectConfigError, EffectSet, TireModel,
                                    effects_from_names, make_effect)

def test_effects_are_immutable_and_replace_gives_new_objects():
    d = make_effect("aero_drag", cda_m2=0.6)
    with pytest.raises(AttributeError):
        d.cda_m2 = 1.0
    d2 = d.replace(cda_m2=0.8)
    assert d.cda_m2 == 0.6 and d2.cda_m2 == 0.8 and d != d2 and d == make_effect("aero_drag", cda_m2=0.6)


def test_bad_names_and_values_are_one_line_errors():
    with pytest.raises(EffectConfigError, match="unknown effect"):
        make_effect("flux_capacitor")
    with pytest.raises(EffectConfigError, match="finite number"):
        make_effect("aero_drag", cda_m2=float("nan"))
    with pytest.raises(EffectConfigError, match="given twice"):
        EffectSet([make_effect("aero_drag"), make_effect("aero_drag")])


def test_check_plausible_names_the_parameter_and_its_physical_range():
    make_effect("aero_drag", cda_m2=3.0).check_plausible()  # the bound itself is a car
    e = make_effect("aero_drag", cda_m2=-0.5)  # a fit may leave the range: built, then labelled
    assert not e.plausible()
    with pytest.raises(EffectConfigError, match=r"cda_m2 = -0.5 m\^2 is outside its physical range \[0, 3\] m\^2"):
        e.check_plausible()
    with pytest.raises(EffectConfigError, match="gyro_bias_z_radps"):
        make_effect("imu_bias", gyro_bias_z_radps=0.06).check_plausible()


def test_effect_set_composition_and_lookup():
    s = EffectSet([make_effect("aero_drag")]) + make_effect("imu_bias") + [make_effect("magic_formula_tire")]
    assert s.names == ("aero_drag", "imu_bias", "magic_formula_tire")
    assert "imu_bias" in s and s["aero_drag"].cda_m2 == 0.7
    assert [e.name for e in s.dynamics] == ["aero_drag", "magic_formula_tire"]
    assert [e.name for e in s.measurement] == ["imu_bias"]
    assert isinstance(s.tire, TireModel) and s.without("magic_formula_tire").tire is None


def test_magnitudes_come_from_vehicle_then_overrides():
    veh = {"magic_formula_tire": {"peak_friction": 0.9}}
    s = effects_from_names(["magic_formula_tire"], veh, {"magic_formula_tire": {"shape_lateral": 1.4}})
    e = s["magic_formula_tire"]
    assert e.peak_friction == 0.9 and e.shape_lateral == 1.4 and e.curvature_lateral == -1.0
    with pytest.raises(EffectConfigError, match="not switched on"):
        effects_from_names([], veh, {"aero_drag": {"cda_m2": 1.0}})


def test_user_effect_takes_part_like_builtin_ones():
    """A user's dynamics effect (a constant push) registered by name acts in the core."""
    from vdps_hil.model.core import Env, Inputs, Model
    from vdps_hil.model.effects.base import ParamSpec
    from vdps_hil.model.params import load_vehicle

    class Push(DynamicsEffect):
        """``push`` -- a constant forward force F = force_n [N] at the CG (default 100 N)."""
        name = "push"
        HOOKS = ("body_wrench",)
        PARAMS = (ParamSpec("force_n", "N", 100.0, "forward push"),)

        def body_wrench(self, vel_b, omega_b, air_b):
            return (self.force_n, 0.0, 0.0, 0.0, 0.0, 0.0)

    registry = REGISTRY.extended([Push])  # a registry of this test's own; the shared one is untouched
    v = load_vehicle("sedan-truth")
    m = Model(v, effects_from_names(["push"], registry=registry))
    raw = {}
    m.f(m.design_state(0.0), Inputs(), Env(), raw)
    assert raw["_acc_b"][0] == pytest.approx(100.0 / v.params.mass_kg)
    assert "push" in registry and "push" not in REGISTRY
