"""What the identifier reads: ``IdentInputs``, the estimated quantities at one instant (never
simulator truth; symbols and units: ``problems`` module docstring), and the gravity of eq 13 in
the aux frame from the estimated road angles (``gravity_aux_mps2``). ``feeder.IdentFeeder``
builds them from the estimator's outputs.
"""

from __future__ import annotations

from dataclasses import dataclass

from vdps_hil.model.frames import gravity_in_aux
from vdps_hil.units import GRAVITY_MPS2


def _tup(v, n: int, name: str) -> tuple[float, ...]:
    t = tuple(float(e) for e in v)
    if len(t) != n:
        raise ValueError(f"IdentInputs.{name}: expected {n} values, got {len(t)}")
    return t


@dataclass(frozen=True, slots=True)
class IdentInputs:
    """Estimated quantities at one instant (never simulator truth). Units in the names; frames:
    aux {a} for translation, vehicle {v} for rotation; wheels in order FL, FR, RR, RL."""

    t_ns: int
    xdd_a_mps2: float
    ydd_a_mps2: float
    zdd_a_mps2: float
    xd_a_mps: float
    yd_a_mps: float
    psi_v_dot_radps: float
    gravity_aux_mps2: tuple[float, float, float]  # (G_x, G_y, G_z), eq 13
    omega_radps: tuple[float, float, float]  # body rates (w_x, w_y, w_z)
    omega_dot_radps2: tuple[float, float, float]  # alpha-beta derivatives
    susp_deflection_m: tuple[float, float, float, float]  # H_i, compression positive
    susp_rate_mps: tuple[float, float, float, float]  # Hd_i
    wheel_speed_radps: tuple[float, float, float, float]
    wheel_accel_radps2: tuple[float, float, float, float]
    wheel_torque_nm: tuple[float, float, float, float]
    slip_ratio: tuple[float, float, float, float]
    slip_angle_rad: tuple[float, float, float, float]
    wheel_angle_rad: tuple[float, float, float, float]  # delta_i (rear 0 for front steer)
    moments_nm: tuple[float, float, float] | None = None  # override of (M_x, M_y, M_z)
    specific_force_b_mps2: tuple[float, float, float] | None = None  # f at the CG, body axes ("measured")
    vehicle_angles_rad: tuple[float, float] | None = None  # road-relative (phi_v, theta_v), eq 4
    lateral_velocity_sigma_mps: float | None = None  # EKF 1-sigma of yd_a (excitation gates)
    susp_interval_s: float | None = None  # the longer of the last suspension sampling interval and the
    #                                       newest sample's age at t_ns (feeder; strut-force rows gate on it)

    def __post_init__(self):
        if not isinstance(self.t_ns, int) or isinstance(self.t_ns, bool):
            raise TypeError(f"IdentInputs.t_ns must be int nanoseconds, got {type(self.t_ns).__name__}")
        for name, n in (("gravity_aux_mps2", 3), ("omega_radps", 3), ("omega_dot_radps2", 3),
                        ("susp_deflection_m", 4), ("susp_rate_mps", 4), ("wheel_speed_radps", 4),
                        ("wheel_accel_radps2", 4), ("wheel_torque_nm", 4), ("slip_ratio", 4),
                        ("slip_angle_rad", 4), ("wheel_angle_rad", 4)):
            object.__setattr__(self, name, _tup(getattr(self, name), n, name))
        if self.moments_nm is not None:
            object.__setattr__(self, "moments_nm", _tup(self.moments_nm, 3, "moments_nm"))
        if self.specific_force_b_mps2 is not None:
            object.__setattr__(self, "specific_force_b_mps2", _tup(self.specific_force_b_mps2, 3,
                                                                   "specific_force_b_mps2"))
        if self.lateral_velocity_sigma_mps is not None:
            object.__setattr__(self, "lateral_velocity_sigma_mps", float(self.lateral_velocity_sigma_mps))
        if self.susp_interval_s is not None:
            object.__setattr__(self, "susp_interval_s", float(self.susp_interval_s))
        if self.vehicle_angles_rad is not None:
            object.__setattr__(self, "vehicle_angles_rad", _tup(self.vehicle_angles_rad, 2, "vehicle_angles_rad"))


def gravity_aux_mps2(phi_r_rad: float, theta_r_rad: float, psi_v_rad: float) -> tuple[float, float, float]:
    """(G_x, G_y, G_z) of eq 13 from the *estimated* road bank, grade and vehicle yaw."""
    g = gravity_in_aux(phi_r_rad, theta_r_rad, psi_v_rad, GRAVITY_MPS2)
    return float(g[0]), float(g[1]), float(g[2])
