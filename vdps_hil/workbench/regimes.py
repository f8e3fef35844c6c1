"""Where the model fails: the worst time windows and the residuals over the operating regime.

Worst windows: each equation's residual divided by its noise sigma (``residuals``), squared and
summed over the equations (the noise-weighted misfit per row); its moving mean over
``window_s`` seconds; the ``n`` highest non-overlapping windows, each with the equation that
contributes most.

Regime bins: the RMS of each equation's residual in bins of one regime variable (equal-count
bins, so every bin has data)::

    speed_mps          |v|                               from the estimate
    ax_mps2, ay_mps2   specific force x, y               IMU at the CG
    slip_angle_front_deg, slip_angle_rear_deg   mean of the axle's slip angles (eq 15-16)
    slip_ratio_max     max_i |kappa_i|
    steer_deg          steering wheel angle
    roll_deg           road-relative roll phi_v (eq 4)
    susp_travel_mm     max_i |H_i|
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dataset import DriveTable
from .residuals import EQUATIONS, EquationResiduals

__all__ = ["Window", "worst_windows", "regime_variables", "RegimeBins", "regime_bins", "REGIME_LABELS"]

REGIME_LABELS = {"speed_mps": "speed [m/s]", "ax_mps2": "longitudinal acceleration [m/s^2]",
                 "ay_mps2": "lateral acceleration [m/s^2]", "slip_angle_front_deg": "front slip angle [deg]",
                 "slip_angle_rear_deg": "rear slip angle [deg]", "slip_ratio_max": "largest slip ratio [-]",
                 "steer_deg": "steering wheel angle [deg]", "roll_deg": "roll relative to the road [deg]",
                 "susp_travel_mm": "largest suspension travel [mm]"}


@dataclass(frozen=True)
class Window:
    """A time window with the largest noise-weighted misfit."""

    t_start_s: float
    t_end_s: float
    misfit: float
    equation: str

    def to_json(self) -> dict:
        return {"t_start_s": self.t_start_s, "t_end_s": self.t_end_s, "misfit": self.misfit,
                "equation": self.equation}


def _weighted(res: EquationResiduals) -> np.ndarray:
    sig = np.where(np.isfinite(res.sigma) & (res.sigma > 0), res.sigma, np.nan)
    w = (res.values / sig) ** 2
    w[:, ~res.available] = np.nan
    return w


def worst_windows(res: EquationResiduals, window_s: float = 1.0, n: int = 3) -> list[Window]:
    """The ``n`` non-overlapping windows of ``window_s`` with the largest mean weighted misfit."""
    t = res.t_s
    if len(t) < 3:
        return []
    w = _weighted(res)
    tot = np.nansum(w, axis=1)
    dt = float(np.median(np.diff(t)))
    k = max(1, int(round(window_s / dt)))
    if len(tot) < k:
        k = len(tot)
    kern = np.ones(k) / k
    mov = np.convolve(tot, kern, mode="valid")
    per_eq = np.array([np.convolve(np.nan_to_num(w[:, j]), kern, mode="valid") for j in range(w.shape[1])])
    out: list[Window] = []
    used = np.zeros(len(mov), bool)
    order = np.argsort(-mov)
    for i in order:
        if used[i]:
            continue
        eq = EQUATIONS[int(np.argmax(per_eq[:, i]))]
        out.append(Window(float(t[i]), float(t[min(i + k - 1, len(t) - 1)]), float(mov[i]), eq))
        used[max(0, i - k + 1):i + k] = True
        if len(out) >= n:
            break
    return out


def regime_variables(table: DriveTable, res: EquationResiduals) -> dict[str, np.ndarray]:
    """The regime variables (module docstring) on the residual rows."""
    c = table.columns
    idx = res.index
    q = res.quantities
    out = {"speed_mps": np.hypot(c["vel_g_mps_e"], c["vel_g_mps_n"])[idx],
           "ax_mps2": c["specific_force_b_mps2_x"][idx], "ay_mps2": c["specific_force_b_mps2_y"][idx],
           "steer_deg": np.degrees(c["steer_wheel_angle_rad"][idx])}
    if q:
        out["slip_angle_front_deg"] = np.degrees([0.5 * (r["slip_angle_rad_1"] + r["slip_angle_rad_2"]) for r in q])
        out["slip_angle_rear_deg"] = np.degrees([0.5 * (r["slip_angle_rad_3"] + r["slip_angle_rad_4"]) for r in q])
        out["slip_ratio_max"] = np.array([max(abs(r[f"slip_ratio_{i}"]) for i in range(1, 5)) for r in q])
    from vdps_hil.model.frames import decompose_vehicle_batch

    eul = np.column_stack([c["roll_g_rad"], c["pitch_g_rad"], c["yaw_g_rad"]])[idx]
    bank = np.nan_to_num(c["road_bank_rad"][idx])
    grade = np.nan_to_num(c["road_grade_rad"][idx])
    if len(eul):
        # eq 4 row by row (the road angles vary slowly along the drive)
        roll = np.array([decompose_vehicle_batch(e[None], b, g)[0, 0] for e, b, g in zip(eul, bank, grade)])
        out["roll_deg"] = np.degrees(roll)
    h = np.column_stack([c[f"susp_deflection_m_{i}"] for i in range(1, 5)])[idx]
    if np.isfinite(h).any():
        out["susp_travel_mm"] = 1e3 * np.nanmax(np.abs(h), axis=1)
    return out


@dataclass
class RegimeBins:
    """RMS residual per equation (columns, ``EQUATIONS`` order) in bins (rows) of one variable."""

    variable: str
    edges: np.ndarray
    centres: np.ndarray
    counts: np.ndarray
    rms: np.ndarray

    def to_json(self) -> dict:
        return {"variable": self.variable, "edges": self.edges.tolist(), "centres": self.centres.tolist(),
                "counts": self.counts.tolist(),
                "rms": {e: [None if not math.isfinite(v) else float(v) for v in self.rms[:, k]]
                        for k, e in enumerate(EQUATIONS)}}


def regime_bins(table: DriveTable, res: EquationResiduals, n_bins: int = 6) -> dict[str, RegimeBins]:
    """Residual RMS per equation binned over every regime variable (equal-count bins)."""
    out = {}
    for name, v in regime_variables(table, res).items():
        ok = np.isfinite(v)
        if ok.sum() < 2 * n_bins or np.nanmax(v) - np.nanmin(v) <= 0:
            continue
        qs = np.quantile(v[ok], np.linspace(0.0, 1.0, n_bins + 1))
        qs = np.unique(qs)
        if len(qs) < 3:
            continue
        which = np.clip(np.searchsorted(qs, v, side="right") - 1, 0, len(qs) - 2)
        nb = len(qs) - 1
        rms = np.full((nb, len(EQUATIONS)), np.nan)
        counts = np.zeros(nb, int)
        for b in range(nb):
            sel = ok & (which == b)
            counts[b] = int(sel.sum())
            if counts[b]:
                vals = res.values[sel]
                fin = np.isfinite(vals)
                n_fin = fin.sum(axis=0)  # an equation not evaluated (partial sensor set): NaN, no warning
                ss = np.where(fin, vals * vals, 0.0).sum(axis=0)
                rms[b] = np.where(n_fin > 0, np.sqrt(ss / np.maximum(n_fin, 1)), np.nan)
        out[name] = RegimeBins(name, qs, 0.5 * (qs[:-1] + qs[1:]), counts, rms)
    return out
