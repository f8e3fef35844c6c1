"""Rollover measures of one prediction (definitions of :mod:`vdps_hil.model.rollover`, applied to
the predicted trajectory; never redefined here) and the assessment the warning policy reads
(:mod:`vdps_hil.prediction.warning`, its module docstring: LTR, PLTR, TTR, TTT)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vdps_hil.units import NS_PER_S

from .result import PredictionResult

__all__ = ["RolloverAssessment", "load_transfer_ratio", "predictive_ltr", "roll_relative_to_road"]


def load_transfer_ratio(normal_load_n) -> np.ndarray:
    """LTR = (F_right - F_left) / (F_right + F_left) per sample of (N, 4) wheel loads (FL FR RR
    RL; right = 2, 3), 0 where the total is 0. Same sign as the simulator's ``ltr``."""
    fz = np.atleast_2d(np.asarray(normal_load_n, dtype=float))
    left = fz[:, 0] + fz[:, 3]
    right = fz[:, 1] + fz[:, 2]
    tot = left + right
    return np.divide(right - left, tot, out=np.zeros_like(tot), where=tot > 0)


def roll_relative_to_road(result: PredictionResult) -> np.ndarray:
    """phi_v(t) of the prediction [rad] (eq 4)."""
    return result.euler_v_rad[:, 0]


def predictive_ltr(result: PredictionResult) -> tuple[float, float]:
    """(PLTR, t*): the predicted LTR of largest magnitude (signed) and its time after t0 [s]."""
    ltr = load_transfer_ratio(result.normal_load_n)
    k = int(np.argmax(np.abs(ltr)))
    return float(ltr[k]), float(result.t_s[k])


@dataclass(frozen=True)
class RolloverAssessment:
    """What the policy needs from one prediction (times after t0 [s]; None = not predicted)."""

    t0_ns: int
    time_to_point_of_no_return_s: float | None
    time_to_tip_up_s: float | None
    peak_ltr: float
    peak_ltr_t_s: float
    peak_roll_rad: float
    horizon_s: float
    stop_reason: str

    @classmethod
    def from_prediction(cls, result: PredictionResult) -> "RolloverAssessment":
        pltr, tpk = predictive_ltr(result)
        roll = roll_relative_to_road(result)
        k = int(np.argmax(np.abs(roll)))
        return cls(int(result.t0_ns), result.point_of_no_return_t_s, result.tip_up_t_s, pltr, tpk,
                   float(roll[k]), float(result.t_s[-1]), result.stop_reason)

    def ttr_at(self, t_ns: int) -> float | None:
        """Time from ``t_ns`` to the predicted point of no return [s] (>= 0), or None."""
        if self.time_to_point_of_no_return_s is None:
            return None
        return max(0.0, self.time_to_point_of_no_return_s - (t_ns - self.t0_ns) / NS_PER_S)

    def to_json(self) -> dict:
        return dict(self.__dict__)
