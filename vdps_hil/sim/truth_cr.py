"""A second, independent truth: CommonRoad's multibody model (``sim.cr_model``) stepped with the
interface of our :class:`~vdps_hil.sim.simulator.Simulator`, so ``sim.drive`` feeds the same
sensor models, wire formats, faults and recordings from it (``vdps sim SCENARIO --truth
commonroad-mb:1``; set 3 likewise).

Range (refused or stopped, never silent)
----------------------------------------
* **Flat road only**: a scenario with bank or grade is refused in one line; with
  ``flat_road=True`` (``vdps sim --flat-road``) it is driven on a level road with a warning in
  ``notes`` (and the summary).
* **No wheel lift-off** in the model: scenarios that stop at the point of no return (the
  rollover scenarios) are refused; a drive stops (``stop_reason = "lift_off_outside_model"``)
  when a normal load reaches zero, beyond which the model's answers mean nothing. No rollover
  events are produced.
* **Effects**: a tire law of ours (``linear_tire``, ``magic_formula_tire``) is replaced by the
  model's own Pacejka tire (noted); other dynamics effects act on our physics core only and are
  refused; measurement effects (``imu_bias``, ``imu_lever_arm``) act in the sensor models as
  with our truth. A scenario's wind is noted as not simulated (no aerodynamics).
* **Low speed**: below 0.1 m/s the package switches to a kinematic model with zero slip; there
  the wheels are made to roll with the body (omega = u / R_w, our low-speed fallback: the
  package would let them spin up on the tire's force offsets). Between 0.1 m/s and a few m/s
  its slip ratio has no speed floor and the wheel modes stiffen as 1/u: sub-stepped (below).
  The vehicle does not reverse (``cr_inputs``). Start scenarios at speed.

Integration
-----------
Our own fixed-step integrator: outer step ``dt_s`` = 1 ms (the sensors' step), Heun's RK2
(default) or classic RK4, inputs held over the step (``cr_inputs``), each outer step split into
n equal sub-steps with n = ceil(dt lambda / c) for the fastest mode (c = 1.4 for RK2, whose
real-axis limit is 2; 2.0 for RK4, limit 2.78)::

    lambda = max(R_w^2 p_kx1 F_z,max / (I_w u),             wheel spin under slip
                 (2 |p_ky1| F_z,max / u + K_rad) / m_u)      unsprung lateral (tire + joint damping)
    F_z,max = 2 x the largest static tire load;  n = 1 in the kinematic branch (|u| < 0.1 m/s)

(set 1 at 25 m/s: lambda = 460 1/s, n = 1; with RK2 n = 2 below 8.2 m/s, 5 at 2 m/s, 83 at
0.1 m/s).
``refine`` multiplies n (step halving). Negative wheel spins are set to zero after each step
(the package forbids them).

Why RK2 at 1 ms (measured, set 1, 25 m/s, 1 Hz steering-wheel sine of 40 deg with +-150 N m
per wheel in phase, 6.7 m/s^2 peak lateral acceleration, 4 s, against RK4 with 4x sub-steps):
RK2 differs by 5.6e-5 m in position, 1.2e-4 deg in attitude, 4.5e-4 m/s^2 in specific force and
2.5e-4 rad/s in wheel spin; halving its step changes these by 1.4e-5 m, 2.9e-5 deg, 1.0e-4 m/s^2
(a ratio of 4: second order, converged). That is two orders below the sensor noise of Table 1
(0.02 m/s^2, 0.08 deg/s, 1 m, 0.4 deg), and RK2 costs about half of RK4 (physics alone 8.6x
against 4.4x real time in CPU seconds, ``tools/bench_truth_cr.py``). ``tests/test_truth_cr.py`` repeats the halving on a lower-speed
circle with stated tolerances.

Conversions (each tested in ``tests/test_truth_cr.py``)
--------------------------------------------------------
The package's states are the sprung CG's position (x1, x2) in its plane, the yaw-frame
velocities (u, v), yaw psi', roll phi', pitch theta' and the sprung-mass vertical position z'
(down). Our truth (``vdps_hil.conventions``)::

    pos_e = x1,  pos_n = -x2,  pos_u = h_s - z'          ENU; the package's x2 points right of x1
    phi = phi',  theta = theta',  psi = -psi'             (roll right-down +, pitch nose-up +: the
                                                          same senses; yaw CCW from East)
    v_g = (dx1/dt, -dx2/dt, -dz'/dt),  dx1/dt = u cos psi' - v sin psi', dx2/dt = u sin psi' + v cos psi'
    a_g = d v_g / dt  from the package's du/dt, dv/dt, d^2 z'/dt^2, dpsi'/dt
    C = C_g^v(phi, theta, psi)  (eq 1, ``model.frames``): v_b = C v_g,  a_b = C a_g,
    f_b = C (a_g - g_g),  g_g = (0, 0, -9.81)             specific force at the sprung CG (IMU)
    omega_b = C_omega(phi, theta) (dphi, dtheta, dpsi)    the package's roll, pitch and yaw
                                                          rates taken as Euler rates (eq 7)
    domega_b/dt = C_omega (d2phi, d2theta, d2psi) + dC_omega/dt (dphi, dtheta, dpsi)

The package treats roll and pitch as small, separate rotations; reading them as our eq 1 Euler
angles is exact to first order and makes the sensors mutually consistent (GNSS position and
velocity, attitude and IMU describe one rigid-body motion). Below 0.1 m/s the package moves the
position with its kinematic slip angle while v_b uses (u, v) (a difference below 0.1 m/s x
beta).

Per wheel (ours 1..4 = FL FR RR RL = the package's LF, RF, RR, LR)::

    wheel_speed_i = omega_i;  slip_ratio_i = -s_i (the package's s = 1 - R_w omega / u_w)
    slip_angle_i = alpha_i (same sense: positive when the wheel slides right, force to the left)
    tire_force_long_i = F_x,i,  tire_force_lat_i = -F_y,i (the package's y points right)
    normal_load_i = F_z,i (may go negative: no lift-off);  road_wheel_angle_1,2 = -delta (no
    Ackermann in the package), 3,4 = 0;  rolling_radius = R_w
    susp_deflection_i = -z_S,i (the package's suspension travel, extension positive, zero at
                        the spring preload = design ride height); rate likewise
    susp_force_i = F_S,i (spring preload + rate + damping + the auxiliary roll stiffness term)
    wheel_torque_i, brake_torque_i: the package's split of m R_w u2 (``cr_inputs``)

The suspension travel (the package's kinematics, written out here since the package keeps it
local to its function)::

    z_S,LF/RF = (h_s - R_w + z_uf - z')/cos phi' - h_s + R_w + a theta' +- (T_f / 2)(phi' - phi_uf)
    z_S,LR/RR = (h_s - R_w + z_ur - z')/cos phi' - h_s + R_w - b theta' +- (T_r / 2)(phi' - phi_ur)
    dz_S,LF/RF = dz_uf - dz' + a dtheta' +- (T_f / 2)(dphi' - dphi_uf), rear likewise with -b

Truth snapshot: every field of ``sim.simulator``'s docstring (flat road: the road frame is the
global frame and the road-relative angles are the absolute ones), plus ``camber_rad_i`` and
``road_wheel_angle_cmd_rad`` (the commanded road-wheel angle, ours: positive left).

Interface used by ``sim.drive`` and ``sim.sensors`` (as :class:`Simulator`): ``n``, ``dt_s``,
``dt_ns``, ``t_s``, ``t_ns``, ``x`` (our 24-state layout, ``model.core.StateLayout``, built from
the package's state), ``model`` (``layout``, ``vehicle``, ``static_load_n``,
``rolling_radius_m``: what the driver and the recorder read), ``env``, ``effects``, ``step()``,
``step_to``, ``run``, ``kinematics()``, ``current_inputs()`` (the inputs as applied to the
wheels: the steering-wheel angle of the road wheels' actual angle, the package's per-wheel net
torques, no separate brake), ``commanded_inputs()`` (schedule or driver, then the override),
``set_input_override``, ``add_step_hook``, ``snapshot()``, ``truth``, ``stopped``,
``stop_reason``, ``events`` (empty).

Symbols as in ``sim.cr_model``; primes mark the package's axes (SAE: x forward, y right, z down).
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

from vdps_hil.model.core import Env, Inputs
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import ImuKinematics

from .cr_convert import (KINEMATIC_SPEED_MPS, ModelView, TruthRangeError, body_kinematics, check_scenario,
                         suspension_travel, trim_state)
from .cr_inputs import CrInputs, InputMapping
from .stepping import FixedStepTruth, InputSource, SimulationError, rk_step, snapshot_ltr
from .cr_model import (CR_GRAVITY_MPS2, CrParameterError, TireProbe, load_parameters, mb_rhs, truth_figures, truth_vehicle)

__all__ = ["CommonRoadTruth", "CommonRoadBackend", "MAX_SUBSTEPS"]

MAX_SUBSTEPS = 200
"""Cap on the sub-steps of one outer step."""
_STEP_FACTOR = {"rk4": 2.0, "rk2": 1.4}
"""c of n = ceil(dt lambda / c): dt lambda per sub-step (module docstring)."""
_OURS_FROM_CR = (0, 1, 3, 2)
"""Our wheel i (0-based FL FR RR RL) -> the package's wheel index (LF RF LR RR)."""


