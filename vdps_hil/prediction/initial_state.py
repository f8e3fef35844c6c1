"""What a prediction starts from: the estimated state at t0 and the last inputs before it
(:class:`PredictorInitialState`, built from the estimator's outputs), and what drives it over the
horizon when the inputs are not held (:class:`InputTrajectory` or any ``u(t_rel_s) -> Inputs``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from vdps_hil.model.core import Inputs


def _vec(v, n: int, name: str) -> tuple[float, ...]:
    t = tuple(float(e) for e in v)
    if len(t) != n:
        raise ValueError(f"PredictorInitialState.{name} needs {n} values, got {len(t)}")
    return t


@dataclass(frozen=True)
class PredictorInitialState:
    """The estimated state at t0 the prediction starts from (all SI; frames in
    :mod:`vdps_hil.conventions`), plus the last inputs before t0 (held-input mode).

    ``susp_deflection_m`` / ``susp_deflection_rate_mps`` may be None (no suspension sensors):
    then the attitude of the estimate and the design CG height are used."""

    t_ns: int
    pos_g_m: tuple[float, float, float]  # sprung CG, ENU [m]
    vel_g_mps: tuple[float, float, float]  # CG velocity, ENU [m/s]
    euler_g_rad: tuple[float, float, float]  # phi_g, theta_g, psi_g (eq 1) [rad]
    road_bank_rad: float  # phi_r [rad]
    road_grade_rad: float  # theta_r [rad]
    rate_b_radps: tuple[float, float, float]  # body rates p, q, r [rad/s]
    wheel_speed_radps: tuple[float, float, float, float]  # omega_1..4 [rad/s]
    susp_deflection_m: tuple[float, float, float, float] | None = None  # H_1..4 [m]
    susp_deflection_rate_mps: tuple[float, float, float, float] | None = None  # H_dot_1..4 [m/s]
    inputs: Inputs = field(default_factory=Inputs)  # last steering / torques before t0

    def __post_init__(self):
        object.__setattr__(self, "t_ns", int(self.t_ns))
        for name, n in (("pos_g_m", 3), ("vel_g_mps", 3), ("euler_g_rad", 3), ("rate_b_radps", 3),
                        ("wheel_speed_radps", 4)):
            object.__setattr__(self, name, _vec(getattr(self, name), n, name))
        for name in ("susp_deflection_m", "susp_deflection_rate_mps"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, _vec(v, 4, name))
        object.__setattr__(self, "road_bank_rad", float(self.road_bank_rad))
        object.__setattr__(self, "road_grade_rad", float(self.road_grade_rad))
        if not isinstance(self.inputs, Inputs):
            raise ValueError("PredictorInitialState.inputs must be an Inputs")
        core = (*self.pos_g_m, *self.vel_g_mps, *self.euler_g_rad, self.road_bank_rad,
                self.road_grade_rad, *self.rate_b_radps, *self.wheel_speed_radps)
        if not all(math.isfinite(v) for v in core):
            raise ValueError("PredictorInitialState has a non-finite value")

    @property
    def has_suspension(self) -> bool:
        return (self.susp_deflection_m is not None
                and all(math.isfinite(v) for v in self.susp_deflection_m))

    @classmethod
    def from_estimator(cls, estimate, filtered, *, brake_torque_nm: Sequence[float] = (0.0,) * 4
                       ) -> "PredictorInitialState":
        """From the estimator pipeline's outputs (``EstimatorPipeline.estimate()`` and
        ``.filtered()``, :mod:`vdps_hil.estimation.pipeline`):

        =========================  ==========================================================
        here                       from
        =========================  ==========================================================
        t_ns                       ``estimate.t_ns``
        pos_g_m, vel_g_mps         ``estimate.x`` [x_g, y_g, z_g], [xdot_g, ydot_g, zdot_g]
        euler_g_rad                ``estimate.x`` [phi_g, theta_g, psi_g]
        road_bank/grade_rad        ``estimate.x`` [phi_r, theta_r]
        rate_b_radps               ``filtered.angular_rate_radps`` (alpha-beta, eq 12)
        wheel_speed_radps          ``filtered.wheel_speed_radps``
        susp_deflection(_rate)     ``filtered.susp_deflection_m`` / ``susp_rate_mps`` (None if NaN)
        inputs                     ``filtered.steer_wheel_angle_rad``, ``wheel_torque_nm``
                                   (the bus torque is the net wheel torque; brakes 0 unless
                                   given)
        =========================  ==========================================================

        Raises ValueError when a required value is missing (NaN): the caller sends the warning
        with status "sensor missing" then."""
        x = [float(v) for v in estimate.x]
        if len(x) < 11:
            raise ValueError("estimate.x must hold the 12 states of eq 7")
        susp = tuple(filtered.susp_deflection_m)
        srate = tuple(filtered.susp_rate_mps)
        if not all(math.isfinite(v) for v in susp):
            susp, srate = None, None
        elif not all(math.isfinite(v) for v in srate):
            srate = None
        steer = float(filtered.steer_wheel_angle_rad)
        torque = tuple(float(v) for v in filtered.wheel_torque_nm)
        if not math.isfinite(steer) or not all(math.isfinite(v) for v in torque):
            raise ValueError("steering or wheel torque missing: no held inputs")
        return cls(t_ns=int(estimate.t_ns), pos_g_m=tuple(x[0:3]), vel_g_mps=tuple(x[3:6]),
                   euler_g_rad=tuple(x[6:9]), road_bank_rad=x[9], road_grade_rad=x[10],
                   rate_b_radps=tuple(filtered.angular_rate_radps),
                   wheel_speed_radps=tuple(filtered.wheel_speed_radps),
                   susp_deflection_m=susp, susp_deflection_rate_mps=srate,
                   inputs=Inputs(steer, torque, tuple(brake_torque_nm)))


@dataclass(frozen=True)
class InputTrajectory:
    """Recorded inputs over the horizon: times relative to t0 [s] (non-decreasing), steering
    wheel angle [rad], drive torques (N, 4) [N m] and brake torques (N, 4) [N m, >= 0; default 0].
    Linear interpolation between samples, held beyond the ends."""

    t_s: np.ndarray
    steer_wheel_angle_rad: np.ndarray
    wheel_torque_nm: np.ndarray
    brake_torque_nm: np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.t_s, dtype=float)
        s = np.asarray(self.steer_wheel_angle_rad, dtype=float)
        w = np.asarray(self.wheel_torque_nm, dtype=float)
        b = np.zeros_like(w) if self.brake_torque_nm is None else np.asarray(self.brake_torque_nm, dtype=float)
        if t.ndim != 1 or t.size == 0 or s.shape != t.shape or w.shape != (t.size, 4) or b.shape != (t.size, 4):
            raise ValueError("InputTrajectory: t_s (N,), steer (N,), wheel/brake torques (N, 4)")
        if np.any(np.diff(t) < 0) or not (np.all(np.isfinite(t)) and np.all(np.isfinite(s))
                                          and np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise ValueError("InputTrajectory: times must not decrease and values must be finite")
        if np.any(b < 0):
            raise ValueError("InputTrajectory: brake torques are magnitudes >= 0")
        for k, v in (("t_s", t), ("steer_wheel_angle_rad", s), ("wheel_torque_nm", w), ("brake_torque_nm", b)):
            object.__setattr__(self, k, v)

    def at(self, t_rel_s: float) -> Inputs:
        t = self.t_s
        steer = float(np.interp(t_rel_s, t, self.steer_wheel_angle_rad))
        tq = tuple(float(np.interp(t_rel_s, t, self.wheel_torque_nm[:, k])) for k in range(4))
        br = tuple(float(np.interp(t_rel_s, t, self.brake_torque_nm[:, k])) for k in range(4))
        return Inputs(steer, tq, br)


InputSource = Callable[[float], Inputs]
"""``u(t_rel_s) -> Inputs``: inputs at a time after t0."""


__all__ = ["InputSource", "InputTrajectory", "PredictorInitialState"]
