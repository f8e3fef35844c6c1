"""GNSS-outage studies: outage windows, and the antenna's horizontal error at the end of each
outage for the pipeline (predicting through it) and for constant-velocity extrapolation of the
last reference epoch, summarised per outage length. The GNSS samples inside a window are
withheld with ``runs.gnss_denied``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vdps_hil.realdata.containers import Reference
from vdps_hil.realdata.reference import constant_velocity
from vdps_hil.realdata.runs import Track

__all__ = ["outage_windows", "OutageError", "outage_errors", "summarize_outages"]


def outage_windows(t_first_s: float, t_last_s: float, period_s: float, lengths_s: Sequence[float],
                   first_offset_s: float | None = None) -> list[tuple[float, float]]:
    """GNSS outages every ``period_s``: window k starts at t_first + first_offset + k period and
    lasts lengths[k mod len(lengths)] (a window must end before ``t_last``)."""
    off = period_s if first_offset_s is None else first_offset_s
    out = []
    k = 0
    while True:
        t0 = t_first_s + off + k * period_s
        t1 = t0 + lengths_s[k % len(lengths_s)]
        if t1 >= t_last_s:
            break
        out.append((t0, t1))
        k += 1
    return out


@dataclass(frozen=True)
class OutageError:
    """Horizontal error [m] at the end of one GNSS outage [t0, t1): ``filter_m`` (the pipeline's
    antenna position predicted through the outage), ``cv_m`` (constant-velocity extrapolation of
    the last reference epoch before t0), both against the reference at ``t_end_s`` (its last epoch
    before t1); ``speed_mps`` the reference speed at t0."""

    t0_s: float
    t1_s: float
    t_end_s: float
    filter_m: float
    cv_m: float
    speed_mps: float

    @property
    def length_s(self) -> float:
        return self.t1_s - self.t0_s


def outage_errors(track: Track, lever_arm_m, ref: Reference, windows: Sequence[tuple[float, float]]
                  ) -> list[OutageError]:
    """Errors at the end of each outage (``OutageError``). The track's newest estimate at or
    before the evaluation epoch is carried to it with its own velocity (estimates are decimated)."""
    pa, va = track.antenna(lever_arm_m)
    out = []
    for a, b in windows:
        k_end = int(np.searchsorted(ref.t_s, b)) - 1
        k_last = int(np.searchsorted(ref.t_s, a)) - 1
        if k_last < 0 or k_end <= k_last:
            continue
        te = float(ref.t_s[k_end])
        i = int(np.searchsorted(track.t_s, te, side="right")) - 1
        if i < 0:
            continue
        p_f = pa[i] + va[i] * (te - track.t_s[i])
        p_cv = constant_velocity(ref.pos_enu_m[k_last], ref.vel_enu_mps[k_last], float(ref.t_s[k_last]), [te])[0]
        out.append(OutageError(float(a), float(b), te, float(np.hypot(*(p_f[:2] - ref.pos_enu_m[k_end, :2]))),
                               float(np.hypot(*(p_cv[:2] - ref.pos_enu_m[k_end, :2]))),
                               float(ref.speed_mps[k_last])))
    return out


def summarize_outages(errors: Sequence[OutageError]) -> dict:
    """Per outage length: count, mean and max filter error, mean CV error, the reduction
    1 - mean(filter) / mean(CV) and the fraction of outages with filter <= CV / 2."""
    out = {}
    for length in sorted({round(e.length_s, 3) for e in errors}):
        es = [e for e in errors if round(e.length_s, 3) == length]
        f = np.array([e.filter_m for e in es])
        c = np.array([e.cv_m for e in es])
        out[f"{length:g}s"] = {"n": len(es), "filter_mean_m": float(f.mean()), "filter_max_m": float(f.max()),
                               "cv_mean_m": float(c.mean()), "reduction": float(1.0 - f.mean() / c.mean()),
                               "halved_fraction": float(np.mean(f <= 0.5 * c))}
    return out