class CommonRoadTruth(FixedStepTruth):
    """A steppable truth on CommonRoad's multibody model with :class:`Simulator`'s interface
    (module docstring).

    Parameters: ``set_id`` (1 or 3), ``scenario`` (initial state, inputs or driver, duration;
    checked against the range), ``effects`` (default: the scenario's; tire laws are replaced,
    measurement effects kept), ``inputs`` (an Inputs or ``source(t, x) -> Inputs`` instead of the
    scenario's), ``initial_speed_mps``, ``dt_s`` (outer step, <= 1 ms, dividing 10 ms),
    ``integrator`` ("rk2" or "rk4"), ``refine`` (sub-step multiplier), ``flat_road``,
    ``record_truth``, ``on_truth``, ``duration_s``, ``sign_width_rad``, ``mirror_combined`` and
    ``lateral_law`` (``cr_model.mb_rhs``; the defaults are the truth backend's)."""

    def __init__(self, set_id: int, scenario=None, effects: EffectSet | None = None, *,
                 inputs: Inputs | InputSource | None = None, initial_speed_mps: float | None = None,
                 dt_s: float = 1e-3, integrator: str = "rk2", refine: int = 1, flat_road: bool = False,
                 truth_rate_hz: float = 100.0, record_truth: bool = True,
                 on_truth: Callable[[dict], None] | None = None, duration_s: float | None = None,
                 sign_width_rad: float | None = None, mirror_combined: bool = True, lateral_law: str = "pacejka"):
        self.set_id = int(set_id)
        self.p = p = load_parameters(self.set_id)
        self.vehicle = truth_vehicle(self.set_id)
        self.figures = truth_figures(self.set_id)
        self.scenario = scenario
        if effects is None:
            effects = scenario.effect_set(self.vehicle) if scenario is not None else EffectSet()
        self.effects, self.notes = check_scenario(scenario, effects, flat_road)
        self.env = Env()
        self.model = ModelView(self.vehicle, self.figures)
        self._init_clock(dt_s, truth_rate_hz, integrator)
        if not (isinstance(refine, int) and refine >= 1):
            raise SimulationError(f"refine must be an integer >= 1, got {refine!r}")
        self.refine = refine
        kw = {"mirror_combined": mirror_combined, "lateral_law": lateral_law}
        self.lateral_law = lateral_law
        if sign_width_rad is not None:
            kw["sign_width_rad"] = sign_width_rad
        self._rhs = mb_rhs(**kw)
        self._probe = TireProbe()
        self._rhs_probe = mb_rhs(probe=self._probe, **kw)
        self.mapping = InputMapping(p, self.vehicle.geometry.steer_ratio)
        # stiffness bound for the sub-steps (module docstring)
        fz_max = 2.0 * max(self.model.static_load_n)
        self._lam_w = p.R_w ** 2 * p.tire.p_kx1 * fz_max / p.I_y_w
        self._lam_lat = (2.0 * abs(p.tire.p_ky1) * fz_max, p.K_rad, min(p.m_uf, p.m_ur))
        self._step_factor = _STEP_FACTOR[integrator]
        self._init_inputs(inputs, scenario, self.model, self.env)
        # initial state
        speed = initial_speed_mps
        heading = east = north = 0.0
        if scenario is not None:
            speed = scenario.initial_speed_mps if speed is None else speed
            heading, east, north = scenario.initial_heading_rad, scenario.initial_east_m, scenario.initial_north_m
        self.xc = trim_state(p, float(speed or 0.0), heading, east, north, rhs=self._rhs)
        self.n = 0
        self.duration_s = duration_s if duration_s is not None else (scenario.duration_s if scenario is not None else None)
        self.stopped = False
        self.stop_reason = ""
        self.record_truth = record_truth
        self.truth: list[dict] = []
        self._on_truth = on_truth
        self._step_hooks: list[Callable] = []
        self.steer_rate_limited_steps = 0
        self.accel_limited_steps = 0
        self.steer_lag_max_rad = 0.0  # largest |delta - delta_cmd| at a step's end (road wheels)
        self.max_substeps = 1
        self._cache_n = -1
        self._cmd = self._ci = self._applied = self._k1 = self._view = None
        self._emit_truth()

    # ------------------------------------------------------------------ state
    def _fresh(self) -> None:
        if self._cache_n != self.n:
            self._cache_n = self.n
            self._cmd = self._ci = self._applied = self._k1 = self._view = None

    @property
    def x(self) -> list[float]:
        """Our 24-state layout (``model.core.StateLayout(True)``) built from the package's state."""
        self._fresh()
        if self._view is None:
            xc, p = self.xc, self.p
            bk = body_kinematics(xc, None, p.h_s)
            z, dz = suspension_travel(xc, p)
            m = _OURS_FROM_CR
            self._view = [*bk["pos_g"], *bk["euler"], *bk["vel_b"], *bk["rate_b"],
                          *(xc[23 + m[i]] for i in range(4)), *(-z[m[i]] for i in range(4)),
                          *(-dz[m[i]] for i in range(4))]
        return self._view

    @property
    def state(self) -> list[float]:
        return list(self.x)

    # ------------------------------------------------------------------ inputs
    def set_input_override(self, override) -> None:
        """As :meth:`Simulator.set_input_override`: acts on the commanded inputs from the next step."""
        self._override = override
        self._cache_n = -1

    def commanded_inputs(self) -> Inputs:
        """The schedule's or driver's inputs for the step starting now, after the override."""
        self._fresh()
        if self._cmd is None:
            u = self._source(self.t_s, self.x)
            ov = self._override
            if ov is not None:
                u = ov if isinstance(ov, Inputs) else ov(self.t_s, u)
            self._cmd = u
        return self._cmd

    def cr_inputs(self) -> CrInputs:
        """The package's inputs for the step starting now (``cr_inputs``)."""
        self._fresh()
        if self._ci is None:
            xc = self.xc
            spins = tuple(xc[23 + k] for k in _OURS_FROM_CR)
            self._ci = self.mapping.map(self.commanded_inputs(), xc[2], xc[3], spins, self.dt_s)
        return self._ci

    def steer_wheel_angle_rad(self) -> float:
        """The steering-wheel angle of the road wheels' angle now (our sense: the package's delta
        is right-positive, ``cr_inputs.InputMapping``: delta_cmd = -angle / ratio)."""
        return -float(self.xc[2]) * self.mapping.steer_ratio

    def current_inputs(self) -> Inputs:
        """The inputs as applied over the step starting now: the steering-wheel angle of the road
        wheels' actual angle (delta times the steering ratio: the column is linked to the rack, so
        when the package's steering-rate limit holds the road wheels back, the column's angle
        sensor lags the command with them) and the package's net torque per wheel (brakes
        included, so no separate brake torque)."""
        self._fresh()
        if self._applied is None:
            ci = self.cr_inputs()
            u = object.__new__(Inputs)
            object.__setattr__(u, "steer_wheel_angle_rad", self.steer_wheel_angle_rad())
            object.__setattr__(u, "wheel_torque_nm", ci.wheel_torque_nm)
            object.__setattr__(u, "brake_torque_nm", (0.0, 0.0, 0.0, 0.0))
            self._applied = u
        return self._applied

    # ------------------------------------------------------------------ dynamics
    def derivative(self, xc: Sequence[float], u: Sequence[float], probe: bool = False) -> list[float]:
        """The package's x_dot (re-bound, ``cr_model``) with our low-speed wheel fallback."""
        xd = (self._rhs_probe if probe else self._rhs)(list(xc), list(u), self.p)
        if abs(xc[3]) < KINEMATIC_SPEED_MPS:
            w = xd[3] / self.p.R_w
            xd[23] = xd[24] = xd[25] = xd[26] = w
        return xd

    def _deriv_now(self) -> list[float]:
        self._fresh()
        if self._k1 is None:
            self._k1 = self.derivative(self.xc, self.cr_inputs().u)
        return self._k1

    def substeps(self, speed_mps: float) -> int:
        """Sub-steps of one outer step at the package's speed u (module docstring)."""
        if abs(speed_mps) < KINEMATIC_SPEED_MPS:  # kinematic branch: no slip, no slip stiffness
            return self.refine
        us = abs(speed_mps)
        ck, krad, mu = self._lam_lat
        lam = max(self._lam_w / us, (ck / us + krad) / mu)
        n = math.ceil(self.dt_s * lam / self._step_factor)
        return max(1, min(MAX_SUBSTEPS, n)) * self.refine

    def step(self) -> bool:
        """One outer step; False when stopped."""
        if self.stopped:
            return False
        ci = self.cr_inputs()
        u = ci.u
        self.steer_rate_limited_steps += ci.steer_limited
        self.accel_limited_steps += ci.accel_limited
        x = self.xc
        n_sub = self.substeps(x[3])
        self.max_substeps = max(self.max_substeps, n_sub)
        h = self.dt_s / n_sub
        deriv = self.derivative

        def f(xs):
            return deriv(xs, u)
        k1 = self._deriv_now()
        for j in range(n_sub):
            x = rk_step(f, x, k1 if j == 0 else f(x), h, self.integrator)
            for k in range(23, 27):
                if x[k] < 0.0:
                    x[k] = 0.0
        self.xc = x
        self.steer_lag_max_rad = max(self.steer_lag_max_rad, abs(x[2] - ci.road_wheel_angle_cmd_rad))
        self.n += 1
        if not all(math.isfinite(v) for v in x):
            self.stopped = True
            self.stop_reason = "non-finite state"
            raise SimulationError(f"CommonRoad truth: non-finite state at t = {self.t_s:.3f} s")
        return self._after_step()

    # ------------------------------------------------------------------ truth
    def kinematics(self) -> ImuKinematics:
        """Specific force at the sprung CG, body rates and angular acceleration (body axes) now."""
        bk = body_kinematics(self.xc, self._deriv_now(), self.p.h_s)
        return ImuKinematics(self.t_s, bk["specific_force_b"], bk["rate_b"], bk["angular_accel_b"])

    def snapshot(self) -> dict:
        """The truth snapshot now (``sim.simulator``'s fields; module docstring)."""
        p, xc = self.p, self.xc
        ci = self.cr_inputs()
        self._probe.clear()
        xd = self.derivative(xc, ci.u, probe=True)
        calls = self._probe.calls
        bk = body_kinematics(xc, xd, p.h_s)
        s: dict = {"t_s": self.t_s, "t_ns": self.t_ns}
        for k, ax in enumerate("enu"):
            s[f"pos_{ax}_m"] = bk["pos_g"][k]
            s[f"vel_g_mps_{ax}"] = bk["vel_g"][k]
        for k, ax in enumerate("xyz"):
            s[f"pos_r_m_{ax}"] = bk["pos_g"][k]
        for k, ax in enumerate("xyz"):
            s[f"vel_b_mps_{ax}"] = bk["vel_b"][k]
            s[f"rate_b_radps_{ax}"] = bk["rate_b"][k]
            s[f"angular_accel_b_radps2_{ax}"] = bk["angular_accel_b"][k]
            s[f"accel_b_mps2_{ax}"] = bk["accel_b"][k]
            s[f"specific_force_b_mps2_{ax}"] = bk["specific_force_b"][k]
        vx, vy, vz = bk["vel_b"]
        s["speed_mps"] = math.sqrt(vx * vx + vy * vy + vz * vz)
        s["sideslip_rad"] = math.atan2(vy, abs(vx)) if (abs(vx) + abs(vy)) > 0.1 else 0.0
        phi, theta, psi = bk["euler"]
        psi_w = (psi + math.pi) % (2 * math.pi) - math.pi
        s["roll_g_rad"], s["pitch_g_rad"], s["yaw_g_rad"] = phi, theta, psi_w
        s["roll_v_rad"], s["pitch_v_rad"], s["yaw_v_rad"] = phi, theta, psi_w
        s["roll_rate_v_radps"] = bk["euler_rate"][0]
        z, dz = suspension_travel(xc, p)
        # suspension forces (the package's F_S: preload - rate - damping + auxiliary roll term)
        L, g = p.a + p.b, CR_GRAVITY_MPS2
        pre = (p.m_s * g * p.b / (2 * L), p.m_s * g * p.b / (2 * L), p.m_s * g * p.a / (2 * L), p.m_s * g * p.a / (2 * L))
        kz = (p.K_sf, p.K_sf, p.K_sr, p.K_sr)
        kd = (p.K_sdf, p.K_sdf, p.K_sdr, p.K_sdr)
        aux = ((xc[6] - xc[13]) * p.K_tsf / p.T_f, -(xc[6] - xc[13]) * p.K_tsf / p.T_f,
               (xc[6] - xc[18]) * p.K_tsr / p.T_r, -(xc[6] - xc[18]) * p.K_tsr / p.T_r)
        delta = xc[2]
        for i, c in enumerate(_OURS_FROM_CR):
            w = i + 1
            (s_c, gamma, fz, _), _r = calls["formula_longitudinal"][c]
            (alpha, _, _, _), _r = calls["formula_lateral"][c]
            s[f"wheel_speed_radps_{w}"] = xc[23 + c]
            s[f"slip_ratio_{w}"] = -s_c
            s[f"slip_angle_rad_{w}"] = alpha
            s[f"tire_force_long_n_{w}"] = calls["formula_longitudinal_comb"][c][1]
            s[f"tire_force_lat_n_{w}"] = -calls["formula_lateral_comb"][c][1]
            s[f"normal_load_n_{w}"] = fz
            s[f"camber_rad_{w}"] = gamma
            s[f"susp_deflection_m_{w}"] = -z[c]
            s[f"susp_deflection_rate_mps_{w}"] = -dz[c]
            s[f"susp_force_n_{w}"] = pre[c] - z[c] * kz[c] - dz[c] * kd[c] + aux[c]
            s[f"road_wheel_angle_rad_{w}"] = -delta if i < 2 else 0.0
            s[f"rolling_radius_m_{w}"] = p.R_w
            s[f"wheel_torque_nm_{w}"] = ci.wheel_torque_nm[i]
            s[f"brake_torque_nm_{w}"] = ci.brake_torque_nm[i]
        s["steer_wheel_angle_rad"] = self.steer_wheel_angle_rad()
        s["steer_wheel_angle_cmd_rad"] = self.commanded_inputs().steer_wheel_angle_rad
        s["road_wheel_angle_cmd_rad"] = -ci.road_wheel_angle_cmd_rad
        s["road_bank_rad"] = s["road_grade_rad"] = 0.0
        s["ltr"] = snapshot_ltr(s)
        return s

    def _emit_truth(self) -> None:
        s = self.snapshot()
        s["events"] = []
        self._deliver_truth(s)
        if min(s[f"normal_load_n_{i}"] for i in range(1, 5)) <= 0.0 and not self.stopped:
            self.stopped = True
            self.stop_reason = "lift_off_outside_model"

    @property
    def events(self) -> list[dict]:
        return []


