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

import numpy as np

from vdps_hil import jit
from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import ImuKinematics
from vdps_hil.model.frames import dcm_global_to_road, dcm_global_to_vehicle, euler_ypr_from_dcm
from vdps_hil.model.params import Vehicle, load_vehicle

from vdps_hil.model.rollover import RolloverMonitor
from vdps_hil.model.core_kernel import N_DIAG
from vdps_hil.units import GRAVITY_MPS2, NS_PER_S

from .step_kernel import N_REC, record_row, truth_steps
from .step_kernel import rk_step as rk_step_kernel
from .stepping import FixedStepTruth, InputSource, SimulationError, input_row, rk_step, snapshot_ltr

_NO_ARRAY = np.empty(0)
_LOAD_KEYS = tuple(f"normal_load_n_{i}" for i in range(1, 5))
_WHEEL_KEYS = tuple((f"wheel_speed_radps_{i}", f"brake_torque_nm_{i}") for i in range(1, 5))


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
        self._road_t = dcm_global_to_road(self.env.bank_rad, self.env.grade_rad, 0.0).T  # (C_g^r)^T, eq 4
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
        self._init_compiled(integrator)
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
        self._recorder = None  # a StepRecorder whose rows the compiled steps write
        self._emit_truth()

    def _init_compiled(self, integrator: str) -> None:
        """The compiled core's arrays, or ``_compiled = False`` (module docstring)."""
        arrays = self.model.kernel_arrays
        self._compiled = arrays is not None and jit.ENABLED
        self._rk4 = integrator == "rk4"
        if self._compiled:
            self._K, self._C, self._E = arrays
            self._S = np.empty((4, 15))
            self._env_a = np.array((*self.env.normal_g, *self.env.wind_enu_mps))
            self._k1a = np.empty(self.model.layout.size)
            self._k1_key = None  # (n, u) the array k1a holds f for
            self._ua_key, self._ua = None, None
            self._diag = None  # (n, u, D): diagnostics of the state at a truth instant

    # ------------------------------------------------------------------ state
    @property
    def x(self) -> list[float]:
        """The state vector (a list; with the compiled core a view of ``self._xa``)."""
        if self._xl is None:
            self._xl = self._xa.tolist()
        return self._xl

    @x.setter
    def x(self, value) -> None:
        self._xl = [float(v) for v in value]
        self._xa = np.array(self._xl, dtype=float)
        self._k1 = self._k1_key = None

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
    def _deriv_now(self, u: Inputs):
        """f(x, u) at the current state (cached per step and inputs)."""
        if self._compiled:
            if self._k1_key is None or self._k1_key[0] != self.n or self._k1_key[1] is not u:
                record_row(self._xa, self._k1a, self._u_array(u), self.n, self._env_a, self._K, self._C, self._E,
                           self._S, _NO_ARRAY, _NO_ARRAY)
                self._k1_key = (self.n, u)
            return self._k1a
        k = self._k1
        if k is not None and k[0] == self.n and k[1] is u:
            return k[2]
        k1 = self.model.f(self.x, u, self.env)
        self._k1 = (self.n, u, k1)
        return k1

    def _u_array(self, u: Inputs) -> np.ndarray:
        if u is not self._ua_key:
            self._ua_key, self._ua = u, np.array(input_row(u))
        return self._ua

    def step(self) -> bool:
        """One integration step; False when stopped."""
        if self.stopped:
            return False
        u = self.current_inputs()
        if self._compiled:
            self._deriv_now(u)
            ok = rk_step_kernel(self._xa, self._k1a, self._u_array(u), self.dt_s, self._rk4, self._env_a, self._K,
                                self._C, self._E, self._S)
            self._xl = self._k1_key = None
            self.n += 1
            if not ok:
                self._non_finite()
            if self._recorder is not None:
                self._record_now()
            return self._after_step()
        f, env = self.model.f, self.env
        xn = rk_step(lambda x: f(x, u, env), self.x, self._deriv_now(u), self.dt_s, self.integrator)
        self.x = xn
        self.n += 1
        if not math.isfinite(xn[6] + xn[9] + xn[12]):
            self._non_finite()
        return self._after_step()

    def _non_finite(self) -> None:
        self.stopped = True
        self.stop_reason = "non-finite state"
        raise SimulationError(f"non-finite state at t = {self.t_s:.3f} s")

    # ------------------------------------------------------------------ compiled stepping
    def attach_recorder(self, recorder) -> bool:
        """Let the compiled steps write ``recorder``'s rows (``sampling.StepRecorder``), starting
        with the row of the current step; False (use a step hook) without the compiled core."""
        if not self._compiled:
            return False
        self._recorder = recorder
        self._record_now()
        return True

    def _record_now(self) -> None:
        """The recorder's row of the current step (and f there under the current inputs; with
        the diagnostics a truth snapshot will use when one is due)."""
        u = self.current_inputs()
        D = np.empty(N_DIAG) if self.n % self._truth_every == 0 else _NO_ARRAY
        record_row(self._xa, self._k1a, self._u_array(u), self.n, self._env_a, self._K, self._C, self._E, self._S,
                   self._recorder.reserve(1)[0], D)
        self._recorder.commit(1)
        self._k1_key = (self.n, u)
        if D.size:
            self._diag = (self.n, u, D)

    def _chunkable(self) -> bool:
        ov = self._override
        return (self._compiled and self._time_only and self._source is self._time_source and not self._step_hooks
                and (ov is None or isinstance(ov, Inputs)))

    def _columns_ahead(self, n0: int, m: int) -> list[list[float]]:
        """The 9 input channels of steps n0 + 1 .. n0 + m from the open-loop source
        (``_chunkable``) or the held override."""
        ov = self._override
        if ov is not None:
            return [[v] * m for v in input_row(ov)]
        dt, ns = self.dt_ns, NS_PER_S
        return self._time_columns([(n0 + j) * dt / ns for j in range(1, m + 1)])

    def step_n(self, n_target: int) -> int:
        """Step to step count ``n_target`` (or until stopped); returns the step count reached.
        Open-loop inputs: up to one truth period per compiled call (module docstring)."""
        every = self._truth_every
        while self.n < n_target and not self.stopped:
            if not self._chunkable():
                self.step()
                continue
            n0 = self.n
            m = min(n_target - n0, every - n0 % every)
            u0 = self.current_inputs()
            self._deriv_now(u0)
            cols = self._columns_ahead(n0, m)
            U = np.empty((m + 1, 9))
            U[0] = self._u_array(u0)
            for c, col in enumerate(cols):
                U[1:, c] = col
            rec = self._recorder.reserve(m) if self._recorder is not None else _NO_ARRAY.reshape(0, N_REC)
            D = np.empty(N_DIAG) if (n0 + m) % every == 0 else _NO_ARRAY
            done = truth_steps(self._xa, self._k1a, U, m, self.dt_s, self._rk4, self._env_a, self._K, self._C,
                               self._E, rec, n0, D)
            if self._recorder is not None:
                self._recorder.commit(done)
            self.n = n0 + done
            self._xl = None
            r = [col[done - 1] for col in cols]
            u = self._override if self._override is not None else Inputs(r[0], r[1:5], r[5:9])
            self._u, self._u_n = u, self.n
            self._k1_key = (self.n, u)
            if done < m:
                self._non_finite()
            if D.size:
                self._diag = (self.n, u, D)
            self._after_step()
        return self.n

    # ------------------------------------------------------------------ truth
    def kinematics(self) -> ImuKinematics:
        """Specific force at the CG, body rates and angular acceleration (body axes) now."""
        u = self.current_inputs()
        k1 = self._deriv_now(u)
        x = self.x
        vx, vy, vz, wx, wy, wz = x[6:12]
        phi, theta = x[3], x[4]
        g = GRAVITY_MPS2
        gb = (-g * math.sin(theta), -g * math.sin(phi) * math.cos(theta), -g * math.cos(phi) * math.cos(theta))
        a = (k1[6] + wy * vz - wz * vy, k1[7] + wz * vx - wx * vz, k1[8] + wx * vy - wy * vx)
        return ImuKinematics(self.t_s, (a[0] - gb[0], a[1] - gb[1], a[2] - gb[2]), (wx, wy, wz),
                             (k1[9], k1[10], k1[11]))

    def snapshot(self) -> dict:
        """The truth snapshot at the current time (see the module docstring)."""
        u = self.current_inputs()
        x = self.x
        dg = self._diag if self._compiled else None
        if dg is not None and dg[0] == self.n and dg[1] is u:
            xd, d = self.model.evaluate_from(x, self._deriv_now(u).tolist(), dg[2], self.env)
        else:
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
        pv, tv, yv = euler_ypr_from_dcm(dcm_global_to_vehicle(phi, theta, psi) @ self._road_t)  # decompose_vehicle
        s["roll_v_rad"], s["pitch_v_rad"], s["yaw_v_rad"] = pv, tv, yv
        # road-relative Euler rates: the road does not rotate, so C_omega^-1(phi_v, theta_v) omega
        cp, sp, ct, st = math.cos(pv), math.sin(pv), math.cos(tv), math.sin(tv)
        s["roll_rate_v_radps"] = wx - st / ct * sp * wy - st / ct * cp * wz
        s["rate_b_radps_x"], s["rate_b_radps_y"], s["rate_b_radps_z"] = wx, wy, wz
        s.update(d)
        for i, (kw, kb) in enumerate(_WHEEL_KEYS):
            s[kw] = x[12 + i]
            s[kb] = u.brake_torque_nm[i]
        s["steer_wheel_angle_rad"] = u.steer_wheel_angle_rad
        s["road_bank_rad"], s["road_grade_rad"] = env.bank_rad, env.grade_rad
        s["ltr"] = snapshot_ltr(s)
        return s

    def _emit_truth(self) -> None:
        s = self.snapshot()
        fz = [s[k] for k in _LOAD_KEYS]
        evs = self.rollover.update(s["t_s"], fz, s["roll_v_rad"], s["roll_rate_v_radps"])
        s["events"] = [e.to_json() for e in evs]
        self._deliver_truth(s)
        if self.stop_at_point_of_no_return and self.rollover.point_of_no_return is not None and not self.stopped:
            self.stopped = True
            self.stop_reason = "point_of_no_return"

    @property
    def events(self) -> list[dict]:
        return [e.to_json() for e in self.rollover.events]
