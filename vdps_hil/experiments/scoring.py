"""Scoring against the simulator's truth: what the experiments compare the chain's outputs with.

Everything here reads truth (``/truth/state`` snapshots, ``/truth/events``, a truth vehicle
file's parameters) and is called by the harnesses of this package, the HIL bench and the
tools, never by the chain (package docstring: the truth rule).

* ``truth_at(by_t, t_ns)``: the truth snapshot at an estimate's instant (exact on the 100 Hz
  grid, else linear between neighbours, angles along their wrapped difference).
* ``fusion_error`` / ``fusion_std``: Fig 4's estimate - truth of eq 7's 12 states and the
  road-relative roll/pitch of eq 4, and its standard deviation over a window.
* ``truth_params`` / ``relative_errors``: e = (identified - true) / true of the ten identified
  parameters against the truth vehicle file.
* ``truth_trajectory``: the truth pose trajectory from a prediction's t0 (``prediction.metrics``).
* ``evaluate_warning_frames``: the sent VDPS_Warning frames against the truth events.

Lead time (acceptance figures)
------------------------------
``lead_time_s = t_PONR,truth - t(first valid frame with level >= warning)``, and
``lead_to_tip_up_s`` likewise to the truth tip-up; ``lead_time_matched_side_s`` counts only frames
whose predicted peak roll has the sign of the truth rollover (a fishhook's first steer can make
the model predict a rollover to the other side first); :func:`evaluate_warning_frames` decodes the
sent frames with :class:`~vdps_hil.codecs.can_decode.VdpsCanDecoder` (CRC and counter checked) and
counts false alarms: warning episodes (maximal runs of valid frames with level >= warning) in a run
without a truth PONR, or ending more than ``false_alarm_window_s`` before it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import can
import numpy as np

from vdps_hil.codecs.can_dbc import WARNING
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.prediction.warning import WarningLevel
from vdps_hil.units import NS_PER_S

__all__ = ["TRUTH_GRID_NS", "FUSION_NAMES", "truth_at", "fusion_error", "fusion_std", "truth_params",
           "relative_errors", "truth_trajectory", "WarningOutcome", "evaluate_warning_frames"]


# ----------------------------------------------------------------------------- truth snapshots
TRUTH_GRID_NS = 10_000_000
_ANGLES = {"roll_g_rad", "pitch_g_rad", "yaw_g_rad", "roll_v_rad", "pitch_v_rad", "yaw_v_rad", "road_bank_rad",
           "road_grade_rad"}


def truth_at(by_t: Mapping[int, Mapping], t_ns: int, grid_ns: int = TRUTH_GRID_NS) -> dict | None:
    """The truth snapshot at ``t_ns``: exact on the 100 Hz grid, else linear between the two
    neighbouring snapshots (angles along their wrapped difference) with ``t_ns`` set; None
    outside. For scoring harnesses (``paper_chain``, tools/nees_study.py, tests) only: the chain
    never reads truth."""
    if t_ns in by_t:
        return by_t[t_ns]
    t0 = t_ns - t_ns % grid_ns
    a, b = by_t.get(t0), by_t.get(t0 + grid_ns)
    if a is None or b is None:
        return None
    w = (t_ns - t0) / grid_ns
    out = {}
    for k, va in a.items():
        vb = b.get(k)
        if isinstance(va, bool) or not isinstance(va, (int, float)) or not isinstance(vb, (int, float)):
            continue
        d = math.remainder(vb - va, 2 * math.pi) if k in _ANGLES else vb - va
        out[k] = va + w * d
    out["t_ns"] = t_ns
    return out


_FUSION_TRUTH = ("pos_e_m", "pos_n_m", "pos_u_m", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u", "roll_g_rad",
                 "pitch_g_rad", "yaw_g_rad", "road_bank_rad", "road_grade_rad", "yaw_v_rad")
FUSION_NAMES = ("x_g_m", "y_g_m", "z_g_m", "vx_g_mps", "vy_g_mps", "vz_g_mps", "phi_g_deg", "theta_g_deg",
                "psi_g_deg", "phi_r_deg", "theta_r_deg", "psi_v_deg", "phi_v_deg", "theta_v_deg")
"""Fig 4's states: eq 7 (ENU position, velocity, absolute attitude, road bank and grade, psi_v)
and the road-relative roll and pitch of eq 4."""


def fusion_error(est, tv) -> np.ndarray:
    e = np.array(est.x[:12], dtype=float) - np.array([tv[k] for k in _FUSION_TRUTH])
    for i in (8, 11):
        e[i] = math.remainder(e[i], 2 * math.pi)
    ev = np.array(est.vehicle_angles_rad[:2], dtype=float) - np.array([tv["roll_v_rad"], tv["pitch_v_rad"]])
    return np.concatenate([e, ev])


def fusion_std(rows) -> dict:
    std = np.std(np.array(rows), axis=0)
    return {n: float(math.degrees(v) if n.endswith("_deg") else v) for n, v in zip(FUSION_NAMES, std)}


# ----------------------------------------------------------------------------- parameters
def truth_params(model: str = "sedan-model") -> dict[str, float]:
    """The truth vehicle file's ten parameters (harness only: the scores' reference)."""
    from vdps_hil.model.params import load_vehicle

    truth = {"sedan-model": "sedan-truth", "suv-model": "suv-truth"}[model]
    return load_vehicle(truth, "truth").params.as_dict()


def relative_errors(params: Mapping[str, float], truth: Mapping[str, float]) -> dict[str, float]:
    """(identified - true) / true per parameter [-]."""
    return {k: (float(params[k]) - truth[k]) / truth[k] for k in truth}


# ----------------------------------------------------------------------------- trajectories
def truth_trajectory(truth: list, t0_s: float, t_end_s: float):
    """The truth pose trajectory from exactly ``t0_s`` (interpolated) to ``t_end_s``."""
    from vdps_hil.prediction.metrics import PoseTrajectory

    tr = PoseTrajectory.from_snapshots(truth, t0_s - 0.02, t_end_s)
    t = tr.t_s[tr.t_s > t0_s + 1e-9]
    return tr.at(np.concatenate([[t0_s], t]))


# ---------------------------------------------------------------------------------------------
# lead time and false alarms
# ---------------------------------------------------------------------------------------------
@dataclass
class WarningOutcome:
    """Result of :func:`evaluate_warning_frames` (times [s]; NaN when absent)."""

    first_warning_t_s: float
    first_imminent_t_s: float
    truth_point_of_no_return_t_s: float
    truth_tip_up_t_s: float
    lead_time_s: float
    lead_to_tip_up_s: float
    lead_time_matched_side_s: float
    warning_episodes: list[tuple[float, float]]
    false_alarms: int
    frames_accepted: int
    frames_rejected: int
    frames_invalid_status: int
    max_gap_s: float
    decoded: list[dict] = field(default_factory=list, repr=False)

    def to_json(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "decoded"}
        d["warning_episodes"] = [list(e) for e in self.warning_episodes]
        return d


def _event_time(events: Iterable[Mapping[str, Any]], kind: str) -> float:
    for e in events:
        if e.get("kind") == kind:
            return float(e["t_s"])
    return math.nan


def evaluate_warning_frames(frames: Sequence[can.Message], truth_events: Iterable[Mapping[str, Any]] = (),
                            level: int = WarningLevel.WARNING, false_alarm_window_s: float = 5.0
                            ) -> WarningOutcome:
    """Decode the sent VDPS_Warning frames (CRC and counter checked by the codec's decoder) and
    compare with the truth events (``Simulator.events``: dicts with ``kind`` "tip_up" /
    "point_of_no_return" and ``t_s``). Only frames with status 0 count as warnings."""
    dec = VdpsCanDecoder()
    rows = []
    for m in frames:
        for s in dec.decode_message(m):
            if s.kind != "warning":
                continue
            rows.append({"t_s": s.t_ns / NS_PER_S, "level": int(s.fields["warning_level"]),
                         "status": int(s.fields["warning_status"]), "valid": s.valid,
                         "ttr_s": s.fields["warning_time_to_rollover_s"],
                         "ltr": s.fields["warning_ltr"], "peak_roll_rad": s.fields["warning_peak_roll_rad"]})
    counts = dec.counters[WARNING]
    rejected = dec.total_rejected  # CRC, counter, range, DLC, unknown ID, malformed
    events = list(truth_events)
    t_pn = _event_time(events, "point_of_no_return")
    t_tu = _event_time(events, "tip_up")
    episodes: list[tuple[float, float]] = []
    start = None
    last_t = None
    for r in rows:
        on = r["valid"] and r["level"] >= level
        if on and start is None:
            start = r["t_s"]
        if not on and start is not None:
            episodes.append((start, last_t))
            start = None
        last_t = r["t_s"]
    if start is not None:
        episodes.append((start, last_t))
    first = episodes[0][0] if episodes else math.nan
    imm = next((r["t_s"] for r in rows if r["valid"] and r["level"] >= WarningLevel.IMMINENT), math.nan)
    false = 0
    for a, b in episodes:
        if math.isnan(t_pn) or b < t_pn - false_alarm_window_s:
            false += 1
    relevant = [a for a, b in episodes if not math.isnan(t_pn) and b >= t_pn - false_alarm_window_s]
    first_rel = relevant[0] if relevant else math.nan
    # the first warning frame whose predicted roll direction is the truth's (PONR side "left":
    # the left side lifts, roll > 0)
    side = next((e.get("side") for e in events if e.get("kind") == "point_of_no_return"), None)
    sign = 1.0 if side == "left" else -1.0
    matched = next((r["t_s"] for r in rows if r["valid"] and r["level"] >= level
                    and r["peak_roll_rad"] * sign > 0.0), math.nan)
    ts = [r["t_s"] for r in rows]
    gaps = np.diff(ts) if len(ts) > 1 else np.array([0.0])
    return WarningOutcome(
        first_warning_t_s=first, first_imminent_t_s=imm, truth_point_of_no_return_t_s=t_pn,
        truth_tip_up_t_s=t_tu, lead_time_s=t_pn - first_rel, lead_to_tip_up_s=t_tu - first_rel,
        lead_time_matched_side_s=t_pn - matched,
        warning_episodes=episodes, false_alarms=false, frames_accepted=int(counts["accepted"]),
        frames_rejected=int(rejected), frames_invalid_status=sum(1 for r in rows if not r["valid"]),
        max_gap_s=float(np.max(gaps)), decoded=rows)
