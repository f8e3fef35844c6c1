"""Prediction metrics, fixed here and used everywhere (tests, tools, ``vdps paper``, workbench).

Frame of the errors: the road frame relative to the (true) pose at t0
------------------------------------------------------------------------
Positions are compared in the aux frame of the true pose at t0 (paper section 2: the road
frame yawed by psi_v(t0), x along the vehicle's heading over the road, z along the road
normal), with the true position at t0 as origin::

    [x_a, y_a, z_a](t) = R(z, psi_v,true(t0)) C_g^r (p_g(t) - p_g,true(t0))        (eq 1-3)

Both trajectories go through the same transform, so the position error
``|p_pred(t) - p_true(t)|`` is the Euclidean error in metres and the per-axis errors are
along-track (x_a), cross-track (y_a) and normal to the road (z_a). Attitude is compared as
the road-relative angles psi_v, theta_v, phi_v (eq 3-4), in degrees; yaw differences are
wrapped to [-180, 180).

Figures (all over the common time span of the two trajectories, samples at equal times)
---------------------------------------------------------------------------------------
* ``position_err_m``, ``yaw_err_deg``, ``pitch_err_deg``, ``roll_err_deg``: at the last
  common sample (the horizon's end); angle errors signed (pred - true).
* ``position_rms_m``, ``yaw_rms_deg``, ``pitch_rms_deg``, ``roll_rms_deg``: RMS over the span.
* **Inaccuracy (paper-style, section 7.3)**: for each channel c of
  (x_a, y_a, z_a, psi_v, theta_v, phi_v)::

      I_c = RMS_t(c_pred - c_true) / max(range_t(c_true - c_true(t0)), floor_c)

  with floor 1 m for positions and 1 deg for angles (a channel that hardly moves is not
  divided by ~0); ``inaccuracy_pct`` = 100 mean_c I_c. The paper reports 0.51 % (left turn,
  Fig 8, 10.25-15 s) and 27.3 % (rollover, Fig 9, 10.25-11.5 s); it does not print its formula
  beyond "relative inaccuracy ... averaged from vehicle displacements (xa, ya, za) and vehicle
  attitude (psi_v, theta_v, phi_v)", so this normalisation is ours (stated in every report).

Symbols: p_g position ENU [m]; C_g^r road rotation (eq 2); psi_v, theta_v, phi_v road-relative
yaw, pitch (nose up +), roll (right side down +) [rad, reported in deg].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from vdps_hil.model.frames import dcm_global_to_road, rot_z

PAPER_INACCURACY_PCT: dict[str, float] = {"left_turn": 0.51, "rollover": 27.3}
"""The paper's published prediction inaccuracies (section 7.3, Figures 8 and 9) [%]."""
POSITION_FLOOR_M = 1.0
ANGLE_FLOOR_RAD = math.radians(1.0)
CHANNELS: tuple[str, ...] = ("xa", "ya", "za", "psi_v", "theta_v", "phi_v")
"""The six channels of the paper-style inaccuracy."""


@dataclass(frozen=True)
class PoseTrajectory:
    """Sampled pose: times [s] (N,), CG position ENU (N, 3) [m], road-relative angles
    (phi_v, theta_v, psi_v) (N, 3) [rad], and the road plane (bank, grade) [rad]."""

    t_s: np.ndarray
    pos_g_m: np.ndarray
    euler_v_rad: np.ndarray
    road_bank_rad: float = 0.0
    road_grade_rad: float = 0.0

    def __post_init__(self):
        t = np.asarray(self.t_s, dtype=float).reshape(-1)
        p = np.asarray(self.pos_g_m, dtype=float)
        e = np.asarray(self.euler_v_rad, dtype=float)
        if p.shape != (t.size, 3) or e.shape != (t.size, 3) or t.size == 0:
            raise ValueError(f"PoseTrajectory: t_s (N,), pos_g_m and euler_v_rad (N, 3); got {t.shape}, "
                             f"{p.shape}, {e.shape}")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "pos_g_m", p)
        object.__setattr__(self, "euler_v_rad", e)

    @classmethod
    def from_prediction(cls, result) -> "PoseTrajectory":
        """From a :class:`~vdps_hil.prediction.result.PredictionResult`, absolute times [s]."""
        return cls(result.t0_ns * 1e-9 + result.t_s, result.pos_g_m, result.euler_v_rad,
                   result.road_bank_rad, result.road_grade_rad)

    @classmethod
    def from_snapshots(cls, snapshots: Sequence[Mapping], t_from_s: float = -math.inf,
                       t_to_s: float = math.inf) -> "PoseTrajectory":
        """From simulator snapshot dicts (``t_s``, ``pos_{e,n,u}_m``, ``roll/pitch/yaw_v_rad``,
        ``road_bank_rad``, ``road_grade_rad``) within [t_from_s, t_to_s] (1e-9 s tolerance).
        For tests, tools and the ``paper`` command (never the pipeline)."""
        sel = [s for s in snapshots if t_from_s - 1e-9 <= s["t_s"] <= t_to_s + 1e-9]
        if not sel:
            raise ValueError("no snapshot in the requested time span")
        return cls(np.array([s["t_s"] for s in sel]),
                   np.array([[s["pos_e_m"], s["pos_n_m"], s["pos_u_m"]] for s in sel]),
                   np.array([[s["roll_v_rad"], s["pitch_v_rad"], s["yaw_v_rad"]] for s in sel]),
                   float(sel[0]["road_bank_rad"]), float(sel[0]["road_grade_rad"]))

    def at(self, t_s: np.ndarray) -> "PoseTrajectory":
        """Linear interpolation at times ``t_s`` (inside the span; yaw unwrapped first)."""
        t = np.asarray(t_s, dtype=float).reshape(-1)
        e = self.euler_v_rad.copy()
        e[:, 2] = np.unwrap(e[:, 2])
        pos = np.stack([np.interp(t, self.t_s, self.pos_g_m[:, k]) for k in range(3)], axis=1)
        eul = np.stack([np.interp(t, self.t_s, e[:, k]) for k in range(3)], axis=1)
        return PoseTrajectory(t, pos, eul, self.road_bank_rad, self.road_grade_rad)


