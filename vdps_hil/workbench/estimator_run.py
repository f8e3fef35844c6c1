"""The estimator and the identifier over a drive, exactly as ``vdps replay`` runs them: the
Figure 2 node (``pipeline.node.VdpsSystem``: suspension conditioning, the estimator of eq 7-12,
the identifier's RLS of eq 19-23; no predictor) configured by the replay's own rule
(``pipeline.configure``: sensor set named or inferred, suspension averaging from the measured
rate), fed the decoded samples in time order (kinds renamed by the sensor set's kind map,
through its calibration nodes). Its estimate is taken on a grid, its innovations per
measurement kind kept as packed arrays, and the identifier's last report kept when the config
runs it (``SystemConfig.identify``; the workbench's ``DatasetConfig.identify``, off by default:
the estimator does not read it) (:func:`run_system`).
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field
from typing import Iterable, Iterator, Sequence

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.estimates import Estimate
from vdps_hil.estimation.pipeline import Innovation
from vdps_hil.estimation.sensorsets import KindMap
from vdps_hil.model.params import Vehicle
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem

from .streams import DatasetError

__all__ = ["EstimatorRun", "RlsResult", "run_system", "renamed", "InnovationLog", "innovation_tables"]


@dataclass
class RlsResult:
    """The identifier's outcome on the drive (``vdps replay``'s RLS): parameters, sigmas,
    converged flags per problem (mass, tracking, cornering, inertia), whether each problem was
    excited, rows used per problem."""

    params: dict[str, float]
    sigmas: dict[str, float]
    converged: dict[str, bool]
    excited: dict[str, bool] = field(default_factory=dict)
    rows_used: dict[str, int] = field(default_factory=dict)
    status: dict[str, str] = field(default_factory=dict)  # per parameter (``identification.status``)

    def to_json(self) -> dict:
        fin = (lambda v: float(v) if v is not None and math.isfinite(v) else None)  # noqa: E731
        return {"params": {k: fin(v) for k, v in self.params.items()},
                "sigmas": {k: fin(v) for k, v in self.sigmas.items()},
                "converged": dict(self.converged), "excited": dict(self.excited), "rows_used": dict(self.rows_used),
                "status": dict(self.status)}


@dataclass
class EstimatorRun:
    """The estimator's outputs sampled for the table: per grid instant the estimate (its own
    t_ns, x, sigma) and every Innovation; ``origin`` is the ENU origin it chose; counters; the
    identifier's outcome (``rls``, None without identification)."""

    est_t_ns: np.ndarray
    est_x: np.ndarray
    est_sigma: np.ndarray
    innovations: "InnovationLog | list[Innovation]"
    origin: object
    counters: dict
    rls: RlsResult | None = None
    gyro_bias_radps: tuple = (0.0, 0.0, 0.0)
    """The estimator's final gyro bias b_g per body axis (``MultiRateEKF.bias``; zero where its
    configuration carries no bias state, as the paper's Table 1 set)."""


def renamed(samples: Iterable[Sample], kind_map: KindMap, nodes: Sequence = ()) -> Iterator[Sample]:
    """The samples through a sensor set's :class:`KindMap` (kinds renamed, e.g. the RAV4's
    ``esc_imu`` -> ``imu``; a sensor the set does not name left out and counted in its
    ``dropped``), then its calibration nodes (as ``vdps replay`` feeds them)."""
    km = kind_map if kind_map else None  # asked once, not per sample
    for s in samples:
        if km is not None:
            s = km(s)
            if s is None:
                continue
        for node in nodes:
            s = node.process(s)
        yield s


def run_system(samples: Iterable[Sample], vehicle: Vehicle, config: SystemConfig, period_s: float = 0.01
               ) -> EstimatorRun:
    """Feed the samples to a fresh :class:`VdpsSystem` (no predictor); take its estimate each
    time the filter time crosses a multiple of ``period_s``; keep its innovations and the
    identifier's last report (module docstring)."""
    p = VdpsSystem(vehicle, config)
    step = int(round(period_s * 1e9))
    nxt = None
    ts, xs, ss, innov = array("q"), array("d"), array("d"), InnovationLog()  # packed: no array object per estimate

    def take(out):
        nonlocal nxt
        for o in out:
            if isinstance(o, Innovation):
                innov.add(o)
            elif isinstance(o, Estimate):
                if nxt is None or o.t_ns >= nxt:
                    nxt = (o.t_ns // step + 1) * step
                    if not ts or o.t_ns > ts[-1]:
                        ts.append(o.t_ns)
                        xs.frombytes(np.ascontiguousarray(o.x, dtype=float).tobytes())
                        ss.frombytes(np.ascontiguousarray(o.sigma, dtype=float).tobytes())

    for i, s in enumerate(samples):
        take(p.handle(s))
        if i % 4096 == 4095:
            p.clear_input_log()  # its replay log would hold the whole drive (as replay_file)
    take(p.finish())
    if not ts:
        raise DatasetError("the estimator never initialised (no GNSS fix with a heading in the recording)")
    rls = _rls_result(p)
    n = len(ts)
    return EstimatorRun(np.frombuffer(ts, dtype=np.int64).copy(), np.frombuffer(xs, dtype=float).reshape(n, -1).copy(),
                        np.frombuffer(ss, dtype=float).reshape(n, -1).copy(), innov, p.pipeline.origin,
                        dict(p.pipeline.counters), rls, p.pipeline.ekf.bias()[0])


def _rls_result(system: VdpsSystem) -> RlsResult | None:
    idf = system.identifier
    if idf is None:
        return None
    st = idf.status()
    per_param = {p: str(v.get("status", "")) for prob in st.get("status", {}).values()
                 for p, v in prob.get("params", {}).items()}
    return RlsResult(dict(idf.params.as_dict()), dict(idf.sigmas), dict(idf.converged),
                     {k: bool(v) for k, v in st.get("excited", {}).items()},
                     {k: int(c.get("rows_used", 0)) for k, c in st.get("counters", {}).items()}, per_param)


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
