"""The row budget of the workbench's fits (:func:`fit_subset`): a drive longer than
``max_fit_s`` is identified and ranked on evenly spread segments of it, not on every row.

Why: the ranking's design carries the slow body-velocity nuisance as hat functions every
``nuisance_knot_s`` (2 s), so its column count p grows with the drive, and the per (micro block,
row group) statistics of the blocked cross-validation hold (blocks x groups x p) values and
solve p x p systems: memory grows with the square of the drive's length and time with its cube
(a 5-minute drive: 1 GiB, 155 CPU s; an hour would need tens of GiB). The statistics do not need
every row of an hour: the identification and the held-out explained fractions are taken on a
fixed amount of drive.

Rule (deterministic, no randomness): when the table spans more than ``max_fit_s`` seconds, take
n = floor(``max_fit_s`` / ``segment_s``) segments of ``segment_s`` seconds whose starts are spread
evenly from the first row to ``segment_s`` before the last, and join them end to end into one
table: each segment's times are shifted so it follows the previous one, and one empty row (every
signal NaN) sits between two segments, so nothing that needs contiguous rows (the innovations'
open-loop strapdown takes the longest contiguous run: one segment) runs across a junction. The
GNSS and estimator-innovation records inside a segment follow it with the same shift. Everything
row-wise (the residuals, the regimes, the worst windows, the simulation error) still runs on the
whole drive at the identified model; the cleaned residual and its RMS (``before``) are the
segments' (the design's rows). A drive of at most ``max_fit_s`` is used whole: its results are
unchanged.

``--add`` (:func:`add_window`): its before/after refits the model on every block before each
prediction start, which the joined segments cannot carry (a prediction must not run across a
junction); on a drive longer than ``max_fit_s`` it is fitted and measured on the drive's middle
``max_fit_s`` seconds, one contiguous window, and says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dataset import DriveTable

__all__ = ["AddWindow", "FitSubset", "add_window", "fit_subset"]


@dataclass
class FitSubset:
    """The segments a long drive is fitted on: the joined table, its rows' indices in the whole
    drive's table (-1 for the empty separator rows), the segments' spans [s] in the drive's time,
    the drive's duration [s] and its table's times [s]."""

    table: DriveTable
    rows: np.ndarray
    segments_s: list[tuple[float, float]]
    drive_s: float
    table_t_s: np.ndarray  # the whole drive's t_s

    @property
    def fitted_s(self) -> float:
        return float(sum(b - a for a, b in self.segments_s))

    def drive_times(self, rows: np.ndarray) -> np.ndarray:
        """The drive's times [s] of rows of the joined table (their times in the whole drive)."""
        return self.table_t_s[self.rows[np.asarray(rows, dtype=int)]]

    def message(self) -> str:
        return (f"row budget: the drive spans {self.drive_s / 60:.1f} min; the parameters and the ranking are "
                f"fitted on {len(self.segments_s)} evenly spread segments of {self.segments_s[0][1] - self.segments_s[0][0]:.0f} s "
                f"({self.fitted_s:.0f} s; starts "
                + ", ".join(f"{a:.0f}" for a, _ in self.segments_s) + " s), the residual traces on the whole drive")

    def to_json(self) -> dict:
        return {"drive_s": self.drive_s, "fitted_s": self.fitted_s, "n_segments": len(self.segments_s),
                "segments_s": [[a, b] for a, b in self.segments_s], "rows": int(np.sum(self.rows >= 0))}


def fit_subset(table: DriveTable, max_fit_s: float, segment_s: float) -> FitSubset | None:
    """The segments to fit on (module docstring), or None when the drive is used whole."""
    t = table.t_s
    if not len(t) or table.duration_s <= max_fit_s or not (segment_s > 0) or not math.isfinite(max_fit_s):
        return None
    n = max(1, int(max_fit_s // segment_s))
    starts = np.linspace(float(t[0]), float(t[-1]) - segment_s, n)
    period = table.period_s
    pieces, times, spans, shifts = [], [], [], []
    t_next = float(t[0])
    for s0 in starts:
        idx = np.flatnonzero((t >= s0) & (t < s0 + segment_s))
        if not len(idx):
            continue
        if pieces:
            pieces.append(np.array([-1]))  # the empty separator row
            times.append(np.array([times[-1][-1] + period]))
            t_next += period
        sh = t_next - float(t[idx[0]])
        pieces.append(idx)
        times.append(t[idx] + sh)
        shifts.append((float(t[idx[0]]), float(t[idx[-1]]), sh))
        spans.append((float(t[idx[0]]), float(t[idx[-1]]) + period))
        t_next += float(t[idx[-1]] - t[idx[0]]) + period
    rows = np.concatenate(pieces)
    new_t = np.concatenate(times)
    sep = rows < 0
    src = np.where(sep, 0, rows)

    def take(v: np.ndarray) -> np.ndarray:
        if v.dtype.kind != "f":
            return v[src]
        out = v[src].astype(float, copy=True)
        out[sep] = np.nan
        return out

    def records(d: dict) -> dict:
        out = {}
        for kind, tab in d.items():
            ts = tab["t_s"]
            sel_all, shift_all = [], []
            for a, b, sh in shifts:
                sel = np.flatnonzero((ts >= a) & (ts <= b))
                sel_all.append(sel)
                shift_all.append(np.full(len(sel), sh))
            sel = np.concatenate(sel_all) if sel_all else np.zeros(0, int)
            sh = np.concatenate(shift_all) if shift_all else np.zeros(0)
            out[kind] = {name: (a[sel] + sh if name == "t_s" else a[sel]) for name, a in tab.items()}
        return out

    sub = DriveTable(table.t0_ns, new_t, {k: take(v) for k, v in table.columns.items()},
                     {k: take(v) for k, v in table.sigma.items()}, records(table.gnss), records(table.innovations),
                     dict(table.rates_hz), table.vehicle, dict(table.counters), table.rls, dict(table.sensors))
    return FitSubset(sub, rows, spans, table.duration_s, t)


@dataclass
class AddWindow:
    """The contiguous span ``--add`` is fitted and measured on (module docstring), in the
    recording's time [ns], so a re-estimated table (another grid origin) is cut at the same
    instants."""

    start_ns: int
    end_ns: int
    drive_s: float
    offset_s: float  # the window's start in the drive's table time

    def cut(self, table: DriveTable) -> DriveTable:
        t_ns = table.t0_ns + np.round(table.t_s * 1e9).astype(np.int64)
        return table.slice((t_ns >= self.start_ns) & (t_ns <= self.end_ns))

    def message(self) -> str:
        span = (self.end_ns - self.start_ns) * 1e-9
        return (f"row budget: --add is fitted and its before/after measured on the drive's middle {span:.0f} s "
                f"({self.offset_s:.0f}-{self.offset_s + span:.0f} s of {self.drive_s / 60:.1f} min)")


def add_window(table: DriveTable, max_fit_s: float) -> AddWindow | None:
    """The middle ``max_fit_s`` seconds of a longer drive, or None when it is used whole."""
    t = table.t_s
    if not len(t) or table.duration_s <= max_fit_s or not math.isfinite(max_fit_s):
        return None
    a = 0.5 * (float(t[0]) + float(t[-1]) - max_fit_s)
    start_ns = table.t0_ns + int(round(a * 1e9))
    return AddWindow(start_ns, start_ns + int(round(max_fit_s * 1e9)), table.duration_s, a)
