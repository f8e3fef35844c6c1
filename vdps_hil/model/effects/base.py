"""Effects: named physical effects behind one small interface, composable into an EffectSet.

An *effect* is a piece of physics with a canonical name, a family, parameters with units and
default magnitudes, and a docstring giving its formula. Two families:

* ``dynamics`` effects change the vehicle's motion. They act on the physics core
  (:mod:`vdps_hil.model.core`) through a few *hooks*; an effect overrides the hooks it needs and
  lists them in ``HOOKS``:

  ==========================  ==================================================================
  hook                        what the core does with it
  ==========================  ==================================================================
  ``tire_forces``             the tire force law (``TireModel``; exactly one per model)
  ``rolling_radius_factor``   r_i = r * factor (static, per corner)
  ``cornering_stiffness_factor``  C_alpha,i = C_alpha,i,0 * factor(F_z,i, F_z0,i)
  ``compliance_steer``        front road-wheel angles delta_i -= K_c * (F_b,1 + F_b,2)
  ``body_wrench``             force [N] and moment [N m] about the sprung CG, body axes
  ``wheel_torque``            extra torque [N m] on wheel i's spin axis
  ``anti_roll_stiffness``     auxiliary roll stiffness (front, rear) [N m/rad] added to the
                              vehicle's anti-roll bars (``model.chassis``; static)
  ==========================  ==================================================================

  The compiled core (:mod:`vdps_hil.model.core_kernel`) takes an effect through
  ``kernel_terms()``: ``(hook, code, parameters)`` per per-call hook, the code naming the
  effect's compiled contribution (an :func:`~vdps_hil.jit.inline` function the effect's own
  method also calls, so the formula is written once). Hooks the core resolves at construction
  (``STATIC_HOOKS``) need no term. An effect without a compiled form (``kernel_terms()`` is
  None, the default for per-call hooks, or a subclass overriding a hook of its parent's
  compiled form) makes its model run on the Python core, stated by ``Model.compiled_status``.

  Where an effect's contribution is linear in its parameters it offers ``regressors(q)``:
  ``{equation: {parameter: d(contribution)/d(parameter)}}`` over the equations of eq 13
  (``EQUATIONS``), evaluated from named quantities ``q`` (the names of the truth snapshot, see
  :mod:`vdps_hil.sim.simulator`, which an estimator can fill from its own estimates).

* ``measurement`` effects change what a sensor reports: ``apply(fields, kin)`` maps a reading
  (bus catalogue names, SI) and the rigid-body kinematics at the CG to the reading the sensor
  gives; ``regressors(kin)`` gives ``{field: {parameter: d(field)/d(parameter)}}`` for the
  estimator's innovations.

Effects are immutable: parameters are fixed at construction (defaults from the class; truth
magnitudes from a vehicle truth file's ``[effects]`` table or a scenario). A new value means a
new object (``effect.replace(name=value)``). ``REGISTRY`` (:mod:`vdps_hil.model.effects.registry`)
maps the built-in canonical names to classes; a user's own effect is a subclass that joins through
the same :class:`~vdps_hil.model.effects.registry.EffectRegistry` API (``REGISTRY.extended``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Iterable, Iterator, Mapping

EQUATIONS: tuple[str, ...] = ("long", "lat", "vert", "roll", "pitch", "yaw",
                              "wheel_1", "wheel_2", "wheel_3", "wheel_4")
"""The equations of eq 13 a dynamics regressor can enter: body-frame force balance [N]
(long/lat/vert), moment balance about the sprung CG [N m] (roll/pitch/yaw) and the four wheel
spin balances [N m]."""

DYNAMICS_HOOKS: tuple[str, ...] = ("tire_forces", "rolling_radius_factor",
                                   "cornering_stiffness_factor", "compliance_steer",
                                   "body_wrench", "wheel_torque", "anti_roll_stiffness")
STATIC_HOOKS: frozenset[str] = frozenset({"rolling_radius_factor", "compliance_steer", "anti_roll_stiffness"})
"""Hooks the core evaluates once, when a model is built (no per-call contribution)."""


class EffectConfigError(ValueError):
    """Unknown effect or parameter, or a bad value; the message is one line."""


@dataclass(frozen=True)
class ParamSpec:
    """One effect parameter: name (with its unit suffix), unit, default magnitude, meaning and
    the physically plausible range (a fit outside it is implausible)."""

    name: str
    unit: str
    default: float
    description: str
    lower: float = -math.inf
    upper: float = math.inf


def _rebuild_effect(cls, values: dict):
    return cls(**values)


class Effect:
    """Base of every effect. Subclasses set ``name``, ``family``, ``PARAMS`` and a docstring
    with formula, units and default magnitude."""

    name: ClassVar[str] = ""
    family: ClassVar[str] = ""
    PARAMS: ClassVar[tuple[ParamSpec, ...]] = ()

    __slots__ = ("_values",)

    def __init__(self, **params: Any):
        specs = {p.name: p for p in self.PARAMS}
        for k in params:
            if k not in specs:
                known = ", ".join(specs) or "none"
                raise EffectConfigError(f"effect {self.name!r}: unknown parameter {k!r} (known: {known})")
        values: dict[str, float] = {}
        for p in self.PARAMS:
            v = params.get(p.name, p.default)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise EffectConfigError(f"effect {self.name!r}: parameter {p.name!r} must be a finite number, got {v!r}")
            values[p.name] = float(v)
        object.__setattr__(self, "_values", values)
        self._validate()

    def _validate(self) -> None:
        """Subclasses raise EffectConfigError for inconsistent values."""

    def __setattr__(self, key, value):
        raise AttributeError(f"effect {self.name!r} is immutable; use .replace({key}=...)")

    def __reduce__(self):
        """Pickled as its class and parameters (a prediction worker process rebuilds it)."""
        return (_rebuild_effect, (type(self), dict(self._values)))

    def __getattr__(self, key):
        values = object.__getattribute__(self, "_values")
        try:
            return values[key]
        except KeyError:
            raise AttributeError(key) from None

    @property
    def params(self) -> dict[str, float]:
        """Parameter name -> value (a copy)."""
        return dict(self._values)

    def replace(self, **changes: float) -> "Effect":
        """A new effect of the same kind with some parameters changed."""
        return type(self)(**{**self._values, **changes})

    @classmethod
    def param_specs(cls) -> dict[str, ParamSpec]:
        return {p.name: p for p in cls.PARAMS}

    def _first_implausible(self) -> ParamSpec | None:
        return next((p for p in self.PARAMS if not p.lower <= self._values[p.name] <= p.upper), None)

    def plausible(self) -> bool:
        """True when every parameter is inside its plausible range."""
        return self._first_implausible() is None

    def check_plausible(self) -> None:
        """Raise EffectConfigError (one line) naming the first parameter outside its plausible
        range: a truth given to the simulator must be a car that can exist (a fit may leave the
        range and is labelled implausible instead)."""
        p = self._first_implausible()
        if p is not None:
            v = self._values[p.name]
            raise EffectConfigError(f"effect {self.name!r}: {p.name} = {v:g} {p.unit} is outside its "
                                    f"physical range [{p.lower:g}, {p.upper:g}] {p.unit}")

    def __eq__(self, other):
        return type(self) is type(other) and self._values == other._values

    def __hash__(self):
        return hash((type(self), tuple(sorted(self._values.items()))))

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v:g}" for k, v in self._values.items())
        return f"{type(self).__name__}({inner})"


class DynamicsEffect(Effect):
    """An effect on the vehicle's motion. Override the hooks you need and list them in HOOKS.

    Hook signatures (all SI, body axes x fwd y left z up, corners 0..3 = FL FR RR RL)::

        rolling_radius_factor(corner) -> float
        cornering_stiffness_factor(corner, fz_n, fz0_n) -> float
        compliance_steer() -> K_c [rad/N]   (front road-wheel angle per N of front lateral force)
        body_wrench(vel_b, omega_b, air_b) -> (Fx, Fy, Fz, Mx, My, Mz)   [N, N m] about the CG
            vel_b: CG velocity, omega_b: body rates, air_b: CG velocity relative to the air
        wheel_torque(corner, omega_radps, fz_n, radius_m) -> torque [N m] on the spin axis
        anti_roll_stiffness() -> (K_front, K_rear) [N m/rad]
    """

    family: ClassVar[str] = "dynamics"
    HOOKS: ClassVar[tuple[str, ...]] = ()
    LINEAR_IN_PARAMETERS: ClassVar[bool] = False

    def rolling_radius_factor(self, corner: int) -> float:
        return 1.0

    def cornering_stiffness_factor(self, corner: int, fz_n: float, fz0_n: float) -> float:
        return 1.0

    def compliance_steer(self) -> float:
        return 0.0

    def body_wrench(self, vel_b, omega_b, air_b) -> tuple[float, float, float, float, float, float]:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def wheel_torque(self, corner: int, omega_radps: float, fz_n: float, radius_m: float) -> float:
        return 0.0

    def anti_roll_stiffness(self) -> tuple[float, float]:
        return (0.0, 0.0)

    def kernel_terms(self) -> tuple[tuple[str, int, tuple[float, ...]], ...] | None:
        """The compiled form: ``((hook, code, parameters), ...)`` for each per-call hook (module
        docstring); ``()`` when every hook is static; None: no compiled form."""
        return () if set(self.HOOKS) <= STATIC_HOOKS else None

    def regressors(self, q: Mapping[str, float]) -> dict[str, dict[str, float]]:
        """{equation: {parameter: d(contribution)/d(parameter)}} at the quantities ``q``.
        Only for effects linear in their parameters (``LINEAR_IN_PARAMETERS``)."""
        raise NotImplementedError(f"effect {self.name!r} is not linear in its parameters")


class TireModel(DynamicsEffect):
    """A tire force law (exactly one per model). ``tire_forces`` gets one corner's normal load
    F_z [N], nominal static load F_z0 [N], slip ratio kappa [-], slip angle alpha [rad] and the
    corner's slip stiffnesses C_kappa [N], C_alpha [N/rad] (from the vehicle's identified
    parameters, possibly scaled by other effects) and returns the longitudinal and lateral
    adhesive forces (F_a, F_b) [N] in the wheel's road-plane axes (eq 15 convention)."""

    HOOKS: ClassVar[tuple[str, ...]] = ("tire_forces",)

    def tire_forces(self, fz_n: float, fz0_n: float, kappa: float, alpha_rad: float,
                    c_kappa_n: float, c_alpha_nprad: float) -> tuple[float, float]:
        raise NotImplementedError


