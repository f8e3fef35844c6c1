"""The predictor started from simulator truth (tests, benchmarks and studies only): a
:class:`~vdps_hil.prediction.initial_state.PredictorInitialState` read from a truth snapshot
instead of the estimator's outputs. The pipeline never calls this (it never sees truth).
"""

from __future__ import annotations

from typing import Any, Mapping

from vdps_hil.model.core import Inputs
from vdps_hil.prediction.initial_state import PredictorInitialState


def initial_state_from_truth(snapshot: Mapping[str, Any], *, with_suspension: bool = True) -> PredictorInitialState:
    """From a truth simulator snapshot (``Simulator.truth`` / ``snapshot()``). Drive torque =
    net wheel torque + brake torque (exact while the wheel rolls forward faster than 2 rad/s)."""
    s = snapshot
    susp = tuple(s[f"susp_deflection_m_{i}"] for i in range(1, 5)) if with_suspension else None
    srate = tuple(s[f"susp_deflection_rate_mps_{i}"] for i in range(1, 5)) if with_suspension else None
    brakes = tuple(float(s.get(f"brake_torque_nm_{i}", 0.0)) for i in range(1, 5))
    drive = tuple(float(s[f"wheel_torque_nm_{i}"]) + brakes[i - 1] for i in range(1, 5))
    return PredictorInitialState(
        t_ns=int(s["t_ns"]), pos_g_m=(s["pos_e_m"], s["pos_n_m"], s["pos_u_m"]),
        vel_g_mps=(s["vel_g_mps_e"], s["vel_g_mps_n"], s["vel_g_mps_u"]),
        euler_g_rad=(s["roll_g_rad"], s["pitch_g_rad"], s["yaw_g_rad"]),
        road_bank_rad=s["road_bank_rad"], road_grade_rad=s["road_grade_rad"],
        rate_b_radps=(s["rate_b_radps_x"], s["rate_b_radps_y"], s["rate_b_radps_z"]),
        wheel_speed_radps=tuple(s[f"wheel_speed_radps_{i}"] for i in range(1, 5)),
        susp_deflection_m=susp, susp_deflection_rate_mps=srate,
        inputs=Inputs(float(s["steer_wheel_angle_rad"]), drive, brakes))


__all__ = ["initial_state_from_truth"]
