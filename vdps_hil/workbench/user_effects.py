"""Your own effect: a few lines of Python that take part in the workbench like the built-in ones.

Loading user code is code execution, so it happens only from what the user names:

* ``--effect-file my_effect.py``: the file is imported as a module (``importlib``); every
  subclass of :class:`~vdps_hil.model.effects.DynamicsEffect` or
  :class:`~vdps_hil.model.effects.MeasurementEffect` it defines with a ``name`` becomes a
  candidate (or the module lists them in ``EFFECTS = [...]``);
* ``--effect-entry NAME``: the entry point ``NAME`` of the group ``vdps_hil.effects`` (an installed
  package declares ``[project.entry-points."vdps_hil.effects"] NAME = "pkg.module:MyEffect"``);
  only the named entries are loaded, never the whole group.

Recordings, model files and configs never load code (they can name an effect, not bring one).
A loaded class is checked against the built-in registry (``model.effects.registry``: a taken
name is refused); callers put the classes in a registry of their own with
``REGISTRY.extended(classes)``, never in the shared ``REGISTRY``.

A user effect needs a ``name``, ``PARAMS`` (``ParamSpec`` with unit, default and plausible
range), its hook (``body_wrench``, ``wheel_torque``, ... see ``model.effects.base``) and, if it is
linear in its parameters, ``regressors(q)``; without regressors the workbench differentiates the
residual numerically around the defaults. Example (a constant side force, e.g. a banked road the
estimator missed)::

    from vdps_hil.model.effects import DynamicsEffect, ParamSpec

    class SideForce(DynamicsEffect):
        \"\"\"``side_force`` -- F_y = side_force_n at the CG.\"\"\"
        name = "side_force"
        HOOKS = ("body_wrench",)
        PARAMS = (ParamSpec("side_force_n", "N", 200.0, "constant lateral force", -5000.0, 5000.0),)

        def body_wrench(self, vel_b, omega_b, air_b):
            return (0.0, self.side_force_n, 0.0, 0.0, 0.0, 0.0)

        def regressors(self, q):
            return {"lat": {"side_force_n": 1.0}}
"""

from __future__ import annotations

import importlib.util
import inspect
import sys
from pathlib import Path
from typing import Iterable, Sequence

from vdps_hil.model.effects import REGISTRY
from vdps_hil.model.effects.base import DynamicsEffect, Effect, EffectConfigError, MeasurementEffect, ParamSpec

__all__ = ["UserEffectError", "load_effect_file", "load_entry_point_effects", "check_effect_class",
           "ENTRY_POINT_GROUP"]

ENTRY_POINT_GROUP = "vdps_hil.effects"


class UserEffectError(ValueError):
    """A user effect that cannot be used (one-line message)."""


def check_effect_class(cls, origin: str) -> type[Effect]:
    """Accept a user effect class or raise UserEffectError (one line)."""
    if not (inspect.isclass(cls) and issubclass(cls, (DynamicsEffect, MeasurementEffect))):
        raise UserEffectError(f"{origin}: {cls!r} is not a DynamicsEffect or MeasurementEffect subclass")
    name = getattr(cls, "name", "")
    if not isinstance(name, str) or not name.isidentifier():
        raise UserEffectError(f"{origin}: effect class {cls.__name__} needs a name (an identifier)")
    try:
        REGISTRY.extended([cls])  # the door built-in effects go through: a taken name is refused
    except EffectConfigError:
        raise UserEffectError(f"{origin}: effect name {name!r} is a built-in effect; choose another name") from None
    if not all(isinstance(p, ParamSpec) for p in getattr(cls, "PARAMS", ())):
        raise UserEffectError(f"{origin}: {name}.PARAMS must be ParamSpec entries")
    try:
        cls()
    except Exception as e:  # noqa: BLE001 - a user's constructor
        raise UserEffectError(f"{origin}: {name}: cannot build it with its defaults: {e}") from None
    return cls


def load_effect_file(path: str | Path) -> list[type[Effect]]:
    """Import the named Python file and return the effect classes it defines (module docstring)."""
    p = Path(path)
    if not p.is_file():
        raise UserEffectError(f"--effect-file {path}: no such file")
    if p.suffix != ".py":
        raise UserEffectError(f"--effect-file {path}: expected a .py file")
    mod_name = f"vdps_user_effect_{abs(hash(str(p.resolve())))}"
    spec = importlib.util.spec_from_file_location(mod_name, p)
    if spec is None or spec.loader is None:
        raise UserEffectError(f"--effect-file {path}: cannot be imported")
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as e:  # noqa: BLE001 - the user's code
        sys.modules.pop(mod_name, None)
        raise UserEffectError(f"--effect-file {path}: {e.__class__.__name__}: {str(e).splitlines()[0] if str(e) else ''}"
                              ) from None
    listed = getattr(module, "EFFECTS", None)
    if listed is not None:
        classes = list(listed)
    else:
        classes = [obj for _, obj in inspect.getmembers(module, inspect.isclass)
                   if obj.__module__ == mod_name and issubclass(obj, (DynamicsEffect, MeasurementEffect))
                   and getattr(obj, "name", "")]
    if not classes:
        raise UserEffectError(f"--effect-file {path}: defines no effect class with a name")
    return [check_effect_class(c, f"--effect-file {path}") for c in classes]


def load_entry_point_effects(names: Sequence[str], group: str = ENTRY_POINT_GROUP,
                             entry_points: Iterable | None = None) -> list[type[Effect]]:
    """Load only the named entry points of ``group`` (module docstring)."""
    if entry_points is None:
        from importlib.metadata import entry_points as _eps

        entry_points = _eps(group=group)
    by_name = {ep.name: ep for ep in entry_points}
    out = []
    for n in names:
        if n not in by_name:
            known = ", ".join(sorted(by_name)) or "none installed"
            raise UserEffectError(f"--effect-entry {n}: no entry point {n!r} in group {group!r} ({known})")
        try:
            cls = by_name[n].load()
        except Exception as e:  # noqa: BLE001 - third-party code
            raise UserEffectError(f"--effect-entry {n}: {e.__class__.__name__}: {e}") from None
        out.append(check_effect_class(cls, f"--effect-entry {n}"))
    return out
