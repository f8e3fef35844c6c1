"""Effects: the registry of canonical effect names and helpers to build effect sets.

``REGISTRY`` (an :class:`EffectRegistry`, :mod:`.registry`) maps each built-in canonical name
(used by ``--effect``, scenarios, the workbench and reports) to its class; a user's effects join
through the same API in a registry of their own (``REGISTRY.extended([MyEffect])``). Build
effects with :func:`make_effect` (parameters checked, one-line errors) and combine them in an
:class:`EffectSet`. :func:`effects_from_names` takes magnitudes from a vehicle truth file's
``[effects]`` table, then from explicit overrides.

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
roll_stiffness                     dynamics    chassis (anti-roll bars; ``model.chassis``)
imu_bias                           measurement imu
imu_lever_arm                      measurement imu
steering_offset                    measurement steering (the steering-angle sensor)
================================== =========== ==================================================
"""

from __future__ import annotations

from typing import Iterable, Mapping

from .aero import AeroDrag, Crosswind
from .chassis import RollStiffness
from .base import (DYNAMICS_HOOKS, EQUATIONS, DynamicsEffect, Effect, EffectConfigError, EffectSet,
                   ImuKinematics, MeasurementEffect, ParamSpec, TireModel)
from .imu import ImuBias, ImuLeverArm
from .registry import BUILTIN_EFFECTS, REGISTRY, EffectRegistry
from .rolling import RollingResistance
from .steering import SteeringCompliance, SteeringOffset
from .tires import LinearTire, LoadDependentCorneringStiffness, LowPressureTire, MagicFormulaTire

TIRE_MODEL_NAMES = tuple(n for n, c in REGISTRY.items() if issubclass(c, TireModel))


def make_effect(name: str, **params: float) -> Effect:
    """One built-in effect by canonical name (``REGISTRY.make``); unknown names or parameters
    raise EffectConfigError."""
    return REGISTRY.make(name, **params)


def effects_from_names(names: Iterable[str], vehicle_effects: Mapping | None = None,
                       overrides: Mapping[str, Mapping[str, float]] | None = None, *,
                       registry: EffectRegistry | None = None) -> EffectSet:
    """An EffectSet of the named effects (from ``registry``, default the built-in ``REGISTRY``).
    Magnitudes: the effect's defaults, then the vehicle truth file's ``[effects]`` table
    (``vehicle_effects``), then ``overrides``."""
    registry = REGISTRY if registry is None else registry
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
        out.append(registry.make(n, **params))
    return EffectSet(out)


__all__ = ["REGISTRY", "BUILTIN_EFFECTS", "EffectRegistry", "TIRE_MODEL_NAMES", "make_effect",
           "effects_from_names", "Effect", "DynamicsEffect", "MeasurementEffect", "TireModel", "EffectSet",
           "EffectConfigError", "ParamSpec", "ImuKinematics", "EQUATIONS", "DYNAMICS_HOOKS", "LinearTire",
           "MagicFormulaTire", "AeroDrag", "Crosswind", "RollingResistance",
           "LoadDependentCorneringStiffness", "LowPressureTire", "SteeringCompliance", "SteeringOffset", "RollStiffness", "ImuBias",
           "ImuLeverArm"]
