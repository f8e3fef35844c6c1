"""Rolling resistance.

``rolling_resistance``: a moment on each wheel's spin axis opposing its rotation::

    T_rr,i = -f_r r_i F_z,i sat(omega_i r_i / v_eps)       [N m]

f_r rolling resistance coefficient [-], r_i rolling radius [m], F_z,i normal load [N],
sat(s) = max(-1, min(1, s)) with v_eps = 0.1 m/s (keeps the law continuous at standstill).
In steady free rolling the road's longitudinal force on the tire is then -f_r F_z,i.
Compiled form: :func:`rolling_resistance_torque` (a :func:`~vdps_hil.jit.inline` function the
effect and the compiled core both call; code ``WHEEL_ROLLING_RESISTANCE``).
"""

from __future__ import annotations

from vdps_hil.jit import inline

from .base import DynamicsEffect, ParamSpec

ROLLING_SPEED_EPS_MPS = 0.1
WHEEL_ROLLING_RESISTANCE = 1


@inline
def rolling_resistance_torque(coefficient, omega_radps, fz_n, radius_m):
    """T_rr = -f_r r F_z sat(omega r / v_eps) [N m] (module docstring)."""
    s = omega_radps * radius_m / ROLLING_SPEED_EPS_MPS
    if s > 1.0:
        s = 1.0
    elif s < -1.0:
        s = -1.0
    return -coefficient * radius_m * fz_n * s


class RollingResistance(DynamicsEffect):
    """``rolling_resistance`` -- T_rr,i = -f_r r_i F_z,i sat(omega_i r_i / 0.1 m/s) [N m] on each
    wheel's spin axis. f_r = coefficient [-], default 0.012 (passenger tire on asphalt,
    0.008-0.015). Linear in f_r: regressor on ``wheel_i`` -r_i F_z,i sat(...) (needs
    ``normal_load_n_i``, ``rolling_radius_m_i``, ``wheel_speed_radps_i``)."""

    name = "rolling_resistance"
    HOOKS = ("wheel_torque",)
    LINEAR_IN_PARAMETERS = True
    PARAMS = (ParamSpec("coefficient", "1", 0.012, "rolling resistance coefficient f_r", 0.0, 0.05),)

    def _validate(self):
        object.__setattr__(self, "_fr", self._values["coefficient"])

    def wheel_torque(self, corner, omega_radps, fz_n, radius_m):
        return rolling_resistance_torque(self._fr, omega_radps, fz_n, radius_m)

    def kernel_terms(self):
        return (("wheel_torque", WHEEL_ROLLING_RESISTANCE, (self._fr,)),)

    def regressors(self, q):
        out = {}
        for i in range(1, 5):
            r = q[f"rolling_radius_m_{i}"]
            s = max(-1.0, min(1.0, q[f"wheel_speed_radps_{i}"] * r / ROLLING_SPEED_EPS_MPS))
            out[f"wheel_{i}"] = {"coefficient": -r * q[f"normal_load_n_{i}"] * s}
        return out