@dataclass(frozen=True)
class ImuKinematics:
    """Rigid-body kinematics a sensor model needs, all in body axes at the sprung CG:
    specific force f = a - g [m/s^2], angular rate omega [rad/s], angular acceleration
    omega_dot [rad/s^2]."""

    t_s: float
    specific_force_mps2: tuple[float, float, float]
    angular_rate_radps: tuple[float, float, float]
    angular_accel_radps2: tuple[float, float, float]


class MeasurementEffect(Effect):
    """An effect on what a sensor reports. ``apply(fields, kin)`` returns a new dict of catalogue
    fields; fields it does not know pass through unchanged."""

    family: ClassVar[str] = "measurement"
    FIELDS: ClassVar[tuple[str, ...]] = ()
    """Catalogue fields this effect changes."""

    def apply(self, fields: Mapping[str, float], kin: ImuKinematics) -> dict[str, float]:
        raise NotImplementedError

    def regressors(self, kin: ImuKinematics) -> dict[str, dict[str, float]]:
        """{field: {parameter: d(field)/d(parameter)}}."""
        raise NotImplementedError


class EffectSet:
    """An ordered, immutable collection of effect instances (at most one of each name, at most
    one tire model). Compose with ``+``; look up by name with ``in`` and ``[name]``."""

    __slots__ = ("_effects",)

    def __init__(self, effects: Iterable[Effect] = ()):
        effects = tuple(effects)
        names: set[str] = set()
        tires = []
        for e in effects:
            if not isinstance(e, Effect):
                raise EffectConfigError(f"not an effect: {e!r}")
            if e.name in names:
                raise EffectConfigError(f"effect {e.name!r} given twice")
            names.add(e.name)
            if isinstance(e, TireModel):
                tires.append(e.name)
        if len(tires) > 1:
            raise EffectConfigError(f"tire models are mutually exclusive: {' and '.join(tires)}")
        object.__setattr__(self, "_effects", effects)

    def __setattr__(self, key, value):
        raise AttributeError("EffectSet is immutable")

    def __reduce__(self):
        return (EffectSet, (self._effects,))

    def __add__(self, other) -> "EffectSet":
        if isinstance(other, Effect):
            other = (other,)
        return EffectSet((*self._effects, *tuple(other)))

    def __iter__(self) -> Iterator[Effect]:
        return iter(self._effects)

    def __len__(self) -> int:
        return len(self._effects)

    def __contains__(self, name: object) -> bool:
        return any(e.name == name for e in self._effects)

    def __getitem__(self, name: str) -> Effect:
        for e in self._effects:
            if e.name == name:
                return e
        raise KeyError(name)

    def __eq__(self, other):
        return isinstance(other, EffectSet) and self._effects == other._effects

    def __repr__(self) -> str:
        return f"EffectSet({', '.join(e.name for e in self._effects)})"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self._effects)

    @property
    def dynamics(self) -> tuple[DynamicsEffect, ...]:
        return tuple(e for e in self._effects if isinstance(e, DynamicsEffect))

    @property
    def measurement(self) -> tuple[MeasurementEffect, ...]:
        return tuple(e for e in self._effects if isinstance(e, MeasurementEffect))

    @property
    def tire(self) -> TireModel | None:
        for e in self._effects:
            if isinstance(e, TireModel):
                return e
        return None

    def without(self, *names: str) -> "EffectSet":
        return EffectSet(e for e in self._effects if e.name not in names)
