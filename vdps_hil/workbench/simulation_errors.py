"""The input-driven simulation error of the model over fixed horizons (:func:`simulation_errors`).

Simulation error: the predictor (``prediction.predictor``),
input-driven by the recorded steering and wheel torques, started from the estimate every
``every_s`` seconds; its CG position, road-relative attitude and speed against the estimate at
0.5, 1 and 2 s after the start.

A prediction that *diverges* -- its state turns non-finite, it rolls past the predictor's roll
limit while the estimated car stays below ``ROLLED_RAD`` of roll, or its heading is more than
``LOST_YAW_DEG`` off the estimate's -- is not an error figure: it is counted
(``SimErrors.diverged_after_s``, ``summary()["n_diverged"]``) and said in words
(:meth:`SimErrors.notes`: "diverged at t = ... s"); a drive without the inputs the predictor is
driven by (steering, the four wheel torques) says which are missing instead of a number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import Vehicle
from vdps_hil.prediction.predictor import InputTrajectory, Predictor, PredictorConfig, PredictorInitialState

from .dataset import DriveTable
from .residuals import MIN_SPEED_MPS, finite_or_zero

__all__ = ["SimErrors", "simulation_errors", "HORIZONS_S"]

HORIZONS_S = (0.5, 1.0, 2.0)
LOST_YAW_DEG = 90.0
"""A prediction more than this off the estimated heading has lost the car: diverged."""
ROLLED_RAD = math.radians(30.0)
"""The predictor's roll limit counts as divergence while the estimated roll stays below this."""
_INPUTS = ("steer_wheel_angle_rad", *[f"wheel_torque_nm_{i}" for i in range(1, 5)])


@dataclass
class SimErrors:
    """Input-driven prediction errors against the estimate: per start (``t0_s``) and horizon
    (``HORIZONS_S``): ``position_m`` (CG position error), ``yaw_deg``, ``roll_deg``,
    ``speed_mps`` (each (n_starts, n_horizons), NaN where the prediction or the drive ended or
    the prediction diverged); ``diverged_after_s`` (n_starts,): time after its start at which a
    prediction diverged (module docstring), NaN when it did not; ``missing_inputs``: the input
    signals the drive lacks (no prediction runs without them)."""

    t0_s: np.ndarray
    horizons_s: tuple
    position_m: np.ndarray
    yaw_deg: np.ndarray
    roll_deg: np.ndarray
    speed_mps: np.ndarray
    diverged_after_s: np.ndarray | None = None
    missing_inputs: tuple = ()

    def summary(self, mask: np.ndarray | None = None) -> dict[str, dict[str, float]]:
        """RMS over the starts (optionally a subset) per horizon of the predictions that did not
        diverge: {"0.5": {position_m, yaw_deg, roll_deg, speed_mps, n, n_diverged}, ...}; an
        RMS over no prediction is NaN, ``n`` the predictions in it, ``n_diverged`` those that
        diverged before the horizon."""
        sel = np.ones(len(self.t0_s), bool) if mask is None else np.asarray(mask, bool)
        div = self.diverged_after_s if self.diverged_after_s is not None else np.full(len(self.t0_s), np.nan)
        out = {}
        for j, h in enumerate(self.horizons_s):
            d = {}
            for name in ("position_m", "yaw_deg", "roll_deg", "speed_mps"):
                a = getattr(self, name)[sel, j]
                a = a[np.isfinite(a)]
                d[name] = float(np.sqrt(np.mean(a * a))) if len(a) else math.nan
            d["n"] = int(np.isfinite(self.position_m[sel, j]).sum())
            d["n_diverged"] = int(np.sum(div[sel] <= h + 1e-9))
            out[f"{h:g}"] = d
        return out

    def notes(self) -> list[str]:
        """What the figures cannot say, in words: missing inputs, diverged predictions."""
        if self.missing_inputs:
            return ["simulation error not computed: the drive has no " + ", ".join(self.missing_inputs)
                    + " (the input-driven predictor needs the steering and the four wheel torques)"]
        div = self.diverged_after_s if self.diverged_after_s is not None else np.zeros(0)
        k = np.flatnonzero(np.isfinite(div))
        if not len(k):
            return []
        run = int(np.sum(np.isfinite(self.position_m[:, 0]) | np.isfinite(div)))
        first = k[0]
        return [f"the input-driven simulation diverged in {len(k)} of {run} predictions: first at t = "
                f"{self.t0_s[first] + div[first]:.2f} s of the drive ({div[first]:.2f} s after its start at "
                f"{self.t0_s[first]:.2f} s); those are left out of the error figures"]


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
    need = list(_INPUTS)
    missing = tuple(n for n in need if not table.has(n))
    div = np.full(len(starts), np.nan)
    if missing:
        return SimErrors(starts, tuple(horizons_s), **out, diverged_after_s=div, missing_inputs=missing)
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
        res, div[s_i] = _predict(cache[key], init, traj, horizons_s)
        if res is not None and not math.isfinite(div[s_i]):
            div[s_i] = _diverged_after(res, table, k0)
        for j, h in enumerate(horizons_s):
            kt = int(np.searchsorted(t, t[k0] + h - 1e-9))
            ip = int(round(h / step_s))
            if res is None or kt >= len(t) or ip >= len(res.t_s):
                continue
            pe = res.pos_g_m[ip]
            pt = np.array([c["pos_g_m_e"][kt], c["pos_g_m_n"][kt], c["pos_g_m_u"][kt]])
            out["position_m"][s_i, j] = float(np.linalg.norm(pe - pt))
            yaw_t = c["yaw_g_rad"][kt]
            out["yaw_deg"][s_i, j] = math.degrees(_wrap(res.euler_g_rad[ip, 2] - yaw_t))
            out["roll_deg"][s_i, j] = math.degrees(res.euler_g_rad[ip, 0] - c["roll_g_rad"][kt])
            out["speed_mps"][s_i, j] = float(np.linalg.norm(res.vel_b_mps[ip])) - float(speed[kt])
            if abs(out["yaw_deg"][s_i, j]) > LOST_YAW_DEG and not math.isfinite(div[s_i]):
                div[s_i] = h
        if math.isfinite(div[s_i]):
            for name in out:
                out[name][s_i, np.asarray(horizons_s) >= div[s_i] - 1e-9] = np.nan
    return SimErrors(starts, tuple(horizons_s), **out, diverged_after_s=div)


def _predict(pred: Predictor, init, traj, horizons_s) -> tuple[object, float]:
    """(prediction, NaN), or -- when the model's arithmetic overflows on the way (a diverging
    state: exp of a huge spring compression) -- (the longest prediction over the horizons that
    completes or None, the first horizon that does not)."""
    try:
        return pred.predict(init, traj), math.nan
    except ArithmeticError:
        pass
    res = None
    for h in sorted(horizons_s):
        try:
            res = Predictor(pred.vehicle, replace(pred.config, horizon_s=h), pred.effects).predict(init, traj)
        except ArithmeticError:
            return res, float(h)
    return res, math.nan


def _diverged_after(res, table: DriveTable, k0: int) -> float:
    """Time after the start at which a prediction stopped by diverging (module docstring), NaN
    when it did not."""
    t_end = float(res.t_s[-1]) if len(res.t_s) else 0.0
    if res.stop_reason == "non_finite":
        return t_end
    if res.stop_reason == "roll_limit":
        kt = min(int(np.searchsorted(table.t_s, table.t_s[k0] + t_end - 1e-9)), len(table.t_s) - 1)
        if abs(table.columns["roll_g_rad"][kt]) < ROLLED_RAD:
            return t_end
    return math.nan


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
