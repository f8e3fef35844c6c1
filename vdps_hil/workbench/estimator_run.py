"""The estimator over a drive: a fresh :class:`~vdps_hil.estimation.pipeline.EstimatorPipeline`
(eq 7-12) fed the decoded samples exactly as it runs live, its estimate taken on a grid, its
innovations per measurement kind kept as packed arrays (:func:`run_estimator`).
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.pipeline import EstimatorPipeline, Innovation, PipelineConfig
from vdps_hil.model.params import Vehicle

from .streams import DatasetError

__all__ = ["EstimatorRun", "run_estimator", "InnovationLog", "innovation_tables"]


@dataclass
class EstimatorRun:
    """The estimator's outputs sampled for the table: per grid instant the estimate (its own
    t_ns, x, sigma) and every Innovation; ``origin`` is the ENU origin it chose; counters."""

    est_t_ns: np.ndarray
    est_x: np.ndarray
    est_sigma: np.ndarray
    innovations: "InnovationLog | list[Innovation]"
    origin: object
    counters: dict


def run_estimator(samples: Sequence[Sample], vehicle: Vehicle, config: PipelineConfig | None = None,
                  period_s: float = 0.01) -> EstimatorRun:
    """Feed the samples to a fresh :class:`EstimatorPipeline`; take its estimate each time the
    bus time crosses a multiple of ``period_s``."""
    p = EstimatorPipeline(vehicle, config)
    step = int(round(period_s * 1e9))
    nxt = None
    ts, xs, ss, innov = [], [], [], InnovationLog()
    for i, s in enumerate(samples):
        out = p.handle(s)
        if i % 4096 == 4095:
            p.clear_input_log()  # its replay log (input_log) would hold the whole drive (as system.replay_file)
        for o in out:
            if isinstance(o, Innovation):
                innov.add(o)
        t = s.t_ns
        if nxt is None:
            nxt = (t // step + 1) * step
        if t >= nxt:
            nxt = (t // step + 1) * step
            e = p.estimate()
            if e is not None and (not ts or e.t_ns > ts[-1]):
                ts.append(e.t_ns)
                xs.append(e.x)
                ss.append(e.sigma)
    if not ts:
        raise DatasetError("the estimator never initialised (no GNSS fix with a heading in the recording)")
    return EstimatorRun(np.array(ts, dtype=np.int64), np.array(xs), np.array(ss), innov, p.origin,
                        dict(p.counters))


class InnovationLog:
    """The estimator's innovations per measurement kind as packed arrays (an Innovation object
    per update would hold ~0.6 kB: 2000 updates per second of drive)."""

    def __init__(self):
        self._k: dict[str, dict[str, array]] = {}

    def add(self, o: Innovation) -> None:
        d = self._k.get(o.kind)
        if d is None:
            d = self._k[o.kind] = {"t": array("q"), "nis": array("d"), "dof": array("d"), "acc": array("b"),
                                   "n": array("l"), "inn": array("d"), "sig": array("d")}
        d["t"].append(o.t_ns)
        d["nis"].append(o.nis)
        d["dof"].append(o.dof)
        d["acc"].append(o.status == "accepted")
        d["n"].append(len(o.innovation))
        d["inn"].extend(o.innovation)
        m = len(o.innovation)
        sg = list(o.innovation_sigma)[:m]
        d["sig"].extend(sg + [math.nan] * (m - len(sg)))

    def __len__(self) -> int:
        return sum(len(d["t"]) for d in self._k.values())

    def tables(self, rel) -> dict[str, dict[str, np.ndarray]]:
        """As ``DriveTable.innovations``: per kind t_s, nis, dof, accepted, innovation / sigma
        (rows padded with NaN to the kind's widest update)."""
        out = {}
        for kind, d in self._k.items():
            n = np.frombuffer(d["n"], dtype=np.int_) if len(d["n"]) else np.zeros(0, int)
            w = int(n.max()) if len(n) else 0
            inn = np.full((len(n), w), np.nan)
            sg = np.full((len(n), w), np.nan)
            cols = np.arange(w)[None, :] < n[:, None]
            inn[cols] = np.frombuffer(d["inn"], dtype=float)
            sg[cols] = np.frombuffer(d["sig"], dtype=float)
            out[kind] = {"t_s": rel(np.frombuffer(d["t"], dtype=np.int64)), "nis": np.array(d["nis"], dtype=float),
                         "dof": np.array(d["dof"], dtype=float), "accepted": np.array(d["acc"], dtype=bool),
                         "innovation": inn, "sigma": sg}
        return out


def innovation_tables(innovations, rel) -> dict[str, dict[str, np.ndarray]]:
    if isinstance(innovations, InnovationLog):
        return innovations.tables(rel)
    by: dict[str, list[Innovation]] = {}
    for o in innovations:
        by.setdefault(o.kind, []).append(o)
    out = {}
    for kind, lst in by.items():
        n = max(len(o.innovation) for o in lst)
        inn = np.full((len(lst), n), np.nan)
        sg = np.full((len(lst), n), np.nan)
        for j, o in enumerate(lst):
            inn[j, :len(o.innovation)] = o.innovation
            sg[j, :len(o.innovation_sigma)] = o.innovation_sigma
        out[kind] = {"t_s": rel([o.t_ns for o in lst]), "nis": np.array([o.nis for o in lst], dtype=float),
                     "dof": np.array([o.dof for o in lst], dtype=float),
                     "accepted": np.array([o.status == "accepted" for o in lst]),
                     "innovation": inn, "sigma": sg}
    return out
