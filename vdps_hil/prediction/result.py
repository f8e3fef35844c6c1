"""One prediction's result (:class:`PredictionResult`): the predicted trajectory, wheel loads,
load transfer ratio and rollover events, built from an integration loop's output
(:func:`build_result`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vdps_hil.model.core import Env
from vdps_hil.model.frames import decompose_vehicle_batch
from vdps_hil.model.rollover import RolloverMonitor
from vdps_hil.units import NS_PER_S

from .initial_state import PredictorInitialState


@dataclass(frozen=True)
class PredictionResult:
    """One prediction. Arrays share the first axis (N output samples, ``t_s[0] = 0`` at t0).

    ``pos_g_m`` ENU (anchored on the estimate at t0), ``euler_g_rad`` (phi_g, theta_g, psi_g),
    ``euler_v_rad`` (phi_v, theta_v, psi_v relative to the road, eq 4), ``vel_b_mps``,
    ``rate_b_radps``, ``wheel_speed_radps``, ``normal_load_n`` (eq 14, per wheel), ``ltr``
    ((F_right - F_left) / sum, as the simulator's), ``roll_rate_v_radps`` (d phi_v / dt).
    Events (times after t0 [s], None when not predicted): ``tip_up_t_s`` (start of the 0.2 s
    interval), ``point_of_no_return_t_s`` (``model.rollover`` definitions on the predicted
    trajectory). ``stop_reason``: horizon, point_of_no_return, roll_limit, non_finite."""

    t0_ns: int
    t_s: np.ndarray
    pos_g_m: np.ndarray
    euler_g_rad: np.ndarray
    euler_v_rad: np.ndarray
    vel_b_mps: np.ndarray
    rate_b_radps: np.ndarray
    wheel_speed_radps: np.ndarray
    normal_load_n: np.ndarray
    ltr: np.ndarray
    roll_rate_v_radps: np.ndarray
    road_bank_rad: float
    road_grade_rad: float
    tip_up_t_s: float | None
    tip_up_side: str | None
    point_of_no_return_t_s: float | None
    point_of_no_return_side: str | None
    stop_reason: str
    input_mode: str
    n_steps: int
    n_f_evals: int

    @property
    def horizon_reached_s(self) -> float:
        return float(self.t_s[-1])

    @property
    def rollover_predicted(self) -> bool:
        return self.point_of_no_return_t_s is not None

    def t_abs_ns(self) -> np.ndarray:
        """Absolute sample times [ns]."""
        return self.t0_ns + np.rint(self.t_s * NS_PER_S).astype(np.int64)


def build_result(init: PredictorInitialState, xs, fzs, ts, env: Env, offset, monitor: RolloverMonitor, stop: str,
                 mode: str, n_steps: int, n_eval: int) -> PredictionResult:
    """The result of one integration loop: its kept states, wheel loads and times as arrays, the
    positions shifted by ``offset`` (ENU), the road-relative angles (eq 4), LTR and the rollover
    monitor's events."""
    X = np.asarray(xs, dtype=float)
    t = np.asarray(ts, dtype=float)
    fz = np.asarray(fzs, dtype=float)
    pos = X[:, 0:3] + offset
    eul = X[:, 3:6].copy()
    eul_v = decompose_vehicle_batch(eul, env.bank_rad, env.grade_rad)
    w = X[:, 9:12]
    tt = np.tan(eul_v[:, 1])
    roll_rate_v = w[:, 0] - tt * np.sin(eul_v[:, 0]) * w[:, 1] - tt * np.cos(eul_v[:, 0]) * w[:, 2]
    left = fz[:, 0] + fz[:, 3]
    right = fz[:, 1] + fz[:, 2]
    tot = left + right
    with np.errstate(invalid="ignore"):  # a diverged prediction's infinite loads (inf - inf): LTR left 0
        ltr = np.divide(right - left, tot, out=np.zeros_like(tot), where=tot > 0)
    tu, pn = monitor.tip_up, monitor.point_of_no_return
    return PredictionResult(
        t0_ns=init.t_ns, t_s=t, pos_g_m=pos, euler_g_rad=eul, euler_v_rad=eul_v,
        vel_b_mps=X[:, 6:9].copy(), rate_b_radps=w.copy(), wheel_speed_radps=X[:, 12:16].copy(),
        normal_load_n=fz, ltr=ltr, roll_rate_v_radps=roll_rate_v,
        road_bank_rad=env.bank_rad, road_grade_rad=env.grade_rad,
        tip_up_t_s=tu.t_s if tu else None, tip_up_side=tu.side if tu else None,
        point_of_no_return_t_s=pn.t_s if pn else None, point_of_no_return_side=pn.side if pn else None,
        stop_reason=stop, input_mode=mode, n_steps=n_steps, n_f_evals=n_eval)


__all__ = ["PredictionResult", "build_result"]
