"""Steering compliance and a steering-angle sensor offset.

``steering_compliance``: the front road-wheel angles yield to the front axle's lateral force
(steering-system and suspension compliance)::

    delta_i = delta_i,kin - K_c (F_b,1 + F_b,2),   i = 1, 2 (front)

delta_i,kin from the steering wheel angle, steer ratio and Ackermann geometry [rad];
F_b,1 + F_b,2 the front tires' lateral forces [N]; K_c compliance [rad/N]. The core solves this
implicit equation at every evaluation (secant on the front lateral force: exact for
``linear_tire``). With a linear tire the front axle stiffness becomes C_f / (1 + K_c C_f) and the
understeer gradient rises by

    Delta K_us = m_s l_r K_c / L          [rad/(m/s^2)]     (sprung-mass front axle share)

-- more precisely by W_f K_c / g where W_f is the static front axle load [N] (tested).

``steering_offset``: the steering-angle sensor reads the steering wheel angle plus a constant
(a sensor zeroed off the straight-ahead position, a steering wheel refitted a spline off, a
toe or thrust-angle misalignment the driver holds out)::

    delta_sw,meas = delta_sw + offset_rad          [rad at the steering wheel]

The car's motion is unchanged; a model fed the reading steers its front wheels by
offset_rad / steer_ratio more than the car does. With a linear tire the model's front lateral
force is then C_f offset_rad / i_s too large, so the residual (measured - model) of the lateral
balance is -C_f offset / i_s and of the yaw balance -l_f C_f offset / i_s (first order, small
angles): a constant lateral force at the front axle, at every speed and every lateral
acceleration. openpilot learns the same quantity (paramsd's angle offset; ``realdata.steering``).
"""

from __future__ import annotations

from typing import Mapping

from .base import DynamicsEffect, ImuKinematics, MeasurementEffect, ParamSpec

STEER_FIELD = "steer_wheel_angle_rad"


class SteeringCompliance(DynamicsEffect):
    """``steering_compliance`` -- delta_front -= K_c (F_b,1 + F_b,2). K_c = compliance_radpn
    [rad/N], default 2.0e-6 (0.115 deg of road-wheel angle per kN of front lateral force; about
    1 deg/g more understeer on the sedan; compliance steer adds 0.5-2 deg/g on passenger cars).
    Regressors (first order in K_c, linear tire): d(F_y,front)/dK_c = -C_f F_y,front on ``lat``
    and l_f times that on ``yaw`` (needs ``front_lateral_force_n``,
    ``cornering_stiffness_front_nprad``, ``l_f_m``)."""

    name = "steering_compliance"
    HOOKS = ("compliance_steer",)
    PARAMS = (ParamSpec("compliance_radpn", "rad/N", 2.0e-6, "front road-wheel angle per N of front lateral force", 0.0, 2e-5),)

    def compliance_steer(self) -> float:
        return self._values["compliance_radpn"]

    def regressors(self, q):
        r = -q["cornering_stiffness_front_nprad"] * q["front_lateral_force_n"]
        return {"lat": {"compliance_radpn": r}, "yaw": {"compliance_radpn": q["l_f_m"] * r}}


class SteeringOffset(MeasurementEffect):
    """``steering_offset`` -- delta_sw,meas = delta_sw + offset_rad (module docstring).
    offset_rad [rad at the steering wheel], default 0.02 (1.1 deg: 0.07 deg at the road wheels on
    a 16:1 rack); plausible within +-0.1 rad (5.7 deg). Regressor: d(reading)/d(offset) = 1. Its
    evidence is the lateral and yaw balance (the workbench's ``SteeringOffsetCandidate``, ranked
    over half a turn of heading with a straight: ``workbench.candidates.TURN_NEEDED_RAD`` and
    ``STRAIGHT_NEEDED_S``), not the GNSS
    innovations of the IMU's strapdown."""

    name = "steering_offset"
    FIELDS = (STEER_FIELD,)
    PARAMS = (ParamSpec("offset_rad", "rad", 0.02, "steering-angle sensor offset at the steering wheel", -0.1, 0.1),)

    def apply(self, fields: Mapping[str, float], kin: ImuKinematics) -> dict[str, float]:
        out = dict(fields)
        if STEER_FIELD in out:
            out[STEER_FIELD] = out[STEER_FIELD] + self._values["offset_rad"]
        return out

    def regressors(self, kin: ImuKinematics) -> dict[str, dict[str, float]]:
        return {STEER_FIELD: {"offset_rad": 1.0}}


_AT_REST = ImuKinematics(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def steering_effects(effects) -> list[MeasurementEffect]:
    """The measurement effects among ``effects`` that change the steering-angle reading."""
    return [e for e in effects if isinstance(e, MeasurementEffect) and STEER_FIELD in e.FIELDS]


def steer_corrected(reading_rad: float, effects) -> float:
    """The steering wheel angle with the steering-sensor effects taken out of ``reading_rad``:
    r - (e(r) - r), exact for an offset (``steering_effects`` of them; the kinematics are not
    read)."""
    d = {STEER_FIELD: reading_rad}
    for e in effects:
        d = e.apply(d, _AT_REST)
    return reading_rad - (d[STEER_FIELD] - reading_rad)