def _wrap_pi(a):
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def road_frame_channels(pos_g_m, euler_v_rad, origin_pos_g_m, origin_psi_v_rad: float,
                        road_bank_rad: float, road_grade_rad: float) -> dict[str, np.ndarray]:
    """The six channels: x_a, y_a, z_a [m] in the aux frame of the given origin pose, and
    psi_v (unwrapped), theta_v, phi_v [rad]."""
    p = np.asarray(pos_g_m, dtype=float)
    e = np.asarray(euler_v_rad, dtype=float)
    c = rot_z(origin_psi_v_rad) @ dcm_global_to_road(road_bank_rad, road_grade_rad)
    a = (p - np.asarray(origin_pos_g_m, dtype=float)) @ c.T
    return {"xa": a[:, 0], "ya": a[:, 1], "za": a[:, 2], "psi_v": np.unwrap(e[:, 2]),
            "theta_v": e[:, 1], "phi_v": e[:, 0]}


def prediction_metrics(pred_pos_g_m, pred_euler_v_rad, true_pos_g_m, true_euler_v_rad, *,
                       t_s=None, road_bank_rad: float = 0.0, road_grade_rad: float = 0.0,
                       position_floor_m: float = POSITION_FLOOR_M,
                       angle_floor_rad: float = ANGLE_FLOOR_RAD) -> dict:
    """Errors of a predicted trajectory against the true one, sampled at the same N times
    (row 0 = t0). Arrays: positions ENU (N, 3) [m], road-relative angles (phi_v, theta_v, psi_v)
    (N, 3) [rad]. Returns a dict (module docstring): ``span_s`` (when ``t_s`` is given),
    ``n_samples``, ``position_err_m``, ``position_rms_m``, ``along_err_m``, ``cross_err_m``,
    ``normal_err_m`` (x_a, y_a, z_a at the end), ``yaw_err_deg``, ``pitch_err_deg``,
    ``roll_err_deg`` (end, signed), ``yaw_rms_deg``, ``pitch_rms_deg``, ``roll_rms_deg``,
    ``inaccuracy_pct`` and ``inaccuracy_channels_pct`` {xa, ya, za, psi_v, theta_v, phi_v}."""
    pp = np.asarray(pred_pos_g_m, dtype=float)
    pe = np.asarray(pred_euler_v_rad, dtype=float)
    tp = np.asarray(true_pos_g_m, dtype=float)
    te = np.asarray(true_euler_v_rad, dtype=float)
    n = tp.shape[0]
    if n == 0 or pp.shape != (n, 3) or pe.shape != (n, 3) or tp.shape != (n, 3) or te.shape != (n, 3):
        raise ValueError("prediction_metrics: all four arrays must be (N, 3) with the same N >= 1")
    origin, psi0 = tp[0], float(te[0, 2])
    cp = road_frame_channels(pp, pe, origin, psi0, road_bank_rad, road_grade_rad)
    ct = road_frame_channels(tp, te, origin, psi0, road_bank_rad, road_grade_rad)
    d = {c: cp[c] - ct[c] for c in CHANNELS}
    d["psi_v"] = _wrap_pi(_wrap_pi(pe[:, 2]) - _wrap_pi(te[:, 2]))
    pos_err = np.sqrt(d["xa"] ** 2 + d["ya"] ** 2 + d["za"] ** 2)
    deg = 180.0 / math.pi
    out: dict = {"n_samples": int(n)}
    if t_s is not None:
        t = np.asarray(t_s, dtype=float).reshape(-1)
        out["span_s"] = float(t[-1] - t[0])
    rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
    out.update({
        "position_err_m": float(pos_err[-1]), "position_rms_m": rms(pos_err),
        "along_err_m": float(d["xa"][-1]), "cross_err_m": float(d["ya"][-1]), "normal_err_m": float(d["za"][-1]),
        "yaw_err_deg": float(d["psi_v"][-1] * deg), "pitch_err_deg": float(d["theta_v"][-1] * deg),
        "roll_err_deg": float(d["phi_v"][-1] * deg),
        "yaw_rms_deg": rms(d["psi_v"]) * deg, "pitch_rms_deg": rms(d["theta_v"]) * deg,
        "roll_rms_deg": rms(d["phi_v"]) * deg,
    })
    chans = {}
    for c in CHANNELS:
        rng = float(np.max(ct[c]) - np.min(ct[c]))
        floor = position_floor_m if c in ("xa", "ya", "za") else angle_floor_rad
        chans[c] = 100.0 * rms(d[c]) / max(rng, floor)
    out["inaccuracy_channels_pct"] = chans
    out["inaccuracy_pct"] = float(np.mean(list(chans.values())))
    return out


