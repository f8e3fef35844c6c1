"""The ranking's outcome: one :class:`RankEntry` per candidate effect or identified parameter, the
:class:`Ranking` around them, their JSON and their words.

JSON (``Ranking.to_json``): ``ranking`` (the entries: effect, kind, explained_fraction,
explained_by_equation, parameters {name: {value, sigma}}, plausible, excited, excitation_z,
group, selected, delta_bic, message, unique_fraction of a selected effect beside others), ``recommendation``, ``equivalent_to``, ``selected``,
``groups``, ``identified_parameters``, ``messages``, ``n_eff``; non-finite numbers as null.
The words (``message``, ``messages``) come from :mod:`~vdps_hil.workbench.words`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import Vehicle

from .context import Context
from .design import Design

__all__ = ["RankEntry", "Ranking", "json_number", "rk_message"]


@dataclass
class RankEntry:
    """One ranked candidate (an effect or an identified parameter)."""

    effect: str
    kind: str
    explained_fraction: float
    explained_by_equation: dict[str, float]
    parameters: dict[str, tuple[float, float]]
    plausible: bool
    excited: bool
    excitation_z: float
    group: list[str]
    selected: bool = False
    delta_bic: float = math.nan
    message: str = ""
    reference: dict[str, float] = field(default_factory=dict)
    explained_gain_by_equation: dict[str, float] = field(default_factory=dict)
    model_value: dict[str, float] = field(default_factory=dict)  # a parameter: the value the model uses
    plausible_range: dict[str, tuple[float, float]] = field(default_factory=dict)  # a parameter: its bounds
    unique_fraction: float = math.nan  # a selected effect beside others: U_e, its order (``ordering``)
    identifier: dict = field(default_factory=dict)  # a parameter: the identifier's verdict (``rls_check``)

    def to_json(self) -> dict:
        num = json_number
        return {"effect": self.effect, "kind": self.kind, "explained_fraction": num(self.explained_fraction),
                "explained_by_equation": {k: num(v) for k, v in self.explained_by_equation.items()},
                "parameters": {k: {"value": num(v), "sigma": num(s)} for k, (v, s) in self.parameters.items()},
                "plausible": bool(self.plausible), "excited": bool(self.excited),
                "excitation_z": num(self.excitation_z), "group": list(self.group), "selected": bool(self.selected),
                "delta_bic": num(self.delta_bic), "message": self.message,
                **({"unique_fraction": num(self.unique_fraction)} if math.isfinite(self.unique_fraction) else {}),
                **({"model_value": {k: num(v) for k, v in self.model_value.items()}} if self.model_value else {}),
                **({"plausible_range": {k: [num(a), num(b)] for k, (a, b) in self.plausible_range.items()}}
                   if self.plausible_range else {}),
                **({"identifier": {k: (num(v) if isinstance(v, float) else v) for k, v in self.identifier.items()}}
                   if self.identifier else {})}


def json_number(v):
    """A float for JSON, None for a missing or non-finite value."""
    return None if v is None or not math.isfinite(float(v)) else float(v)


@dataclass
class Ranking:
    """The outcome (``to_json`` has the issue's keys ``ranking``, ``recommendation``,
    ``equivalent_to``; ``before``/``after`` are added by the CLI)."""

    entries: list[RankEntry]
    parameters: list[RankEntry]
    recommendation: str | None
    equivalent_to: list[str]
    selected: list[str]
    groups: list[dict]
    messages: list[str]
    n_eff: float
    n_rows: int
    base_vehicle: Vehicle
    reference_vehicle: Vehicle
    effects: EffectSet
    context: Context = field(repr=False, default=None)  # set while the entries are described; None once
    design: Design = field(repr=False, default=None)    # ``rank`` returns (drive-sized: freed there)
    candidates: dict = field(repr=False, default_factory=dict)
    thetas: dict = field(repr=False, default_factory=dict)

    def entry(self, name: str) -> RankEntry | None:
        for e in self.entries + self.parameters:
            if e.effect == name:
                return e
        return None

    def to_json(self) -> dict:
        return {"ranking": [e.to_json() for e in self.entries],
                "recommendation": self.recommendation, "equivalent_to": list(self.equivalent_to),
                "selected": list(self.selected), "groups": self.groups,
                "identified_parameters": [e.to_json() for e in self.parameters],
                "messages": list(self.messages), "n_eff": self.n_eff}


def rk_message(rk: Ranking, e: RankEntry) -> str:
    from ..words import describe_entry

    return describe_entry(rk, e)
