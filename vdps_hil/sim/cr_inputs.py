"""Our driver inputs (steering-wheel angle, wheel drive and brake torques) -> the inputs of
CommonRoad's multibody model (``sim.cr_model``): u1 = road-wheel steering velocity, u2 =
longitudinal acceleration; and the wheel torques the model then applies.

The package's standard interface takes only these two inputs. A scenario's open-loop schedule
or closed-loop driver (``sim.scenarios``, ``sim.driver``) gives :class:`~vdps_hil.model.core.Inputs`;
the mapping below lets them drive the model unchanged. Inputs are held over each integration
step [t_n, t_n + h), as our simulator holds them.

Steering: a dead-beat servo on the road-wheel angle::

    delta_cmd = -delta_sw / i_s                (the package steers positive to the right; our
                                                steering-wheel angle is positive to the left)
    u1        = (delta_cmd - delta_n) / h      held over the step, so delta(t_n + h) = delta_cmd:
                                               the road wheels follow the steering wheel one
                                               step (1 ms) late
    u1       := steering_constraints(delta_n, u1)   (the package's limits: |u1| <= 0.4 rad/s at
                                               the road wheels, 6.4 rad/s = 367 deg/s at the
                                               steering wheel with i_s = 16; |delta| <= 0.91 rad
                                               (set 1) / 1.023 rad (set 3))

When a limit acts the road wheels lag the steering wheel: ``CrInputs.steer_limited`` says so
and the truth backend counts the steps (``steer_rate_limited_steps``); the CAN steering sensor
measures the steering wheel (the command), the truth records both.

Wheel torques -> acceleration::

    T_i = T_drive,i - B_i sat(omega_i / omega_h)      our brake law (``model.core``: a brake
                                                      opposes rotation, omega_h = 2 rad/s)
    u2  = sum_i T_i / (m R_w)                         the acceleration the torques give the
                                                      whole mass (the package's own inverse:
                                                      T = m R_w u2)
    u2 := acceleration_constraints(u, u2)             (the package's limits: |u2| <= a_max =
                                                      11.5 m/s^2, drive limited to
                                                      a_max v_switch / u above v_switch, the
                                                      engine's power)
    u2 := max(u2, 0) when u <= 0                      no reversing: a brake holds a stopped
                                                      vehicle (our addition)

Applied per wheel (the package's split; what the truth records and the CAN torque sensor
measures)::

    T = m R_w u2;  u2 > 0: T_FL = T_FR = T_se T / 2,  T_RR = T_RL = (1 - T_se) T / 2   (drive)
                   u2 < 0: T_FL = T_FR = T_sb T / 2,  T_RR = T_RL = (1 - T_sb) T / 2   (brake)

So the per-wheel distribution of a scenario is replaced by the vehicle's own (set 1: front
drive, 76 % of the braking on the front axle; set 3: rear drive, 64 %); the total is kept
unless a limit acts (``accel_limited``).

Symbols: delta road-wheel angle [rad], delta_sw steering-wheel angle [rad], i_s steering ratio
[-], h step [s], T torque [N m], B brake torque magnitude [N m], omega wheel spin [rad/s], m
total mass [kg], R_w wheel radius [m], u longitudinal velocity [m/s], T_se, T_sb front shares of
drive and brake torque [-]. Wheels in our order 1..4 = FL FR RR RL.
"""

from __future__ import annotations

from dataclasses import dataclass

from vdps_hil.model.core import BRAKE_HOLD_SPEED_RADPS, Inputs

__all__ = ["CrInputs", "InputMapping"]


@dataclass(frozen=True)
class CrInputs:
    """One step's mapped inputs (module docstring). Torques in our wheel order FL FR RR RL."""

    steer_rate_radps: float  # u1, road wheels, positive to the right (package sense)
    accel_mps2: float  # u2 after the limits
    road_wheel_angle_cmd_rad: float  # delta_cmd (package sense)
    wheel_torque_nm: tuple[float, float, float, float]  # applied net torque per wheel
    brake_torque_nm: tuple[float, float, float, float]  # its braking part, magnitudes >= 0
    steer_limited: bool
    accel_limited: bool

    @property
    def u(self) -> list[float]:
        """The package's input vector [u1, u2]."""
        return [self.steer_rate_radps, self.accel_mps2]


class InputMapping:
    """Maps our :class:`Inputs` to :class:`CrInputs` for a parameter object ``p`` of the package
    and a steering ratio (module docstring)."""

    def __init__(self, p, steer_ratio: float):
        from vehiclemodels.utils.acceleration_constraints import acceleration_constraints
        from vehiclemodels.utils.steering_constraints import steering_constraints

        if not steer_ratio > 0:
            raise ValueError(f"steer_ratio must be positive, got {steer_ratio!r}")
        self._steer_c, self._accel_c = steering_constraints, acceleration_constraints
        self.p = p
        self.steer_ratio = float(steer_ratio)
        self._m_r = p.m * p.R_w
        self._split_drive = (p.T_se / 2, p.T_se / 2, (1 - p.T_se) / 2, (1 - p.T_se) / 2)
        self._split_brake = (p.T_sb / 2, p.T_sb / 2, (1 - p.T_sb) / 2, (1 - p.T_sb) / 2)

    def net_torque_nm(self, inputs: Inputs, wheel_spin_radps) -> float:
        """sum_i (T_drive,i - B_i sat(omega_i / omega_h)) [N m]."""
        total = 0.0
        for td, b, w in zip(inputs.wheel_torque_nm, inputs.brake_torque_nm, wheel_spin_radps):
            s = w / BRAKE_HOLD_SPEED_RADPS
            total += td - b * (1.0 if s > 1.0 else -1.0 if s < -1.0 else s)
        return total

    def map(self, inputs: Inputs, road_wheel_angle_rad: float, speed_mps: float, wheel_spin_radps,
            step_s: float) -> CrInputs:
        """``road_wheel_angle_rad`` delta_n (package sense), ``speed_mps`` the package's u,
        ``wheel_spin_radps`` in our order, ``step_s`` the step the input is held over."""
        p = self.p
        delta_cmd = -inputs.steer_wheel_angle_rad / self.steer_ratio
        u1_raw = (delta_cmd - road_wheel_angle_rad) / step_s
        u1 = float(self._steer_c(road_wheel_angle_rad, u1_raw, p.steering))
        a_raw = self.net_torque_nm(inputs, wheel_spin_radps) / self._m_r
        a = float(self._accel_c(speed_mps, a_raw, p.longitudinal))
        if speed_mps <= 0.0 and a < 0.0:
            a = 0.0
        t_total = self._m_r * a
        split = self._split_drive if a > 0.0 else self._split_brake
        torque = tuple(t_total * s for s in split)
        brake = tuple(-t for t in torque) if a < 0.0 else (0.0, 0.0, 0.0, 0.0)
        return CrInputs(u1, a, delta_cmd, torque, brake, u1 != u1_raw, abs(a - a_raw) > 1e-12)
