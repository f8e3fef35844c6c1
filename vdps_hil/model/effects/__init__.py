"""Effects: the registry of canonical effect names and helpers to build effect sets.

``REGISTRY`` maps each canonical name (used by ``--effect``, scenarios, the workbench and reports)
to its class. Build effects with :func:`make_effect` (parameters checked, one-line errors) and
combine them in an :class:`EffectSet`. :func:`effects_from_names` takes magnitudes from a vehicle
truth file's ``[effects]`` table, then from explicit overrides.

================================== =========== ==================================================
name                               family      module
================================== =========== ==================================================
linear_tire                        dynamics    tires (eq 15-17)
magic_formula_tire                 dynamics    tires (Pacejka, combined slip, load sensitivity)
load_dependent_cornering_stiffness dynamics    tires
low_pressure_tire                  dynamics    tires
aero_drag                          dynamics    aero
crosswind                          dynamics    aero
rolling_resistance                 dynamics    rolling
steering_compliance                dynamics    steering
imu_bias                           measurement imu
imu_lever_arm                      measurement imu
================================== =========== ==================================================
"""

from __future__ import annotations

from typing import Iterable, Mapping

from .aero import AeroDrag, Crosswind
from .base import (DYNAMICS_HOOKS, EQUATIONS, DynamicsEffect, Effect, EffectConfigError, EffectSet,
                   ImuKinematics, MeasurementEffect, ParamSpec, TireModel)
from .imu import ImuBias, ImuLeverArm
from .rolling import RollingResistance
from .steering import SteeringCompliance
from .tires import LinearTire, LoadDependentCorneringStiffness, LowPressureTire, MagicFormulaTire

REGISTRY: dict[str, type[Effect]] = {
    cls.name: cls for cls in (
        LinearTire, MagicFormulaTire, AeroDrag, RollingResistance, LoadDependentCorneringStiffness,
        LowPressureTire, Crosswind, SteeringCompliance, ImuBias, ImuLeverArm)
}
"""Canonical name -> effect class. Add your own: ``REGISTRY[MyEffect.name] = MyEffect``."""

TIRE_MODEL_NAMES = tuple(n for n, c in REGISTRY.items() if issubclass(c, TireModel))


def make_effect(name: str, **params: float) -> Effect:
    """One effect by canonical name; unknown names or parameters raise EffectConfigError."""
    try:
        cls = REGISTRY[name]
    except KeyError:
        raise EffectConfigError(f"unknown effect {name!r} (known: {', '.join(REGISTRY)})") from None
    return cls(**params)


def effects_from_names(names: Iterable[str], vehicle_effects: Mapping | None = None,
                       overrides: Mapping[str, Mapping[str, float]] | None = None) -> EffectSet:
    """An EffectSet of the named effects. Magnitudes: the effect's defaults, then the vehicle
    truth file's ``[effects]`` table (``vehicle_effects``), then ``overrides``."""
    vehicle_effects = vehicle_effects or {}
    overrides = overrides or {}
    names = list(names)
    for n in overrides:
        if n not in names:
            raise EffectConfigError(f"parameters given for effect {n!r} which is not switched on")
    out = []
    for n in names:
        params = {}
        base = vehicle_effects.get(n, {})
        if not isinstance(base, Mapping):
            raise EffectConfigError(f"vehicle [effects].{n} must be a table")
        params.update(base)
        params.update(overrides.get(n, {}))
        out.append(make_effect(n, **params))
    return EffectSet(out)


__all__ = ["REGISTRY", "TIRE_MODEL_NAMES", "make_effect", "effects_from_names", "Effect",
           "DynamicsEffect", "MeasurementEffect", "TireModel", "EffectSet", "EffectConfigError",
           "ParamSpec", "ImuKinematics", "EQUATIONS", "DYNAMICS_HOOKS", "LinearTire",
           "MagicFormulaTire", "AeroDrag", "Crosswind", "RollingResistance",
           "LoadDependentCorneringStiffness", "LowPressureTire", "SteeringCompliance", "ImuBias",
           "ImuLeverArm"]
