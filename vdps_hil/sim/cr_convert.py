"""Conversions between CommonRoad's multibody model and our frames for the second truth
(``sim.truth_cr``): the body's kinematics from the package's state, the suspension travel, the
trimmed start state, the scenario range the model covers, and the model view the driver and the
recorder read. Frames, signs and the equations are in ``sim.truth_cr``'s docstring; primes
mark the package's axes (SAE: x forward, y right, z down)."""

from __future__ import annotations

import math
from typing import Callable, Sequence

from vdps_hil.model.core import StateLayout
from vdps_hil.model.effects import EffectSet, MeasurementEffect, TireModel

from .cr_model import CR_GRAVITY_MPS2, mb_rhs, static_ride
from .truth_backends import TruthBackendError

__all__ = ["TruthRangeError", "ModelView", "body_kinematics", "suspension_travel", "check_scenario", "trim_state",
           "KINEMATIC_SPEED_MPS"]

KINEMATIC_SPEED_MPS = 0.1
"""Below this |u| the package uses its kinematic single-track branch [m/s]."""


class TruthRangeError(TruthBackendError):
    """A scenario outside the CommonRoad backend's range (one-line message)."""


# ---------------------------------------------------------------------------------------------
# conversions (pure functions of the package's state and its derivative)
# ---------------------------------------------------------------------------------------------
def body_kinematics(x: Sequence[float], xd: Sequence[float] | None, h_s_m: float,
                    g_mps2: float = CR_GRAVITY_MPS2) -> dict:
    """Our rigid-body truth from the package's state ``x`` and derivative ``xd`` (module
    docstring, "Conversions"): ``pos_g``, ``euler`` (phi, theta, psi), ``euler_rate``,
    ``vel_g`` (ENU), ``vel_b``, ``rate_b`` (body axes, ISO 8855); with ``xd`` also ``accel_g``,
    ``accel_b``, ``specific_force_b``, ``angular_accel_b``. Tuples of 3 floats; C_g^v and
    C_omega written out (``model.frames`` has them as matrices; tested equal)."""
    psi_c, r_c, u, v = x[4], x[5], x[3], x[10]
    c, s = math.cos(psi_c), math.sin(psi_c)
    vx1 = u * c - v * s
    vx2 = u * s + v * c
    vel_g = (vx1, -vx2, -x[12])
    phi, theta, psi = x[6], x[8], -psi_c
    cp, sp, ct, st = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    cy, sy = c, -s  # cos, sin of our yaw
    # C_g^v = R(x, phi) R(y, theta) R(z, psi) (eq 1)
    C = ((ct * cy, ct * sy, st),
         (-cp * sy - sp * st * cy, cp * cy - sp * st * sy, sp * ct),
         (sp * sy - cp * st * cy, -sp * cy - cp * st * sy, cp * ct))

    def rot(w):
        return tuple(r[0] * w[0] + r[1] * w[1] + r[2] * w[2] for r in C)

    dp, dt_, dy = x[7], x[9], -r_c
    # C_omega = [[1, 0, st], [0, -cp, ct sp], [0, sp, ct cp]] (eq 7 consistent with eq 1)
    rate_b = (dp + st * dy, -cp * dt_ + ct * sp * dy, sp * dt_ + ct * cp * dy)
    out = {"pos_g": (x[0], -x[1], h_s_m - x[11]), "euler": (phi, theta, psi), "euler_rate": (dp, dt_, dy),
           "vel_g": vel_g, "vel_b": rot(vel_g), "rate_b": rate_b}
    if xd is None:
        return out
    ax1 = xd[3] * c - xd[10] * s - vx2 * r_c
    ax2 = xd[3] * s + xd[10] * c + vx1 * r_c
    acc_g = (ax1, -ax2, -xd[12])
    acc_b = rot(acc_g)
    ddp, ddt, ddy = xd[7], xd[9], -xd[5]
    # C_omega (d2phi, d2theta, d2psi) + dC_omega/dt (dphi, dtheta, dpsi)
    ang_b = (ddp + st * ddy + ct * dt_ * dy,
             -cp * ddt + ct * sp * ddy + sp * dp * dt_ + (-st * sp * dt_ + ct * cp * dp) * dy,
             sp * ddt + ct * cp * ddy + cp * dp * dt_ + (-st * cp * dt_ - ct * sp * dp) * dy)
    out.update(accel_g=acc_g, accel_b=acc_b,
               specific_force_b=tuple(a + C[k][2] * g_mps2 for k, a in enumerate(acc_b)),
               angular_accel_b=ang_b)
    return out


