"""Steering compliance.

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
"""

from __future__ import annotations

from .base import DynamicsEffect, ParamSpec


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
