"""Benchmark of the workbench's ranking on its residual path: every row's eq 13 residuals in one
compiled call (``workbench.row_kernel``) against the per-row reference (``RowModel.residual``,
the path a model without a compiled core takes), side by side in one process.

For each case (a drive simulated once into ``--cache``, then ``load_drive`` with the model file)
it alternates, ``--rounds`` times, the two paths and prints the CPU time (``time.process_time``)
of

* one ``compute_residuals`` with the nuisance columns and the named quantities read (what a
  ranking's design with candidates needs), median over ``--repeat``;
* the whole ``rank`` (the ranking with its base fit, screening and selection),

and whether both paths gave the same residuals (bit for bit) and the same ranking
(recommendation, groups, every entry's parameters). The per-row side is made by letting
``RowModel.packed`` report no compiled core, which is how a model with a user's effect runs.

Usage::

    .venv/bin/python tools/bench_rank.py [--cache DIR] [--rounds 2] [--repeat 3] [--cases ours cr1]

Cases: ``ours`` (our simulator, an under-inflated tire hidden on its study maneuver,
``experiments.workbench_study.HIDDEN``, seed 21, ``sedan-model``) and
``cr1`` (CommonRoad set 1's circle ramped to 7.5 m/s^2, ``shipped:cr-circle-ramp``, seed 21,
``cr1-model``: an anti-roll bar, the Magic Formula candidate's Newton on every row).

Measured (2026-12-06, this machine quiet, ``--rounds 2 --repeat 3``): see the README, "The
workbench's residuals compiled".
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.experiments.workbench_study import HIDDEN, cached_drive, model_file  # noqa: E402
from vdps_hil.model.effects import EffectSet, make_effect  # noqa: E402
from vdps_hil.model.params import load_vehicle  # noqa: E402
from vdps_hil.workbench import row_model  # noqa: E402
from vdps_hil.workbench.dataset import load_drive  # noqa: E402
from vdps_hil.workbench.ranking.selection import rank  # noqa: E402
from vdps_hil.workbench.residuals import compute_residuals, row_states  # noqa: E402

CASES = {
    "ours": (HIDDEN["low_pressure_tire"][0], [HIDDEN["low_pressure_tire"][1]], None),
    "cr1": ("shipped:cr-circle-ramp", [], "commonroad-mb:1"),
}


class _PerRow:
    """While active, ``RowModel.packed`` reports no compiled core (the per-row reference runs)."""

    def __enter__(self):
        self._packed = row_model.RowModel.packed
        row_model.RowModel.packed = lambda self: None

    def __exit__(self, *exc):
        row_model.RowModel.packed = self._packed


def _residuals(tab, veh, st, per_row: bool):
    effects = EffectSet([make_effect("magic_formula_tire")])
    t = time.process_time()
    with (_PerRow() if per_row else nullcontext()):
        res = compute_residuals(tab, veh, effects, states=st)
        n = len(res.quantities)  # read: the quantities are made on first use
    return time.process_time() - t, res, n


def _rank(tab, veh, per_row: bool):
    t = time.process_time()
    with (_PerRow() if per_row else nullcontext()):
        rk = rank(tab, veh)
    summary = (rk.recommendation, [tuple(g["members"]) for g in rk.groups],
               {e.effect: e.parameters for e in rk.entries}, list(rk.messages))
    return time.process_time() - t, summary


def _same(a, b) -> bool:
    return all(np.array_equal(x, y, equal_nan=True) for x, y in
               ((a.values, b.values), (a.nuisance, b.nuisance), (a.ws_parts, b.ws_parts))) and \
        list(a.quantities) == list(b.quantities)


def run_case(name: str, cache: str, rounds: int, repeat: int) -> None:
    man, specs, truth = CASES[name]
    veh = load_vehicle(model_file(truth))
    tab = load_drive(cached_drive(cache, man, specs, 21, truth=truth), veh)
    st = row_states(tab, veh)
    print(f"{name}: {len(st.index)} usable rows of {len(tab)}")
    same_res = same_rank = True
    for r in range(rounds):
        times = {True: [], False: []}
        for _ in range(repeat):
            for per_row in (True, False):
                dt, res, _ = _residuals(tab, veh, st, per_row)
                times[per_row].append(dt)
                if per_row:
                    ref = res
                else:
                    same_res &= _same(ref, res)
        t_row, rk_row = _rank(tab, veh, True)
        t_comp, rk_comp = _rank(tab, veh, False)
        same_rank &= rk_row == rk_comp
        a, b = statistics.median(times[True]), statistics.median(times[False])
        print(f"  round {r + 1}: compute_residuals per-row {a * 1e3:.0f} ms, compiled {b * 1e3:.0f} ms "
              f"({a / b:.1f}x); rank per-row {t_row:.2f} s, compiled {t_comp:.2f} s ({t_row / t_comp:.2f}x)")
    print(f"  residuals identical: {same_res}; ranking identical: {same_rank} (recommendation {rk_comp[0]})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", default=None, help="directory of the simulated drives (default: a temporary one)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    a = ap.parse_args(argv)
    if a.rounds < 1 or a.repeat < 1:
        ap.error("--rounds and --repeat must be >= 1")
    with tempfile.TemporaryDirectory() as td:
        for name in a.cases:
            run_case(name, a.cache or td, a.rounds, a.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