def suspension_travel(x: Sequence[float], p) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The package's suspension travel z_S and its rate per corner, in its order LF RF LR RR
    (extension positive; module docstring)."""
    cphi = math.cos(x[6])
    base = p.h_s - p.R_w
    zf = (base + x[16] - x[11]) / cphi - base + p.a * x[8]
    zr = (base + x[21] - x[11]) / cphi - base - p.b * x[8]
    rf = 0.5 * p.T_f * (x[6] - x[13])
    rr = 0.5 * p.T_r * (x[6] - x[18])
    dzf = x[17] - x[12] + p.a * x[9]
    dzr = x[22] - x[12] - p.b * x[9]
    drf = 0.5 * p.T_f * (x[7] - x[14])
    drr = 0.5 * p.T_r * (x[7] - x[19])
    return (zf + rf, zf - rf, zr + rr, zr - rr), (dzf + drf, dzf - drf, dzr + drr, dzr - drr)


class ModelView:
    """What the closed-loop driver and the step recorder read from ``sim.model``."""

    def __init__(self, vehicle, figures: dict):
        self.vehicle = vehicle
        self.layout = StateLayout(True)
        self.static_load_n = tuple(figures[f"static_load_n_{i}"] for i in range(1, 5))
        self.rolling_radius_m = (vehicle.tire.rolling_radius_m,) * 4


def check_scenario(scenario, effects: EffectSet, flat_road: bool) -> tuple[EffectSet, list[str]]:
    """The effects the backend keeps (measurement effects) and its notes; TruthRangeError for a
    scenario outside its range (module docstring, "Range")."""
    notes: list[str] = []
    if scenario is not None:
        if scenario.bank_rad != 0.0 or scenario.grade_rad != 0.0:
            road = f"bank {math.degrees(scenario.bank_rad):g} deg, grade {math.degrees(scenario.grade_rad):g} deg"
            if not flat_road:
                raise TruthRangeError(f"scenario {scenario.name!r} asks for a road with {road}; the CommonRoad "
                                      f"model has a flat road only (--flat-road drives it level)")
            notes.append(f"flat road: the scenario's {road} is not simulated (--flat-road)")
        if any(w != 0.0 for w in scenario.wind_enu_mps):
            notes.append("wind not simulated: the CommonRoad model has no aerodynamics")
        if scenario.stop_at_point_of_no_return:
            raise TruthRangeError(f"scenario {scenario.name!r} is a rollover scenario; the CommonRoad model has "
                                  f"no wheel lift-off, rollover is outside its range")
    kept = []
    for e in effects:
        if isinstance(e, MeasurementEffect):
            kept.append(e)
        elif isinstance(e, TireModel):
            notes.append(f"effect {e.name} replaced by the CommonRoad model's own Pacejka tire")
        else:
            raise TruthRangeError(f"effect {e.name!r} acts on this project's physics core; the CommonRoad "
                                  f"truth has its own physics (drop the effect or use --truth ours)")
    return EffectSet(kept), notes


def trim_state(p, speed_mps: float, heading_rad: float = 0.0, east_m: float = 0.0, north_m: float = 0.0,
               rhs: Callable | None = None, iterations: int = 20) -> list[float]:
    """The package's state at static equilibrium on a level road, moving straight ahead at
    ``speed_mps`` (our heading, ENU position): the static ride of ``cr_model.static_ride`` refined
    by Newton on the vertical, pitch and (above 0.1 m/s) wheel-spin accelerations with zero
    inputs (the wheels settle at the slip where the tire's force offsets vanish)."""
    rhs = rhs or mb_rhs()
    ride = static_ride(p)
    x = [0.0] * 29
    x[0], x[1], x[3], x[4] = float(east_m), -float(north_m), float(speed_mps), -float(heading_rad)
    x[8], x[11], x[16], x[21] = ride.pitch_rad, ride.z_sprung_m, ride.z_unsprung_front_m, ride.z_unsprung_rear_m
    for k in range(23, 27):
        x[k] = speed_mps / p.R_w
    unknowns, resid = [11, 8, 16, 21], [12, 9, 17, 22]
    if abs(speed_mps) >= KINEMATIC_SPEED_MPS:
        unknowns, resid = unknowns + [23, 24, 25, 26], resid + [23, 24, 25, 26]
    import numpy as np

    def r(xv):
        xd = rhs(list(xv), [0.0, 0.0], p)
        return np.array([xd[k] for k in resid])

    for _ in range(iterations):
        r0 = r(x)
        if float(np.max(np.abs(r0))) < 1e-11:
            break
        J = np.zeros((len(resid), len(unknowns)))
        for j, k in enumerate(unknowns):
            xp = list(x)
            dk = 1e-7 * max(1.0, abs(x[k]))
            xp[k] += dk
            J[:, j] = (r(xp) - r0) / dk
        dz = np.linalg.solve(J, -r0)
        for j, k in enumerate(unknowns):
            x[k] += float(dz[j])
    return x


# ---------------------------------------------------------------------------------------------
