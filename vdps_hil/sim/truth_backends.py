"""Truth backends of ``vdps sim``: which physics produces the motion the sensor models measure.

==================  ==========================================================================
spec                backend
==================  ==========================================================================
``ours`` (default)  ``sim.simulator.Simulator``: this project's physics core with its effects
``commonroad-mb:N`` ``sim.truth_cr.CommonRoadBackend``: CommonRoad's multibody model with its
                    parameter set N (1 or 3; the package's other multibody set is reserved as
                    an acceptance check and refused)
==================  ==========================================================================

A spec is ``NAME`` or ``NAME:ARG``. ``BACKENDS`` maps a name to ``"module:Class"``, imported
only when asked for (the CommonRoad package is not imported by a drive on our own truth). A
backend class takes ``(arg, **options)`` and offers ``vehicle`` (its truth Vehicle), ``spec``,
``prepare(scenario, effects) -> (effects, notes)`` (one-line errors for what it cannot drive),
``simulator(scenario, effects, **kw)`` (an object with ``Simulator``'s interface) and
``describe(sim)`` (for the ``truth.drive`` metadata).
"""

from __future__ import annotations

import importlib

__all__ = ["BACKENDS", "OURS", "TruthBackendError", "parse_truth_spec", "truth_backend"]

OURS = "ours"
BACKENDS: dict[str, str] = {"commonroad-mb": "vdps_hil.sim.truth_cr:CommonRoadBackend"}
"""Backend name -> ``module:Class`` (``OURS`` is the built-in ``Simulator``)."""


class TruthBackendError(ValueError):
    """An unknown or malformed truth spec (one-line message)."""


def parse_truth_spec(spec: str) -> tuple[str, str]:
    """``NAME`` or ``NAME:ARG`` -> (name, arg)."""
    name, _, arg = str(spec).strip().partition(":")
    name = name.strip()
    if name != OURS and name not in BACKENDS:
        raise TruthBackendError(f"unknown truth {spec!r} (known: {', '.join([OURS, *BACKENDS])}; "
                                f"e.g. commonroad-mb:1)")
    if name == OURS and arg:
        raise TruthBackendError(f"truth {OURS!r} takes no argument, got {spec!r}")
    return name, arg.strip()


def truth_backend(spec: str | None, **options):
    """The backend object of a spec, or None for our own simulator (``None`` or ``"ours"``).
    ``options`` go to the backend (e.g. ``flat_road``)."""
    if spec is None:
        return None
    name, arg = parse_truth_spec(spec)
    if name == OURS:
        return None
    module, _, cls = BACKENDS[name].partition(":")
    return getattr(importlib.import_module(module), cls)(arg, **options)
