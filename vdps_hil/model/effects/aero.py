"""Aerodynamic effects: drag and crosswind side force.

Symbols (body axes at the sprung CG, x fwd y left z up)::

    v_air = v_cg - w     CG velocity relative to the air, body axes              [m/s]
    w                    wind velocity (``Env.wind_enu_mps`` plus the crosswind's)  [m/s]
    rho                  air density                                               [kg/m^3]

* ``aero_drag``:  F_x = -1/2 rho C_d A |v_air| v_air,x   (at the CG, no moment)
* ``crosswind``:  F_y = -1/2 rho C_Y A |v_air| v_air,y,  M_z = x_cp F_y  (and brings its wind)

Compiled form: each force is written once, as a :func:`~vdps_hil.jit.inline` function the
effect's ``body_wrench`` calls and the compiled core calls (codes ``WRENCH_AERO_DRAG``,
``WRENCH_CROSSWIND``; parameters as numbers, :meth:`~vdps_hil.model.effects.base.DynamicsEffect.kernel_terms`).
"""

from __future__ import annotations

import math
from typing import Mapping

from vdps_hil.jit import inline

from .base import DynamicsEffect, ParamSpec

AIR_DENSITY_KGPM3 = 1.225  # ISA sea level, 15 degC
WRENCH_AERO_DRAG = 1
WRENCH_CROSSWIND = 2


@inline
def drag_wrench(air_density_kgpm3, cda_m2, ax, ay, az):
    """``aero_drag``: (F_x, 0, 0, 0, 0, 0), F_x = -1/2 rho C_d A |v_air| v_air,x [N]."""
    k = -0.5 * air_density_kgpm3 * cda_m2
    return (k * math.sqrt(ax * ax + ay * ay + az * az) * ax, 0.0, 0.0, 0.0, 0.0, 0.0)


@inline
def crosswind_wrench(air_density_kgpm3, side_force_area_m2, cp_x_m, ax, ay, az):
    """``crosswind``: (0, F_y, 0, 0, 0, x_cp F_y), F_y = -1/2 rho C_Y A |v_air| v_air,y [N]."""
    fy = -0.5 * air_density_kgpm3 * side_force_area_m2 * math.sqrt(ax * ax + ay * ay + az * az) * ay
    return (0.0, fy, 0.0, 0.0, 0.0, cp_x_m * fy)


def _air_speed(q: Mapping[str, float]) -> tuple[float, float, float]:
    ax, ay = q["air_vel_b_mps_x"], q["air_vel_b_mps_y"]
    az = q.get("air_vel_b_mps_z", 0.0)
    return ax, ay, math.sqrt(ax * ax + ay * ay + az * az)


class AeroDrag(DynamicsEffect):
    """``aero_drag`` -- aerodynamic drag along the body x axis, applied at the CG::

        F_x = -1/2 rho (C_d A) |v_air| v_air,x        [N]

    C_d A = cda_m2 [m^2] (default 0.7: C_d 0.30 x 2.3 m^2, mid-size sedan), rho = air_density
    [kg/m^3] (default 1.225). No lift and no pitching moment. Linear in C_d A:
    regressor on the ``long`` equation -1/2 rho |v_air| v_air,x (needs ``air_vel_b_mps_x/y``).
    """

    name = "aero_drag"
    HOOKS = ("body_wrench",)
    LINEAR_IN_PARAMETERS = True
    PARAMS = (
        ParamSpec("cda_m2", "m^2", 0.7, "drag area C_d A", 0.0, 3.0),
        ParamSpec("air_density_kgpm3", "kg/m^3", AIR_DENSITY_KGPM3, "air density", 0.9, 1.4),
    )

    def body_wrench(self, vel_b, omega_b, air_b):
        v = self._values
        return drag_wrench(v["air_density_kgpm3"], v["cda_m2"], *air_b)

    def kernel_terms(self):
        v = self._values
        return (("body_wrench", WRENCH_AERO_DRAG, (v["air_density_kgpm3"], v["cda_m2"])),)

    def regressors(self, q):
        ax, ay, sp = _air_speed(q)
        return {"long": {"cda_m2": -0.5 * self._values["air_density_kgpm3"] * sp * ax}}


class Crosswind(DynamicsEffect):
    """``crosswind`` -- a steady wind and the side force and yaw moment it causes::

        w   = wind_speed (cos psi_w, sin psi_w, 0)       in ENU, psi_w = wind_to_rad  [m/s]
        F_y = -1/2 rho (C_Y A) |v_air| v_air,y           [N]   at the CG height
        M_z = x_cp F_y                                    [N m] centre of pressure x_cp ahead of CG

    Defaults: wind 10 m/s blowing toward the north (psi_w = pi/2: from the right of a car driving
    east), C_Y A = 5.0 m^2 (passenger cars: dC_Y/dbeta about 0.04-0.05 per degree of yaw angle on a
    frontal area of about 2.2 m^2), x_cp = 0.5 m (yaw-moment derivative about 0.01-0.015 per degree
    on the wheelbase: the centre of pressure lies ahead of the CG). The wind also enters every
    other aerodynamic effect through v_air. Linear in C_Y A (with the wind given): regressors on
    ``lat`` -1/2 rho |v_air| v_air,y and on ``yaw`` x_cp times that.
    """

    name = "crosswind"
    HOOKS = ("body_wrench",)
    LINEAR_IN_PARAMETERS = True
    PARAMS = (
        ParamSpec("wind_speed_mps", "m/s", 10.0, "wind speed over ground", 0.0, 40.0),
        ParamSpec("wind_to_rad", "rad", math.pi / 2, "direction the wind blows toward, CCW from East"),
        ParamSpec("side_force_area_m2", "m^2", 5.0, "side-force area C_Y A (per unit v_air,y/|v_air|)", 0.0, 15.0),
        ParamSpec("cp_x_m", "m", 0.5, "centre of pressure ahead of the CG", -2.0, 2.0),
        ParamSpec("air_density_kgpm3", "kg/m^3", AIR_DENSITY_KGPM3, "air density", 0.9, 1.4),
    )

    def wind_enu_mps(self) -> tuple[float, float, float]:
        """The wind this effect brings, ENU [m/s]."""
        s, a = self._values["wind_speed_mps"], self._values["wind_to_rad"]
        return (s * math.cos(a), s * math.sin(a), 0.0)

    def body_wrench(self, vel_b, omega_b, air_b):
        v = self._values
        return crosswind_wrench(v["air_density_kgpm3"], v["side_force_area_m2"], v["cp_x_m"], *air_b)

    def kernel_terms(self):
        v = self._values
        return (("body_wrench", WRENCH_CROSSWIND, (v["air_density_kgpm3"], v["side_force_area_m2"], v["cp_x_m"])),)

    def regressors(self, q):
        ax, ay, sp = _air_speed(q)
        r = -0.5 * self._values["air_density_kgpm3"] * sp * ay
        return {"lat": {"side_force_area_m2": r}, "yaw": {"side_force_area_m2": self._values["cp_x_m"] * r}}