LINEAR_LATERAL = "linear-lateral"
"""The variant suffix of ``commonroad-mb:N:linear-lateral`` (``cr_model.linear_lateral``)."""


class CommonRoadBackend:
    """The ``commonroad-mb:N`` truth backend of ``vdps sim`` (``sim.truth_backends``): parameter
    set N in (1, 3); ``flat_road`` drives a banked or graded scenario on a level road.
    ``commonroad-mb:N:linear-lateral`` is the same vehicle with the tires' lateral law linear
    (no saturation; ``cr_model`` change 4), for measuring what saturation costs a model."""

    name = "commonroad-mb"

    def __init__(self, arg: str, *, flat_road: bool = False):
        text, _, variant = str(arg).strip().partition(":")
        if not text.isdigit():
            raise CrParameterError(f"commonroad-mb needs a parameter set number (commonroad-mb:1 or "
                                   f"commonroad-mb:3), got {arg!r}")
        if variant not in ("", LINEAR_LATERAL):
            raise CrParameterError(f"commonroad-mb:{text}: unknown variant {variant!r} (known: {LINEAR_LATERAL})")
        load_parameters(int(text))  # refuses the reserved and unknown sets before anything else
        self.set_id = int(text)
        self.lateral_law = "linear" if variant else "pacejka"
        self.flat_road = bool(flat_road)
        self.vehicle = truth_vehicle(self.set_id)
        self.notes: list[str] = []

    @property
    def spec(self) -> str:
        return f"{self.name}:{self.set_id}" + (f":{LINEAR_LATERAL}" if self.lateral_law == "linear" else "")

    def prepare(self, scenario, effects: EffectSet) -> tuple[EffectSet, list[str]]:
        """Check the scenario and effects now (one-line TruthRangeError); the kept effects and notes."""
        kept, self.notes = check_scenario(scenario, effects, self.flat_road)
        return kept, list(self.notes)

    def simulator(self, scenario, effects: EffectSet, **kw) -> CommonRoadTruth:
        return CommonRoadTruth(self.set_id, scenario, effects, flat_road=self.flat_road, lateral_law=self.lateral_law,
                               **kw)

    def describe(self, sim: CommonRoadTruth | None = None) -> dict:
        from .cr_model import CAMBER_SIGN_WIDTH_RAD, package_version
        d = {"backend": self.spec, "package": "commonroad-vehicle-models", "package_version": package_version(),
             "parameter_set": self.set_id, "camber_sign_width_rad": CAMBER_SIGN_WIDTH_RAD,
             "combined_slip": "mirror-symmetric part", "lateral_law": self.lateral_law, "flat_road": self.flat_road,
             "steer_ratio": self.vehicle.geometry.steer_ratio, "notes": list(self.notes)}
        if sim is not None:
            d["notes"] += [n for n in sim.notes if n not in d["notes"]]
            d.update(integrator=sim.integrator, dt_s=sim.dt_s,
                     steer_rate_limited_steps=sim.steer_rate_limited_steps,
                     steer_lag_max_rad=sim.steer_lag_max_rad,
                     accel_limited_steps=sim.accel_limited_steps, max_substeps=sim.max_substeps)
        return d
