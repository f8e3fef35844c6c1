"""The truth simulator: the physics core (``model.core``) stepped at a fixed step, with an input
port, truth snapshots at 100 Hz and the kinematic truth a sensor model needs at every step.

Integration
-----------
Fixed step ``dt_s`` (default 1 ms; must divide the 10 ms truth period), Heun's method (RK2,
default) or classic RK4, inputs held over each step (zero-order hold, as a digital bench or ECU
applies them). Time is an integer step count, so ``t_ns = n * dt_ns`` exactly.

Why RK2 at 1 ms: the stiffest mode is the wheel spin under slip, tau = I_w max(|v|, v_floor) /
(r^2 C_kappa): 3.9 ms at 25 m/s and 0.78 ms at the slip speed floor (5 m/s) for the sedan
(I_w = 1.2 kg m^2, r = 0.31 m, C_kappa = 80 kN). dt = 1 ms resolves it at speed (dt/tau = 0.26)
and stays stable to standstill (Heun needs dt < 2 tau, RK4 dt < 2.78 tau; checked at
construction). Wheel hop (about 13 Hz, damped) and the body modes (1-2 Hz) are slower. Over
10 s of ``paper`` RK2 and RK4 at the same step differ by 8 um in position and 7e-6 deg in
attitude, and halving the step changes the result by 0.5 mm and 0.003 deg -- an error set by
the zero-order hold of the 1 Hz inputs, not by the integrator (tests/test_simulator.py). RK2
costs half of RK4.

Usage::

    sim = Simulator(scenario=load_scenario("paper"))     # vehicle and effects from the scenario
    sim.step_to(1.0)                                     # advance to t = 1 s
    kin = sim.kinematics()                               # specific force, rates, angular accel
    sim.set_input_override(Inputs(0.1, (100.0,) * 4))    # a bench/ECU takes over the inputs
    sim.set_input_override(lambda t, scheduled: dataclasses.replace(scheduled, brake_torque_nm=...))
    sim.run()                                            # to the scenario's end (or the PONR)
    sim.truth                                            # list of 100 Hz snapshots (dicts, SI)

Truth snapshot (one dict per 10 ms; SI, names carry units; wheel i = 1..4 FL FR RR RL)
-------------------------------------------------------------------------------------
``t_s``, ``t_ns``; ``pos_{e,n,u}_m`` (sprung CG, ENU), ``pos_r_m_{x,y,z}`` (road frame);
``vel_g_mps_{e,n,u}``, ``vel_b_mps_{x,y,z}``, ``speed_mps``, ``sideslip_rad``;
``roll_g_rad``, ``pitch_g_rad``, ``yaw_g_rad`` (absolute, eq 1), ``roll_v_rad``, ``pitch_v_rad``,
``yaw_v_rad`` (relative to the road, eq 3-4), ``roll_rate_v_radps`` (d phi_v / dt);
``rate_b_radps_{x,y,z}``, ``angular_accel_b_radps2_{x,y,z}``, ``accel_b_mps2_{x,y,z}`` (CG
acceleration), ``specific_force_b_mps2_{x,y,z}`` (a - g at the CG);
``wheel_speed_radps_i``, ``slip_ratio_i``, ``slip_angle_rad_i``, ``tire_force_long_n_i``,
``tire_force_lat_n_i``, ``normal_load_n_i``, ``susp_deflection_m_i`` (from design ride height,
compression positive), ``susp_deflection_rate_mps_i``, ``susp_force_n_i``,
``road_wheel_angle_rad_i``, ``rolling_radius_m_i``, ``wheel_torque_nm_i`` (net applied: drive
minus brake), ``brake_torque_nm_i``; ``steer_wheel_angle_rad``; ``road_bank_rad``,
``road_grade_rad``; ``ltr`` (load transfer ratio (F_right - F_left)/sum); ``events`` (list of
rollover events detected at this sample, as dicts).
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import ImuKinematics
from vdps_hil.model.frames import decompose_vehicle
from vdps_hil.model.params import Vehicle, load_vehicle

from vdps_hil.model.rollover import RolloverMonitor

from .stepping import FixedStepTruth, InputSource, SimulationError, rk_step, snapshot_ltr



def _fast_inputs(steer: float, torques: tuple, brakes: tuple) -> Inputs:
    u = object.__new__(Inputs)
    object.__setattr__(u, "steer_wheel_angle_rad", steer)
    object.__setattr__(u, "wheel_torque_nm", torques)
    object.__setattr__(u, "brake_torque_nm", brakes)
    return u


__all__ = ["Simulator", "SimulationError", "InputSource"]


class Simulator(FixedStepTruth):
    """A steppable truth simulator.

    Parameters
    ----------
    vehicle: a Vehicle or a vehicle file name; default: the scenario's vehicle.
    scenario: a :class:`vdps_hil.sim.scenarios.Scenario` (road, effects, initial state, inputs or
        driver, duration). Without it give ``inputs`` (Inputs or an InputSource) and optionally
        ``env``, ``initial_speed_mps`` / ``initial_state``.
    effects: an EffectSet replacing the scenario's (default: the scenario's, with magnitudes from
        the vehicle truth file). Measurement effects are carried (``sim.effects.measurement``) for
        the sensor models; only dynamics effects act here.
    dt_s: integration step (<= 1 ms, dividing 10 ms). integrator: "rk4" or "rk2".
    unsprung_dof: truth model with unsprung vertical DOF (default True).
    stop_at_point_of_no_return: stop stepping when the PONR is reached (default: the scenario's).
    record_truth: keep the 100 Hz snapshots in ``self.truth``; ``on_truth(snapshot)`` is called too.
    """

    def __init__(self, vehicle: Vehicle | str | None = None, scenario=None, effects: EffectSet | None = None, *,
                 inputs: Inputs | InputSource | None = None, env: Env | None = None,
                 initial_state: Sequence[float] | None = None, initial_speed_mps: float | None = None,
                 dt_s: float = 1e-3, integrator: str = "rk2", truth_rate_hz: float = 100.0,
                 unsprung_dof: bool = True, stop_at_point_of_no_return: bool | None = None,
                 record_truth: bool = True, on_truth: Callable[[dict], None] | None = None,
                 duration_s: float | None = None, slip_speed_floor_mps: float | None = None):
        if vehicle is None:
            vehicle = scenario.vehicle if scenario is not None else "sedan-truth"
        if isinstance(vehicle, str):
            vehicle = load_vehicle(vehicle)
        self.vehicle = vehicle
        self.scenario = scenario
        if effects is None:
            effects = scenario.effect_set(vehicle) if scenario is not None else EffectSet()
        self.env = env if env is not None else (scenario.env() if scenario is not None else Env())
        kw = {} if slip_speed_floor_mps is None else {"slip_speed_floor_mps": slip_speed_floor_mps}
        self.model = Model(vehicle, effects.dynamics if isinstance(effects, EffectSet) else effects,
                           unsprung_dof=unsprung_dof, **kw)
        self.effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
        self._init_clock(dt_s, truth_rate_hz, integrator)
        limit = self.model.max_stable_step_s if integrator == "rk4" else self.model.max_stable_step_s * 2.0 / 2.78
        if dt_s > limit:
            raise SimulationError(f"dt_s {dt_s} s exceeds the stability limit {limit:.2e} s of the wheel-spin mode")
        self.n = 0
        self._init_inputs(inputs, scenario, self.model, self.env)
        # initial state
        if initial_state is not None:
            x0 = [float(v) for v in initial_state]
            if len(x0) != self.model.layout.size:
                raise SimulationError(f"initial_state has {len(x0)} values, the layout needs {self.model.layout.size}")
        else:
            speed = initial_speed_mps
            heading, east, north = 0.0, 0.0, 0.0
            if scenario is not None:
                speed = scenario.initial_speed_mps if speed is None else speed
                heading = scenario.initial_heading_rad
                east, north = scenario.initial_east_m, scenario.initial_north_m
            x0 = self.model.trim_state(speed or 0.0, self.env, heading, east_m=east, north_m=north)
        self.x = x0
        self.duration_s = duration_s if duration_s is not None else (scenario.duration_s if scenario is not None else None)
        if stop_at_point_of_no_return is None:
            stop_at_point_of_no_return = bool(scenario.stop_at_point_of_no_return) if scenario is not None else False
        self.stop_at_point_of_no_return = stop_at_point_of_no_return
        geo = vehicle.geometry
        self.rollover = RolloverMonitor(self.model.static_load_n,
                                        0.5 * (geo.track_half_front_m + geo.track_half_rear_m), geo.h_cg_m)
        self.stopped = False
        self.stop_reason = ""
        self.record_truth = record_truth
        self.truth: list[dict] = []
        self._on_truth = on_truth
        self._step_hooks: list[Callable[["Simulator"], None]] = []
        self._k1 = None  # (n, u, k1) cache of f at the current state
        self._u = None  # inputs in force for the current step
        self._u_n = -1
        self._emit_truth()

    # ------------------------------------------------------------------ state
    @property
    def state(self) -> list[float]:
        """A copy of the state vector (layout: ``self.model.layout``)."""
        return list(self.x)

    def state_named(self) -> dict[str, float]:
        return dict(zip(self.model.layout.names, self.x))

    # ------------------------------------------------------------------ input port
    def set_input_override(self, override: Inputs | Callable[[float, Inputs], Inputs] | None) -> None:
        """Replace the scheduled inputs from the next step on: an Inputs (held), a callable
        ``(t_s, scheduled_inputs) -> Inputs`` (e.g. an ECU adding brake torque), or None to go
        back to the schedule/driver."""
        self._override = override
        self._u_n = -1

    def current_inputs(self) -> Inputs:
        """The inputs applied over the step starting now."""
        if self._u_n != self.n:
            u = self._source(self.t_s, self.x)
            ov = self._override
            if ov is not None:
                u = ov if isinstance(ov, Inputs) else ov(self.t_s, u)
            self._u = u
            self._u_n = self.n
        return self._u

    # ------------------------------------------------------------------ stepping
    def _deriv_now(self, u: Inputs) -> list:
        k = self._k1
        if k is not None and k[0] == self.n and k[1] is u:
            return k[2]
        k1 = self.model.f(self.x, u, self.env)
        self._k1 = (self.n, u, k1)
        return k1

    def step(self) -> bool:
        """One integration step; False when stopped."""
        if self.stopped:
            return False
        u = self.current_inputs()
        f, env = self.model.f, self.env
        xn = rk_step(lambda x: f(x, u, env), self.x, self._deriv_now(u), self.dt_s, self.integrator)
        self.x = xn
        self.n += 1
        if not math.isfinite(xn[6] + xn[9] + xn[12]):
            self.stopped = True
            self.stop_reason = "non-finite state"
            raise SimulationError(f"non-finite state at t = {self.t_s:.3f} s")
        return self._after_step()

    # ------------------------------------------------------------------ truth
    def kinematics(self) -> ImuKinematics:
        """Specific force at the CG, body rates and angular acceleration (body axes) now."""
        u = self.current_inputs()
        k1 = self._deriv_now(u)
        x = self.x
        vx, vy, vz, wx, wy, wz = x[6:12]
        phi, theta = x[3], x[4]
        from vdps_hil.units import GRAVITY_MPS2 as g
        gb = (-g * math.sin(theta), -g * math.sin(phi) * math.cos(theta), -g * math.cos(phi) * math.cos(theta))
        a = (k1[6] + wy * vz - wz * vy, k1[7] + wz * vx - wx * vz, k1[8] + wx * vy - wy * vx)
        return ImuKinematics(self.t_s, (a[0] - gb[0], a[1] - gb[1], a[2] - gb[2]), (wx, wy, wz),
                             (k1[9], k1[10], k1[11]))

    def snapshot(self) -> dict:
        """The truth snapshot at the current time (see the module docstring)."""
        u = self.current_inputs()
        x = self.x
        xd, d = self.model.evaluate(x, u, self.env)
        pe, pn, pu, phi, theta, psi, vx, vy, vz, wx, wy, wz = x[:12]
        s: dict = {"t_s": self.t_s, "t_ns": self.t_ns, "pos_e_m": pe, "pos_n_m": pn, "pos_u_m": pu}
        env = self.env
        cpr, spr, ctr, str_ = math.cos(env.bank_rad), math.sin(env.bank_rad), math.cos(env.grade_rad), math.sin(env.grade_rad)
        # C_g^r = R(x, phi_r) R(y, theta_r)
        s["pos_r_m_x"] = ctr * pe + str_ * pu
        s["pos_r_m_y"] = spr * str_ * pe + cpr * pn - spr * ctr * pu
        s["pos_r_m_z"] = -cpr * str_ * pe - spr * pn + cpr * ctr * pu
        dpos = xd[0:3]
        s["vel_g_mps_e"], s["vel_g_mps_n"], s["vel_g_mps_u"] = dpos
        s["vel_b_mps_x"], s["vel_b_mps_y"], s["vel_b_mps_z"] = vx, vy, vz
        s["speed_mps"] = math.sqrt(vx * vx + vy * vy + vz * vz)
        s["sideslip_rad"] = math.atan2(vy, abs(vx)) if (abs(vx) + abs(vy)) > 0.1 else 0.0
        s["roll_g_rad"], s["pitch_g_rad"], s["yaw_g_rad"] = phi, theta, (psi + math.pi) % (2 * math.pi) - math.pi
        pv, tv, yv = decompose_vehicle(phi, theta, psi, env.bank_rad, env.grade_rad)
        s["roll_v_rad"], s["pitch_v_rad"], s["yaw_v_rad"] = pv, tv, yv
        # road-relative Euler rates: the road does not rotate, so C_omega^-1(phi_v, theta_v) omega
        cp, sp, ct, st = math.cos(pv), math.sin(pv), math.cos(tv), math.sin(tv)
        s["roll_rate_v_radps"] = wx - st / ct * sp * wy - st / ct * cp * wz
        s["rate_b_radps_x"], s["rate_b_radps_y"], s["rate_b_radps_z"] = wx, wy, wz
        s.update(d)
        for i in range(4):
            s[f"wheel_speed_radps_{i + 1}"] = x[12 + i]
            s[f"brake_torque_nm_{i + 1}"] = u.brake_torque_nm[i]
        s["steer_wheel_angle_rad"] = u.steer_wheel_angle_rad
        s["road_bank_rad"], s["road_grade_rad"] = env.bank_rad, env.grade_rad
        s["ltr"] = snapshot_ltr(s)
        return s

    def _emit_truth(self) -> None:
        s = self.snapshot()
        fz = [s[f"normal_load_n_{i}"] for i in range(1, 5)]
        evs = self.rollover.update(s["t_s"], fz, s["roll_v_rad"], s["roll_rate_v_radps"])
        s["events"] = [e.to_json() for e in evs]
        self._deliver_truth(s)
        if self.stop_at_point_of_no_return and self.rollover.point_of_no_return is not None and not self.stopped:
            self.stopped = True
            self.stop_reason = "point_of_no_return"

    @property
    def events(self) -> list[dict]:
        return [e.to_json() for e in self.rollover.events]
