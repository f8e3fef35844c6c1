"""Order of the selected effects: by what each explains that the others cannot (its unique
contribution in the final model), not by the round of the forward selection it entered in.

Forward selection is greedy: in its first round every candidate is judged against the base
model alone, so when a drive misses two effects whose residuals overlap, the first pick can be
the one that best absorbs part of the *other* effect's residual. Measured on the shipped ISO 3888
lane change (Magic Formula truth tire, a 10 m/s crosswind hidden, seed 1001): in round 1 tire
saturation explained 0.419 of the held-out residual, the crosswind 0.411; with the saturation in
the model the crosswind then explained 0.86 of what was left. Which effect is missing *most* is a
property of the final model, where both are present::

    U_e = 1 - SSE_cv,E(S) / SSE_cv,E(S \\ e)

S = the selected effects at the final linearisation point (their parameters as fitted), S \\ e
the same point with e taken out (its change columns and its effect removed; the ten parameters
and the nuisance re-fitted linearly, as for every held-out figure). E = the rows where e's kind
of effect shows, the evidence path of the selection (``selection._evidence``): for a sensor
effect the GNSS/IMU innovations, for every other effect the 14 equations of eq 13. Summed over
all rows, a sensor error's figure is drowned by the balance rows, whose whitened misfit (the
reduced model's own shortcomings, several noise sigmas) is many times the innovations'
(shipped lane change, 0.05 m/s^2 / 0.1 deg/s IMU bias hidden, seed 1002: the bias explains 0.43
of the held-out innovations and 0.015 of all rows, the truth's tire saturation 0.23 of all rows).

The selected effects are ordered by U_e, largest first; the first is the recommendation. With
one selected effect nothing changes. No threshold is involved: the set of selected effects is
the forward selection's, only their order is decided here.

Sensor effects come first, among themselves by U_e. Every residual the workbench judges the
model on is computed from the sensors' readings, so an error of the sensors (a lever arm, a bias)
is what an engineer corrects before trusting any comparison of the model with the drive; and its
U_e is a share of the innovations while a dynamics effect's is a share of the force balance, two
figures on different rows that say nothing about which is larger. Measured on CommonRoad set 1
and 3 lane changes with a 0.5 m IMU lever arm injected (tuning seeds 100-101): the lever arm and
an anti-roll stiffness were both selected, the anti-roll stiffness first by U_e (0.11-0.16 of the
balance rows against the lever arm's -0.04 to -0.14 of the innovations in the joint design,
where its own innovation fit takes 37 % off the velocity innovations).
"""

from __future__ import annotations

import os
from typing import Collection, Mapping

import numpy as np

from vdps_hil.model.effects import EffectSet

from ..candidate_base import Candidate
from .config import GROUP_NAMES, INNOVATION_GROUPS
from .identification import Point, build_design

__all__ = ["unique_contributions", "order_selected"]


def unique_contributions(table, states, inn, reference, point: Point, cfg, selected: Mapping[str, Candidate],
                         cv_all) -> dict[str, float]:
    """U_e of every selected effect (module docstring); ``cv_all``: held-out SSE per row group of
    the final model (all of ``selected`` at ``point``). Empty with fewer than two selected."""
    if len(selected) < 2:
        return {}
    innovation = np.isin(np.arange(len(GROUP_NAMES)), [GROUP_NAMES.index(g) for g in INNOVATION_GROUPS])
    out: dict[str, float] = {}
    for name, c in selected.items():
        rows = innovation if c.family == "measurement" else ~innovation  # E, the evidence rows
        rest = {n: other for n, other in selected.items() if n != name}
        effects = EffectSet([e for e in point.effects if e.name != name])
        phis = {n: p for n, p in point.phis.items() if n != name}
        _, d, always = build_design(table, states, inn, reference, Point(point.base, effects, phis), cfg, rest)
        without = float(d.cv(always)[rows].sum())
        out[name] = 1.0 - float(cv_all[rows].sum()) / without if without > 0.0 else 0.0
    if os.environ.get("VDPS_WB_DEBUG"):
        print(f"[ranking] unique contributions {out}")
    return out


def order_selected(selected_order: list[str], unique: Mapping[str, float],
                   sensors: Collection[str] = ()) -> list[str]:
    """The selected effects, those named in ``sensors`` first, each part by decreasing unique
    contribution (ties and effects without a figure keep their selection order)."""
    return sorted(selected_order, key=lambda n: (n not in sensors, -unique.get(n, float("-inf")),
                                                 selected_order.index(n)))
