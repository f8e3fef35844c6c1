"""The input-driven simulation error of the model over fixed horizons (:func:`simulation_errors`).

Simulation error: the predictor (``prediction.predictor``),
input-driven by the recorded steering and wheel torques, started from the estimate every
``every_s`` seconds; its CG position, road-relative attitude and speed against the estimate at
0.5, 1 and 2 s after the start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import Vehicle
from vdps_hil.prediction.predictor import InputTrajectory, Predictor, PredictorConfig, PredictorInitialState

from .dataset import DriveTable
from .residuals import MIN_SPEED_MPS, finite_or_zero

__all__ = ["SimErrors", "simulation_errors", "HORIZONS_S"]

HORIZONS_S = (0.5, 1.0, 2.0)


@dataclass
class SimErrors:
    """Input-driven prediction errors against the estimate: per start (``t0_s``) and horizon
    (``HORIZONS_S``): ``position_m`` (CG position error), ``yaw_deg``, ``roll_deg``,
    ``speed_mps`` (each (n_starts, n_horizons), NaN where the prediction or the drive ended)."""

    t0_s: np.ndarray
    horizons_s: tuple
    position_m: np.ndarray
    yaw_deg: np.ndarray
    roll_deg: np.ndarray
    speed_mps: np.ndarray

    def summary(self, mask: np.ndarray | None = None) -> dict[str, dict[str, float]]:
        """RMS over the starts (optionally a subset) per horizon: {"0.5": {...}, ...}."""
        sel = np.ones(len(self.t0_s), bool) if mask is None else np.asarray(mask, bool)
        out = {}
        for j, h in enumerate(self.horizons_s):
            d = {}
            for name in ("position_m", "yaw_deg", "roll_deg", "speed_mps"):
                a = getattr(self, name)[sel, j]
                a = a[np.isfinite(a)]
                d[name] = float(np.sqrt(np.mean(a * a))) if len(a) else math.nan
            out[f"{h:g}"] = d
        return out


def simulation_errors(table: DriveTable, vehicle: Vehicle, effects: EffectSet | Sequence = (), *,
                      every_s: float = 0.5, horizons_s: Sequence[float] = HORIZONS_S,
                      starts_s: Sequence[float] | None = None, step_s: float = 0.01,
                      vehicle_at=None, effects_at=None) -> SimErrors:
    """Input-driven predictions from the estimate (module docstring).

    ``vehicle_at(t0_s)`` / ``effects_at(t0_s)``: optional callables giving the model to use for
    a prediction starting at t0 (the workbench passes parameters fitted only on data before t0)."""
    effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
    c = table.columns
    hmax = max(horizons_s)
    t = table.t_s
    if starts_s is None:
        starts_s = np.arange(t[0], t[-1] - hmax + 1e-9, every_s)
    starts = np.asarray(starts_s, dtype=float)
    nh = len(horizons_s)
    out = {k: np.full((len(starts), nh), np.nan) for k in ("position_m", "yaw_deg", "roll_deg", "speed_mps")}
    cfg = PredictorConfig(horizon_s=hmax, step_s=step_s, stop_at_point_of_no_return=False)
    cache: dict = {}
    need = ["steer_wheel_angle_rad", *[f"wheel_torque_nm_{i}" for i in range(1, 5)]]
    speed = np.hypot(c["vel_g_mps_e"], c["vel_g_mps_n"])
    for s_i, t0 in enumerate(starts):
        k0 = int(np.searchsorted(t, t0 - 1e-9))
        if k0 >= len(t) or speed[k0] < MIN_SPEED_MPS:
            continue
        init = _initial_state(table, k0)
        if init is None:
            continue
        k1 = int(np.searchsorted(t, t[k0] + hmax + 1e-9))
        sl = slice(k0, min(k1 + 1, len(t)))
        inp = np.column_stack([c[n][sl] for n in need])
        if not np.all(np.isfinite(inp)):
            continue
        traj = InputTrajectory(t[sl] - t[k0], inp[:, 0], inp[:, 1:5])
        veh = vehicle_at(t[k0]) if vehicle_at else vehicle
        eff = effects_at(t[k0]) if effects_at else effects
        key = (id(veh), id(eff))
        if key not in cache:
            cache.clear()
            cache[key] = Predictor(veh, cfg, EffectSet(EffectSet(eff).dynamics))
        res = cache[key].predict(init, traj)
        for j, h in enumerate(horizons_s):
            kt = int(np.searchsorted(t, t[k0] + h - 1e-9))
            ip = int(round(h / step_s))
            if kt >= len(t) or ip >= len(res.t_s):
                continue
            pe = res.pos_g_m[ip]
            pt = np.array([c["pos_g_m_e"][kt], c["pos_g_m_n"][kt], c["pos_g_m_u"][kt]])
            out["position_m"][s_i, j] = float(np.linalg.norm(pe - pt))
            yaw_t = c["yaw_g_rad"][kt]
            out["yaw_deg"][s_i, j] = math.degrees(_wrap(res.euler_g_rad[ip, 2] - yaw_t))
            out["roll_deg"][s_i, j] = math.degrees(res.euler_g_rad[ip, 0] - c["roll_g_rad"][kt])
            out["speed_mps"][s_i, j] = float(np.linalg.norm(res.vel_b_mps[ip])) - float(speed[kt])
    return SimErrors(starts, tuple(horizons_s), **out)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _initial_state(table: DriveTable, k: int) -> PredictorInitialState | None:
    c = table.columns
    try:
        susp = tuple(c[f"susp_deflection_m_{i}"][k] for i in range(1, 5))
        rate = tuple(c[f"susp_deflection_rate_mps_{i}"][k] for i in range(1, 5))
        if not all(math.isfinite(v) for v in susp):
            susp = rate = None
        elif not all(math.isfinite(v) for v in rate):
            rate = None
        return PredictorInitialState(
            t_ns=table.t0_ns + int(round(table.t_s[k] * 1e9)),
            pos_g_m=(c["pos_g_m_e"][k], c["pos_g_m_n"][k], c["pos_g_m_u"][k]),
            vel_g_mps=(c["vel_g_mps_e"][k], c["vel_g_mps_n"][k], c["vel_g_mps_u"][k]),
            euler_g_rad=(c["roll_g_rad"][k], c["pitch_g_rad"][k], c["yaw_g_rad"][k]),
            road_bank_rad=finite_or_zero(c["road_bank_rad"][k]), road_grade_rad=finite_or_zero(c["road_grade_rad"][k]),
            rate_b_radps=tuple(c[f"rate_b_radps_{a}"][k] for a in "xyz"),
            wheel_speed_radps=tuple(c[f"wheel_speed_radps_{i}"][k] for i in range(1, 5)),
            susp_deflection_m=susp, susp_deflection_rate_mps=rate)
    except ValueError:
        return None
