"""The pipeline on what a car actually has: converted files back into samples through the
project's own adapters (``load_samples``: the code path of ``vdps import``), GNSS-denied
filtering, one ``EstimatorPipeline`` run (``run_pipeline``) and its estimates as arrays
(``Track``; antenna position and velocity through the lever arm, package docstring).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.model.frames import dcm_gv
from vdps_hil.estimation.estimates import Estimate, Innovation
from vdps_hil.estimation.pipeline import EstimatorPipeline
from vdps_hil.estimation.pipeline_config import PipelineConfig
from vdps_hil.geodesy import EnuOrigin

__all__ = ["load_samples", "Track", "track_from_estimates", "RunResult", "gnss_denied", "run_pipeline", "series"]


# ------------------------------------------------------------------------------ samples
def load_samples(can=(), serial=(), *, signalmap=None, dbc: Mapping[str, str] | None = None
                 ) -> tuple[list[Sample], dict]:
    """Decode files the way ``vdps import`` does (``record.importer.build_adapters``: the same
    adapters and decoders) but keep the samples in memory. ``can``/``serial`` are
    ``importer.CanSource`` / ``SerialSource``. Returns (samples in time order, per-source
    status)."""
    from vdps_hil.adapters.base import EndOfInput
    from vdps_hil.bus.subscription import Subscription
    from vdps_hil.record.importer import build_adapters

    adapters, _ = build_adapters(list(can), list(serial), signalmap=signalmap, dbc=dict(dbc or {}))
    out: list[Sample] = []
    status = {}
    for a in adapters:
        a.open()
        sub = a.subscribe(Subscription(f"realdata-{a.name}", 1 << 30, raw=False))
        try:
            while True:
                try:
                    n = a.poll(0.0)
                except EndOfInput:
                    break
                out.extend(e for e in sub.drain() if isinstance(e, Sample))
                if n == 0 and not a.is_open:
                    break
            out.extend(e for e in sub.drain() if isinstance(e, Sample))
            status[a.name] = a.status()
        finally:
            a.close()
            a.unsubscribe(sub)
    out.sort(key=lambda s: s.t_ns)
    return out, status


# ------------------------------------------------------------------------------ pipeline runs
@dataclass(frozen=True)
class Track:
    """Estimates of a run as arrays: ``t_s`` (N,), ``x`` (N, 12) full states (``STATE_NAMES``),
    ``sigma`` (N, 12)."""

    t_s: np.ndarray
    x: np.ndarray
    sigma: np.ndarray

    @property
    def pos_m(self) -> np.ndarray:
        return self.x[:, 0:3]

    @property
    def vel_mps(self) -> np.ndarray:
        return self.x[:, 3:6]

    def antenna(self, lever_arm_m, omega_radps=None) -> tuple[np.ndarray, np.ndarray]:
        """(p_ant, v_ant) of a point at ``lever_arm_m`` (body axes) for every estimate:
        p + C^T l and v + C^T (w x l) (``omega_radps`` (N, 3) body rates, or zero)."""
        la = np.asarray(lever_arm_m, dtype=float)
        p = self.pos_m.copy()
        v = self.vel_mps.copy()
        for i in range(self.t_s.shape[0]):
            ct = dcm_gv(self.x[i, 6], self.x[i, 7], self.x[i, 8]).T
            p[i] += ct @ la
            if omega_radps is not None:
                v[i] += ct @ np.cross(omega_radps[i], la)
        return p, v

    def window(self, t0_s: float, t1_s: float) -> "Track":
        m = (self.t_s >= t0_s) & (self.t_s <= t1_s)
        return Track(self.t_s[m], self.x[m], self.sigma[m])


def track_from_estimates(estimates: Sequence[Estimate], t_offset_s: float = 0.0) -> Track:
    if not estimates:
        return Track(np.zeros(0), np.zeros((0, 12)), np.zeros((0, 12)))
    t = np.array([e.t_ns for e in estimates], dtype=float) / 1e9 + t_offset_s
    return Track(t, np.array([e.x for e in estimates]), np.array([e.sigma for e in estimates]))


@dataclass
class RunResult:
    """One pipeline run: the pipeline (counters, observability), its estimates as a ``Track``
    and the per-kind number of samples handed to it / withheld (GNSS-denied windows)."""

    pipeline: EstimatorPipeline
    track: Track
    handled: dict
    withheld: dict
    nis: dict = field(default_factory=dict)
    """kind -> {"accepted": n, "mean_nis_per_dof": mean(NIS / dof) of the accepted updates}."""


def gnss_denied(windows_s: Sequence[tuple[float, float]], latency_s: float = 0.0):
    """A predicate dropping GNSS samples (kinds ``gnss_*``) whose measurement time t - latency
    is inside a window [t0, t1) (seconds on the drive clock; ``latency_s`` the configured GNSS
    latency, so that no fix measured inside the window reaches the filter, and none measured
    outside is withheld)."""
    ws = sorted((float(a), float(b)) for a, b in windows_s)
    starts = [a for a, _ in ws]

    def drop(s: Sample) -> bool:
        if not s.kind.startswith("gnss"):
            return False
        t = s.t_ns / 1e9 - latency_s
        i = bisect.bisect_right(starts, t) - 1
        return i >= 0 and ws[i][0] <= t < ws[i][1]

    return drop


def run_pipeline(vehicle, config: PipelineConfig, samples: Iterable[Sample], *,
                 kind_map: Mapping[str, str] | None = None, drop=None, origin: EnuOrigin | None = None,
                 preprocess: Sequence = (), order_by_effective_time: bool = True) -> RunResult:
    """Feed ``samples`` to a fresh ``EstimatorPipeline`` and collect its estimates.

    ``kind_map`` renames recorded kinds to pipeline kinds (``esc_imu`` -> ``imu``); ``drop(s)``
    withholds samples (GNSS-denied windows, ``gnss_denied``); ``preprocess`` nodes
    (``process(sample) -> sample``, e.g. ``ZeroRateCalibration``) then see the delivered stream in
    order, before the pipeline. With
    ``order_by_effective_time`` the stream is ordered by t_ns minus the configured latency of
    its kind (a live node would hold samples for the longest latency to achieve the same);
    the pipeline itself subtracts the latency."""
    km = dict(kind_map or {})
    lat = config.latencies
    lat_ns = {"imu": int(round(lat.imu_s * 1e9)), "gnss": int(round(lat.gnss_s * 1e9)),
              "gnss_vel": int(round(lat.gnss_vel_effective_s * 1e9)),
              "suspension": int(round(lat.suspension_s * 1e9)), "wheel": int(round(lat.wheel_s * 1e9))}
    stream = []
    handled: dict[str, int] = {}
    withheld: dict[str, int] = {}
    for s in samples:
        k = km.get(s.kind, s.kind)
        if k != s.kind:
            s = dataclasses.replace(s, kind=k)
        if drop is not None and drop(s):
            withheld[k] = withheld.get(k, 0) + 1
            continue
        handled[k] = handled.get(k, 0) + 1
        stream.append(s)
    if order_by_effective_time and any(lat_ns.values()):
        def eff(s):
            g = s.kind if s.kind == "gnss_vel" else (
                "gnss" if s.kind.startswith("gnss") else ("wheel" if s.kind.startswith("wheel") else s.kind))
            return s.t_ns - lat_ns.get(g, 0)
        stream.sort(key=eff)
    for node in preprocess:
        stream = [node.process(s) for s in stream]
    p = EstimatorPipeline(vehicle, config, origin=origin)
    est = []
    nis: dict[str, list[float]] = {}
    for s in stream:
        for o in p.handle(s):
            if isinstance(o, Estimate):
                est.append(o)
            elif isinstance(o, Innovation) and o.status == "accepted" and o.dof:
                v = nis.setdefault(o.kind, [0, 0.0])
                v[0] += 1
                v[1] += o.nis / o.dof
    summary = {k: {"accepted": n, "mean_nis_per_dof": tot / n} for k, (n, tot) in nis.items()}
    return RunResult(p, track_from_estimates(est), handled, withheld, summary)



def series(samples: Iterable[Sample], kind: str, fields: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(t_s (N,), values (N, len(fields))) of the valid samples of one kind (NaN where a field
    is absent)."""
    t, v = [], []
    for s in samples:
        if s.kind == kind and s.valid:
            t.append(s.t_ns / 1e9)
            v.append([s.fields.get(f, math.nan) for f in fields])
    return np.array(t), np.array(v, dtype=float).reshape(len(t), len(fields))
