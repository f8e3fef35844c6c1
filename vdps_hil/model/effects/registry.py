"""The effect registry: canonical effect name -> effect class, the one door through which the
built-in effects and a user's own effects are named (``--effect``, scenarios, model files, the
workbench).

* :class:`EffectRegistry` -- ``register(cls)``, ``get(name)`` / ``[name]``, ``names()``,
  ``make(name, **params)`` (parameters checked, one-line errors) and ``extended(classes)`` (a new
  registry with more effects). A name is registered once: another class under a taken name is
  an :class:`~vdps_hil.model.effects.base.EffectConfigError`.
* ``REGISTRY`` -- the built-in effects (:data:`BUILTIN_EFFECTS`, listed explicitly here; nothing
  registers itself on import). It is read-only: code that adds effects (a user's file or entry
  point, :mod:`vdps_hil.workbench.user_effects`; a test) builds its own registry with
  ``REGISTRY.extended([MyEffect])`` and passes it on (e.g. ``effects_from_names(..., registry=)``).
"""

from __future__ import annotations

from typing import Iterable, Iterator, Mapping

from .aero import AeroDrag, Crosswind
from .base import Effect, EffectConfigError
from .chassis import RollStiffness
from .imu import ImuBias, ImuLeverArm
from .rolling import RollingResistance
from .steering import SteeringCompliance, SteeringOffset
from .tires import LinearTire, LoadDependentCorneringStiffness, LowPressureTire, MagicFormulaTire

BUILTIN_EFFECTS: tuple[type[Effect], ...] = (
    LinearTire, MagicFormulaTire, AeroDrag, RollingResistance, LoadDependentCorneringStiffness,
    LowPressureTire, Crosswind, SteeringCompliance, RollStiffness, ImuBias, ImuLeverArm, SteeringOffset)
"""The built-in effect classes, in the order the registry lists them."""


class EffectRegistry(Mapping[str, type[Effect]]):
    """Canonical name -> effect class (a read-only mapping plus ``register``; module docstring).
    ``read_only=True`` refuses ``register`` (the shared built-in registry)."""

    __slots__ = ("_classes", "_read_only")

    def __init__(self, classes: Iterable[type[Effect]] = (), *, read_only: bool = False):
        self._classes: dict[str, type[Effect]] = {}
        self._read_only = False
        for cls in classes:
            self.register(cls)
        self._read_only = bool(read_only)

    def register(self, cls: type[Effect]) -> type[Effect]:
        """Add ``cls`` under its ``name`` (again for the same class is a no-op); returns ``cls``."""
        if self._read_only:
            raise TypeError("this effect registry is read-only; add effects to your own: "
                            "registry = REGISTRY.extended([MyEffect])")
        name = getattr(cls, "name", "")
        if not (isinstance(cls, type) and issubclass(cls, Effect)) or not isinstance(name, str) or not name:
            raise EffectConfigError(f"not an effect class with a name: {cls!r}")
        have = self._classes.get(name)
        if have is not None and have is not cls:
            raise EffectConfigError(f"effect name {name!r} is already registered ({have.__qualname__})")
        self._classes[name] = cls
        return cls

    def __getitem__(self, name: str) -> type[Effect]:
        return self._classes[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._classes)

    def __len__(self) -> int:
        return len(self._classes)

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self._classes)

    def make(self, name: str, **params: float) -> Effect:
        """One effect by canonical name; unknown names or parameters raise EffectConfigError."""
        try:
            cls = self._classes[name]
        except KeyError:
            raise EffectConfigError(f"unknown effect {name!r} (known: {', '.join(self._classes)})") from None
        return cls(**params)

    def extended(self, classes: Iterable[type[Effect]]) -> "EffectRegistry":
        """A new (writable) registry: these effects plus ``classes``."""
        return EffectRegistry((*self._classes.values(), *classes))

    def __repr__(self) -> str:
        return f"EffectRegistry({', '.join(self._classes)}{', read-only' if self._read_only else ''})"


REGISTRY = EffectRegistry(BUILTIN_EFFECTS, read_only=True)
"""The built-in effects (read-only; ``REGISTRY.extended([...])`` for more)."""


__all__ = ["BUILTIN_EFFECTS", "REGISTRY", "EffectRegistry"]
