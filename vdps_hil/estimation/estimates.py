"""What the estimator pipeline node emits (``pipeline.EstimatorPipeline``): ``Estimate`` (the 12
states of eq 7 with 1-sigma and the road-relative vehicle angles of eq 4), ``Innovation`` (one
EKF update) and ``FilteredSignals`` (the alpha-beta outputs of eq 12 and the pass-through inputs
the identifier reads).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vdps_hil.estimation.ekf import UpdateResult
from vdps_hil.estimation.states import STATE_NAMES, States


@dataclass(frozen=True)
class Estimate:
    """The 12 states of eq 7 (``States`` order, ``STATE_NAMES``) with 1-sigma, and the
    road-relative vehicle angles (phi_v, theta_v, psi_v) of eq 4 with their sigmas."""

    t_ns: int
    x: tuple[float, ...]
    sigma: tuple[float, ...]
    vehicle_angles_rad: tuple[float, float, float]
    vehicle_angles_sigma_rad: tuple[float, float, float]

    @classmethod
    def from_filter(cls, t_ns: int, layout, x, P) -> "Estimate":
        """From the filter vector ``x`` and covariance ``P`` in ``layout`` (``StateLayout``):
        P_full = E P E^T, the eq-4 angles' covariance J P_full[6:11, 6:11] J^T."""
        xf, e, ang, jac = layout.expand_with_vehicle_angles(x)
        pf = e @ P @ e.T
        pa = jac @ pf[6:11, 6:11] @ jac.T
        return cls(t_ns, tuple(xf.tolist()), _sigmas(pf), tuple(ang.tolist()), _sigmas(pa))

    def get(self, state) -> float:
        return self.x[_state_index(state)]

    def sigma_of(self, state) -> float:
        return self.sigma[_state_index(state)]

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "state": dict(zip(STATE_NAMES, self.x)),
                "sigma": dict(zip(STATE_NAMES, self.sigma)),
                "vehicle_angles_rad": dict(zip(("phi_v", "theta_v", "psi_v"), self.vehicle_angles_rad)),
                "vehicle_angles_sigma_rad": dict(zip(("phi_v", "theta_v", "psi_v"), self.vehicle_angles_sigma_rad))}


@dataclass(frozen=True)
class Innovation:
    """One EKF update: innovation per used row, sqrt(diag S), NIS and the gate."""

    t_ns: int
    kind: str
    status: str
    innovation: tuple[float, ...]
    innovation_sigma: tuple[float, ...]
    nis: float
    dof: int
    gate: float
    delayed: bool

    @classmethod
    def from_result(cls, r: UpdateResult) -> "Innovation":
        return cls(r.t_ns, r.kind.value, r.status, r.innovation, r.innovation_sigma, r.nis, r.dof, r.gate, r.delayed)

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "kind": self.kind, "status": self.status, "innovation": list(self.innovation),
                "innovation_sigma": list(self.innovation_sigma), "nis": self.nis, "dof": self.dof,
                "gate": self.gate, "delayed": self.delayed}


@dataclass(frozen=True)
class FilteredSignals:
    """Latest alpha-beta outputs (eq 12) and pass-through inputs for the identifier; NaN where
    no sample has arrived. ``lags_s``: derivative lag per group at its last sampling period."""

    t_ns: int
    angular_rate_radps: tuple[float, float, float]
    angular_accel_radps2: tuple[float, float, float]
    wheel_speed_radps: tuple[float, float, float, float]
    wheel_accel_radps2: tuple[float, float, float, float]
    susp_deflection_m: tuple[float, float, float, float]
    susp_rate_mps: tuple[float, float, float, float]
    wheel_torque_nm: tuple[float, float, float, float]
    steer_wheel_angle_rad: float
    lags_s: dict


def _sigmas(p: np.ndarray) -> tuple[float, ...]:
    """sqrt(max(p_ii, 0)) per diagonal element (NaN stays NaN) on floats: numpy's maximum and
    sqrt element for element (a diagonal made by matmul is never -0.0, the one input where a
    vectorised maximum may pick the other zero)."""
    return tuple([math.sqrt(v) if v > 0.0 else (v if v != v else 0.0) for v in p.diagonal().tolist()])


def _state_index(state) -> int:
    if isinstance(state, str):
        return STATE_NAMES.index(state)
    return int(States(state))
