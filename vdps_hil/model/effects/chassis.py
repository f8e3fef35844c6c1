"""Chassis effects: the parts of ``model.chassis`` as effects a model can lack and the workbench
can recommend.

``roll_stiffness``: auxiliary roll stiffness (anti-roll bars) of the front and rear axle, added
to the vehicle file's own (``[chassis]``; usually absent, i.e. 0). Each axle's bar acts on the
body as a pair of opposite vertical forces at the struts (Gillespie 1992, *Fundamentals of
Vehicle Dynamics*, ch. 8 "Roll stiffness"; Milliken & Milliken 1995, *Race Car Vehicle
Dynamics*, ch. 16: a roll rate in parallel with the springs' K_s T^2 / 2)::

    F_arb,i = K_arb,axle (H_i - H_j) / T_axle^2         [N]      (j: the other wheel of the axle)
    M_x,arb = -K_arb,f phi_f - K_arb,r phi_r            [N m],   phi_f = (H_2 - H_1) / T_f,
                                                                 phi_r = (H_3 - H_4) / T_r

H_i suspension deflection (compression positive, corners FL FR RR RL), T track width [m],
phi the axle's relative roll (body over axle, right side down positive) [rad], K [N m/rad].
Default magnitude: 15 kN m/rad front, 5 kN m/rad rear (passenger cars carry 5-40 kN m/rad of
bar roll stiffness, mostly at the front; CommonRoad's Ford Escort 12.9 kN m/rad front, its VW
Vanagon 33.9 / 7.7 kN m/rad). Linear in its parameters: regressors d(M_x)/dK_f = -phi_f,
d(M_x)/dK_r = -phi_r on the ``roll`` equation (needs ``susp_deflection_m_1..4``,
``track_front_m``, ``track_rear_m``: ``Model.regressor_quantities``). Without it a car's bars
leave the identifier's roll moment (eq 23, b_4 row 1) short by K_arb phi: I_x is then reported
as a model mismatch of the ``roll`` row (``identification.mismatch``), not silently wrong.
"""

from __future__ import annotations

from .base import DynamicsEffect, ParamSpec


class RollStiffness(DynamicsEffect):
    """``roll_stiffness`` -- auxiliary roll stiffness K_arb,f, K_arb,r [N m/rad] (module
    docstring), default 15000 N m/rad front and 5000 N m/rad rear."""

    name = "roll_stiffness"
    HOOKS = ("anti_roll_stiffness",)
    LINEAR_IN_PARAMETERS = True
    PARAMS = (
        ParamSpec("anti_roll_stiffness_front_nmprad", "N m/rad", 15000.0,
                  "auxiliary (anti-roll bar) roll stiffness of the front axle", 0.0, 1.0e5),
        ParamSpec("anti_roll_stiffness_rear_nmprad", "N m/rad", 5000.0,
                  "auxiliary (anti-roll bar) roll stiffness of the rear axle", 0.0, 1.0e5),
    )

    def anti_roll_stiffness(self) -> tuple[float, float]:
        v = self._values
        return v["anti_roll_stiffness_front_nmprad"], v["anti_roll_stiffness_rear_nmprad"]

    def regressors(self, q):
        phi_f = (q["susp_deflection_m_2"] - q["susp_deflection_m_1"]) / q["track_front_m"]
        phi_r = (q["susp_deflection_m_3"] - q["susp_deflection_m_4"]) / q["track_rear_m"]
        return {"roll": {"anti_roll_stiffness_front_nmprad": -phi_f, "anti_roll_stiffness_rear_nmprad": -phi_r}}
