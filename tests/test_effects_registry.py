"""The effect registry (model/effects/registry.py): the built-in canonical names and documented
effects; the shared registry is read-only; user effects join through the same API in a
registry of their own."""

import pytest

from vdps_hil.model.effects import (DYNAMICS_HOOKS, REGISTRY, DynamicsEffect, EffectConfigError, EffectRegistry,
                                    MeasurementEffect, ParamSpec)

CANONICAL = {"linear_tire", "magic_formula_tire", "aero_drag", "rolling_resistance",
             "load_dependent_cornering_stiffness", "low_pressure_tire", "crosswind", "steering_compliance",
             "roll_stiffness", "imu_bias", "imu_lever_arm", "steering_offset"}


def test_registry_has_the_canonical_names_and_documented_effects():
    assert set(REGISTRY) == CANONICAL
    for name, cls in REGISTRY.items():
        assert cls.name == name
        assert cls.family in ("dynamics", "measurement")
        assert issubclass(cls, DynamicsEffect if cls.family == "dynamics" else MeasurementEffect)
        doc = cls.__doc__ or ""
        assert name in doc and "default" in doc.lower(), name
        for p in cls.PARAMS:
            assert p.unit and p.description and p.lower <= p.default <= p.upper, (name, p.name)
        if cls.family == "dynamics":
            assert set(cls.HOOKS) <= set(DYNAMICS_HOOKS) and cls.HOOKS, name
        e = cls()  # defaults construct
        assert e.params == {p.name: p.default for p in cls.PARAMS}
        assert e.plausible()


class _Drift(DynamicsEffect):
    """``drift`` -- a constant forward force F = force_n [N] (default 10 N)."""
    name = "drift"
    HOOKS = ("body_wrench",)
    PARAMS = (ParamSpec("force_n", "N", 10.0, "x force", 0.0, 100.0),)


def test_the_shared_registry_is_read_only_and_extended_gives_a_new_one():
    with pytest.raises(TypeError, match="read-only"):
        REGISTRY.register(_Drift)
    reg = REGISTRY.extended([_Drift])
    assert isinstance(reg, EffectRegistry) and reg.names() == (*REGISTRY.names(), "drift")
    assert reg.get("drift") is _Drift and "drift" not in REGISTRY
    assert reg.make("drift", force_n=3.0).force_n == 3.0
    assert reg.register(_Drift) is _Drift  # the same class again: a no-op


def test_a_taken_name_and_unknown_names_are_one_line_errors():
    class Other(_Drift):
        name = "aero_drag"

    with pytest.raises(EffectConfigError, match="already registered"):
        REGISTRY.extended([Other])
    with pytest.raises(EffectConfigError, match="unknown effect 'nope'"):
        EffectRegistry([_Drift]).make("nope")
    with pytest.raises(EffectConfigError, match="not an effect class"):
        EffectRegistry([int])