def compare_trajectories(pred: PoseTrajectory, true: PoseTrajectory, **kw) -> dict:
    """:func:`prediction_metrics` over the common span: the true trajectory is interpolated at
    the predicted sample times that lie inside it (both must start at the same t0 within 1 us).
    Adds ``t0_s`` and ``t_end_s``."""
    if abs(pred.t_s[0] - true.t_s[0]) > 1e-6:
        raise ValueError(f"trajectories start at different times ({pred.t_s[0]:.6f} s, {true.t_s[0]:.6f} s)")
    keep = pred.t_s <= true.t_s[-1] + 1e-9
    t = pred.t_s[keep]
    tr = true.at(t)
    out = prediction_metrics(pred.pos_g_m[keep], pred.euler_v_rad[keep], tr.pos_g_m, tr.euler_v_rad,
                             t_s=t, road_bank_rad=true.road_bank_rad, road_grade_rad=true.road_grade_rad, **kw)
    out["t0_s"] = float(t[0])
    out["t_end_s"] = float(t[-1])
    return out


def format_metrics(name: str, m: Mapping, paper_key: str | None = None) -> str:
    """A short text block: the end-of-horizon errors, RMS errors and the paper-style inaccuracy
    next to the paper's value (``paper_key``: "left_turn" or "rollover")."""
    lines = [f"{name}: span {m.get('span_s', float('nan')):.2f} s, {m['n_samples']} samples",
             f"  at the end  position {m['position_err_m']:.3f} m (along {m['along_err_m']:+.3f}, cross "
             f"{m['cross_err_m']:+.3f}, normal {m['normal_err_m']:+.3f})  yaw {m['yaw_err_deg']:+.3f} deg  "
             f"pitch {m['pitch_err_deg']:+.3f} deg  roll {m['roll_err_deg']:+.3f} deg",
             f"  RMS         position {m['position_rms_m']:.3f} m  yaw {m['yaw_rms_deg']:.3f} deg  "
             f"pitch {m['pitch_rms_deg']:.3f} deg  roll {m['roll_rms_deg']:.3f} deg"]
    ch = m["inaccuracy_channels_pct"]
    per = "  ".join(f"{c} {ch[c]:.2f}" for c in CHANNELS)
    paper = PAPER_INACCURACY_PCT.get(paper_key) if paper_key else None
    ref = f"   (paper: {paper:.2f} %)" if paper is not None else ""
    lines.append(f"  inaccuracy  {m['inaccuracy_pct']:.2f} %{ref}   per channel [%]: {per}")
    return "\n".join(lines)


def paper_comparison_row(name: str, m: Mapping, paper_key: str) -> tuple[str, float, float]:
    """(name, ours [%], paper [%]) for a table of paper-style inaccuracies."""
    return name, float(m["inaccuracy_pct"]), PAPER_INACCURACY_PCT[paper_key]


__all__ = ["ANGLE_FLOOR_RAD", "CHANNELS", "PAPER_INACCURACY_PCT", "POSITION_FLOOR_M", "PoseTrajectory",
           "compare_trajectories", "format_metrics", "paper_comparison_row", "prediction_metrics",
           "road_frame_channels"]
