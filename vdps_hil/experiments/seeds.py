"""Every tuning seed of the project in one table, and the held-out rule over all of them.

A seed on which a threshold was chosen (by a fit or by judgment) is declared once, beside the
threshold it chose (``TUNING_SEEDS`` in its module); this module only gathers them. No study
may use a seed of *any* tuning set: a drive that chose the workbench's thresholds is not
an independent check of the identifier either (the identification study's seeds were 102-111,
two of which, 102 and 103, had chosen the workbench's ranking thresholds on the same CommonRoad
circle-ramp drives; its seeds are 113-122 since 2026-12-06).

:func:`check_held_out` raises a one-line ``ValueError`` naming the overlap; the study tools call
it on the seeds they are given, ``tests/test_seeds.py`` on every study's seed set.

A tuning seed is, strictly, a drive: the scenario and the seed the threshold was chosen on
(``paper-left-turn`` 1, 2 and 200-209, CommonRoad seed 101 and the workbench's maneuvers 100-103,
``paper`` seed 0). The studies are held to the seed numbers (stricter); tests that drive other scenarios at
seeds 0-2 (the decoder's, the simulator's and the bench's tests; ``vdps paper``'s rollover and
false-alarm runs at its ``--seed0``) are other drives and are not checked. ``vdps sim``'s default
seed is 0, the IMU monitor's tuning drive when the scenario is ``paper``; no test asserts the
monitor's limits on it (the monitor's own tests use synthetic streams).
"""

from __future__ import annotations

from typing import Iterable

from vdps_hil.estimation.imu_monitor import TUNING_SEEDS as _IMU_MONITOR
from vdps_hil.experiments.ident_study import STUDY_SEEDS as _IDENT_STUDY
from vdps_hil.experiments.ident_study import TUNING_SEEDS as _IDENT
from vdps_hil.experiments.workbench_study import STUDY_SEEDS as _WORKBENCH_STUDY
from vdps_hil.experiments.workbench_study import TUNING_SEEDS as _WORKBENCH
from vdps_hil.prediction.warning import TUNING_SEEDS as _WARNING_HOLD

__all__ = ["TUNING", "STUDIES", "tuning_seeds", "check_held_out", "held_out_seeds", "refused_by_tool"]

TUNING: dict[str, tuple[int, ...]] = {
    "the IMU monitor's outage and spike limits (estimation.imu_monitor)": tuple(_IMU_MONITOR),
    "the identification thresholds (experiments.ident_study)": tuple(_IDENT),
    "the workbench's ranking thresholds (experiments.workbench_study)": tuple(_WORKBENCH),
    "the warning's convergence hold (prediction.warning)": tuple(_WARNING_HOLD),
}
"""What each tuning set chose -> its seeds (each declared in the module named)."""

STUDIES: dict[str, tuple[int, ...]] = {
    "identification study (tools/ident_study.py)": tuple(_IDENT_STUDY),
    "workbench study (tools/workbench_study.py, workbench_study_cr.py)": tuple(_WORKBENCH_STUDY),
}
"""The acceptance studies' default seeds."""


def tuning_seeds() -> frozenset[int]:
    """Every seed of every tuning set."""
    return frozenset(s for seeds in TUNING.values() for s in seeds)


def check_held_out(seeds: Iterable[int], what: str) -> None:
    """Raise ValueError (one line) when any of ``seeds`` (of ``what``: a study, a test) is a
    tuning seed, naming the seed and the threshold it chose."""
    for s in sorted(set(int(x) for x in seeds)):
        chose = [name for name, tuned in TUNING.items() if s in tuned]
        if chose:
            raise ValueError(f"{what}: seed {s} is a tuning seed of {chose[0]}: use a held-out seed")


def held_out_seeds(first: int, n: int) -> list[int]:
    """The first ``n`` seeds from ``first`` on that are no tuning seed (``vdps paper``'s
    identification drives: its default 1-20 held the two ``paper-left-turn`` drives the
    identification thresholds were chosen on, so it runs 3-22)."""
    out, s, tuned = [], int(first), tuning_seeds()
    while len(out) < n:
        if s not in tuned:
            out.append(s)
        s += 1
    return out


def refused_by_tool(seeds: Iterable[int], tool: str, tuning: bool) -> bool:
    """A study tool's guard: True (after one line on stderr) when ``seeds`` hold a tuning seed
    and the run was not declared a tuning run (``--tuning``)."""
    if tuning:
        return False
    try:
        check_held_out(seeds, tool)
    except ValueError as e:
        import sys

        print(f"{e} (or --tuning)", file=sys.stderr)
        return True
    return False
