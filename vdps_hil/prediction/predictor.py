"""The 6-DOF predictor: the paper's eq 13-16 model propagated from the estimated state at t0
(paper section 6, Figure 2) on the shared physics core.

What is propagated
------------------
``Model(model_vehicle.with_params(identified), EffectSet([LinearTire()]), unsprung_dof=False)``
(:mod:`vdps_hil.model.core`): the paper's reduced model (rigid tires, eq 14 normal loads, eq 15
linear tires, eq 16 axes, Ackermann steering), 16 states: sprung CG position (ENU), absolute
Euler angles (eq 1), body velocity, body rates, four wheel spins. The effect set is
configurable (``effects`` in the config, or an :class:`EffectSet`) so the workbench can add
effects; the paper's is ``linear_tire`` alone.

Inputs over the horizon
-----------------------
* **held** (the warning path, as in the paper, section 7.3): steering wheel angle, drive and brake
  torques held at their last values before t0 (``PredictorInitialState.inputs``);
* **input-driven** (the workbench): a callable ``u(t_rel_s) -> Inputs`` or an
  :class:`InputTrajectory` of recorded samples (linear interpolation, held beyond its ends).

Either way the inputs are sampled at the start of each step and held over it (zero-order hold,
as the truth simulator does).

Initial state (only data before t0: the estimator's outputs)
------------------------------------------------------------
From a :class:`PredictorInitialState` (ENU position p_g, ENU velocity v_g, absolute Euler angles,
road bank phi_r and grade theta_r, body rates omega, wheel spins, suspension deflections H_i and
rates H_dot_i)::

    env       = road plane (phi_r, theta_r) through the origin of the predictor's own frame
    v_b       = C_g^v v_g                                                     (eq 1)
    n_b       = C_r^v e_z = (sin theta_v, sin phi_v cos theta_v, cos phi_v cos theta_v)

The reduced model has no suspension DOF: H_i follows from the body pose over the road,
``H_i = r - h - n_b . r_w,i`` (r rolling radius, h CG height over the road along n, r_w,i the
wheel centre at design ride height in body axes). ``pose_source`` chooses how the body is placed:

* ``"suspension"`` (default): with finite H_i, the CG height h and the road-relative roll/pitch
  are the least-squares inverse of that relation (eq 5 with the model's own geometry; exact for
  four consistent corners)::

    r - H_i = c + n_x x_i + n_y y_i,   c = h + n_z z_w     ->  theta_v = asin n_x,
                                                              phi_v = asin(n_y / cos theta_v)

  and the CG velocity along the road normal from the suspension rates,
  ``n . v_b = -mean_i (H_dot_i + n . (omega x r_w,i))``; the yaw psi_v (eq 4) and the in-plane
  velocity come from the estimate. Without suspension data: as ``"estimate"``.
* ``"estimate"``: attitude and velocity from the estimate, h = the design CG height (the
  estimator's vertical position is not referred to the road: its origin is the first GNSS fix).
* ``"estimate_plane"``: attitude and velocity from the estimate, h = n_g . p_g (the road plane
  through the global origin: true in the simulator, and the assumption of the EKF's
  ``y2_sus_plane`` form). With ``unsprung_dof`` (a workbench variant, not the paper's) H_i and
  H_dot_i become the suspension states and the pose is placed as here or as ``"estimate"``.

The predicted positions are shifted by the constant offset that puts the prediction's t0
position on the estimated one, so ``pos_g_m[0]`` equals the estimate.

Integration: the stiff wheel spin makes explicit RK2 need ~1 ms steps; the default ``ros2``
(a Rosenbrock W-method, linearly implicit in the four wheel spins) takes 10 ms steps at the
same accuracy: :mod:`vdps_hil.prediction.integration` (equations, measured errors).

Evaluation of the core: with the paper's model and effect set (reduced model, ``linear_tire``
alone or with static rolling-radius factors; any chassis parts of ``model.chassis``) the steps call
:class:`vdps_hil.model.reduced.ReducedLinearCore` -- the same equations as ``Model.f``
specialised once per model and per input value, with the wheel-spin Jacobian in closed form
(equal to the forward difference of ``Model.f``) -- instead of the generic ``Model.f``. Same
trajectory to rounding (3e-13 m, 2e-13 deg; ``tests/test_predictor.py``); 14.6 -> 6.6-7.3 ms per
5 s prediction (``tools/bench_predictor.py``). Every other effect set, the ``unsprung_dof``
variant and ``Predictor(..., fast=False)`` take the generic path.

Stop conditions: the horizon, the predicted point of no return (``model.rollover`` definition,
applied to the predicted trajectory; with ``stop_at_point_of_no_return``), |phi_v| > 85 deg or a
non-finite state.

Symbols and units
-----------------
==============  ================================================================  =========
symbol          meaning                                                           unit
==============  ================================================================  =========
t0              time of the estimate the prediction starts from                   ns
h               integration step (``step_s``)                                     s
T               horizon (``horizon_s``)                                           s
p_g, v_g        CG position / velocity, ENU                                       m, m/s
phi, theta, psi absolute (g) or road-relative (v) roll, pitch, yaw (eq 1-4)       rad
phi_r, theta_r  road bank, grade (eq 2)                                           rad
omega           body rates (p, q, r)                                              rad/s
omega_i         wheel spin, i = 1..4 FL FR RR RL                                  rad/s
H_i, H_dot_i    suspension deflection (compression +) and its rate                m, m/s
F_z,i           normal load (eq 14)                                               N
==============  ================================================================  =========
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectConfigError, EffectSet, effects_from_names
from vdps_hil.model.frames import compose_absolute, decompose_vehicle, dcm_global_to_vehicle
from vdps_hil.model.params import IdentifiedParams, Vehicle
from vdps_hil.model.reduced import ReducedLinearCore
from vdps_hil.model.reduced import supports as reduced_supports
from vdps_hil.model.rollover import RolloverMonitor
from vdps_hil.units import NS_PER_S

from .config import PredictionConfigError, PredictorConfig
from .initial_state import InputSource, InputTrajectory, PredictorInitialState
from .integration import propagate_generic, propagate_reduced
from .result import PredictionResult, build_result


class Predictor:
    """``Predictor(model_vehicle, config).predict(initial_state, inputs=None) -> PredictionResult``.

    ``model_vehicle``: a *model* vehicle file (``load_vehicle("sedan-model")``), usually with the
    identified parameters: ``vehicle.with_params(**identifier.params.as_dict())`` or
    ``predictor.with_params(identified)``. A truth file is refused (the predictor never reads
    truth). ``effects``: an EffectSet replacing the config's effect names (the workbench)."""

    def __init__(self, vehicle: Vehicle, config: PredictorConfig | None = None,
                 effects: EffectSet | None = None, *, fast: bool = True):
        if vehicle.kind != "model":
            raise ValueError(f"the predictor takes a model vehicle file, not a {vehicle.kind!r} file")
        self.config = config or PredictorConfig()
        if effects is None:
            try:
                effects = effects_from_names(self.config.effects, {}, self.config.effect_params)
            except EffectConfigError as e:
                raise PredictionConfigError(f"predictor.effects: {e}") from None
        self.effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
        self.vehicle = vehicle
        self.model = Model(vehicle, self.effects.dynamics, unsprung_dof=self.config.unsprung_dof,
                           slip_speed_floor_mps=self.config.slip_speed_floor_mps)
        cfg = self.config
        if cfg.integrator == "rk2":
            limit = self.model.max_stable_step_s * 2.0 / 2.78
            if cfg.step_s > limit:
                raise PredictionConfigError(
                    f"predictor.step_s {cfg.step_s} s exceeds the explicit RK2 stability limit {limit:.2e} s "
                    "of the wheel-spin mode; use integrator = \"ros2\" or a smaller step")
        geo = vehicle.geometry
        self._track_half_m = 0.5 * (geo.track_half_front_m + geo.track_half_rear_m)
        self.reduced_core = ReducedLinearCore(self.model) if fast and reduced_supports(self.model) else None
        """The specialised evaluation of the same core (:mod:`vdps_hil.model.reduced`) when the
        model allows it (the paper's reduced model and effect set) and ``fast``; else None and
        every step calls ``model.f`` (the generic path, also the reference of the fast one)."""

    # ----------------------------------------------------------------- construction helpers
    def with_params(self, params: IdentifiedParams | Mapping[str, float]) -> "Predictor":
        """A new predictor with the identified parameters (never mutates this one)."""
        d = params.as_dict() if isinstance(params, IdentifiedParams) else dict(params)
        return Predictor(self.vehicle.with_params(**d), self.config, self.effects,
                         fast=self.reduced_core is not None)

    # ----------------------------------------------------------------- initial state
    def core_state(self, init: PredictorInitialState) -> tuple[list[float], Env, np.ndarray]:
        """(core state x0 in the predictor's frame, road Env, ENU offset added to predicted
        positions). See the module docstring ("Initial state")."""
        m = self.model
        env = Env(init.road_bank_rad, init.road_grade_rad)
        phi_g, theta_g, psi_g = init.euler_g_rad
        phi_v, theta_v, psi_v = decompose_vehicle(phi_g, theta_g, psi_g, env.bank_rad, env.grade_rad)
        geo = self.vehicle.geometry
        r = self.vehicle.tire.rolling_radius_m
        zw = m.wheel_centre_z_m
        xy = m.corner_xy
        omega = init.rate_b_radps
        src = self.config.pose_source
        use_susp = src == "suspension" and init.has_suspension and not self.config.unsprung_dof
        if use_susp:
            # least squares: r - H_i = c + n_x x_i + n_y y_i
            a = np.array([[1.0, xy[i][0], xy[i][1]] for i in range(4)])
            b = np.array([r - init.susp_deflection_m[i] for i in range(4)])
            c, nxb, nyb = np.linalg.lstsq(a, b, rcond=None)[0]
            theta_v = math.asin(max(-1.0, min(1.0, nxb)))
            phi_v = math.asin(max(-1.0, min(1.0, nyb / math.cos(theta_v))))
            nzb = math.cos(phi_v) * math.cos(theta_v)
            h = float(c - nzb * zw)
            phi_g, theta_g, psi_g = compose_absolute(phi_v, theta_v, psi_v, env.bank_rad, env.grade_rad)
        elif src == "estimate_plane":
            ng = env.normal_g
            h = float(ng[0] * init.pos_g_m[0] + ng[1] * init.pos_g_m[1] + ng[2] * init.pos_g_m[2])
        else:
            h = geo.h_cg_m  # design CG height
        cgv = dcm_global_to_vehicle(phi_g, theta_g, psi_g)
        v_b = cgv @ np.asarray(init.vel_g_mps)
        n_b = cgv @ np.asarray(env.normal_g)
        if use_susp and init.susp_deflection_rate_mps is not None and all(
                math.isfinite(v) for v in init.susp_deflection_rate_mps):
            wx, wy, wz = omega
            acc = 0.0
            for i in range(4):
                xi, yi = xy[i]
                wr = (wy * zw - wz * yi, wz * xi - wx * zw, wx * yi - wy * xi)  # omega x r_w,i
                acc += init.susp_deflection_rate_mps[i] + float(n_b @ np.asarray(wr))
            v_n = -acc / 4.0
            v_b = v_b + (v_n - float(n_b @ v_b)) * n_b
        # position in the predictor's frame: same East/North, Up such that n . p = h
        ng = env.normal_g
        e, n_ = init.pos_g_m[0], init.pos_g_m[1]
        u = (h - ng[0] * e - ng[1] * n_) / ng[2]
        offset = np.array([0.0, 0.0, init.pos_g_m[2] - u])
        susp = rate = None
        if self.config.unsprung_dof:
            susp = init.susp_deflection_m if init.has_suspension else None
            rate = init.susp_deflection_rate_mps if susp is not None else None
        x0 = m.state_from((e, n_, u), (phi_g, theta_g, psi_g), v_b, omega, init.wheel_speed_radps,
                          susp, rate)
        return x0, env, offset

    # ----------------------------------------------------------------- prediction
    def predict(self, init: PredictorInitialState,
                inputs: Inputs | InputSource | InputTrajectory | None = None) -> PredictionResult:
        """Propagate the model over the horizon from ``init``.

        ``inputs``: None -> held (``init.inputs``, the warning path); an Inputs -> held at that
        value; a callable ``u(t_rel_s)`` or an :class:`InputTrajectory` -> input-driven."""
        x, env, offset = self.core_state(init)
        if inputs is None:
            mode, held, src = "held", init.inputs, None
        elif isinstance(inputs, Inputs):
            mode, held, src = "held", inputs, None
        elif isinstance(inputs, InputTrajectory):
            mode, held, src = "driven", None, inputs.at
        elif callable(inputs):
            mode, held, src = "driven", None, inputs
        else:
            raise TypeError("inputs must be None, Inputs, an InputTrajectory or a callable u(t_rel_s)")
        monitor = RolloverMonitor(self.model.static_load_n, self._track_half_m, self.vehicle.geometry.h_cg_m)
        if self.reduced_core is not None:
            run = propagate_reduced(self.reduced_core, self.config, x, env, held, src, monitor)
        else:
            run = propagate_generic(self.model, self.config, x, env, held, src, monitor)
        xs, fzs, ts, stop, n, n_eval = run
        return build_result(init, xs, fzs, ts, env, offset, monitor, stop, mode, n, n_eval)


class Cadence:
    """When to start the next prediction: every ``1 / cadence_hz`` of bus time (``due(t_ns)``
    is True at most once per period, on the first call at or after each period boundary)."""

    def __init__(self, cadence_hz: float):
        if not (math.isfinite(cadence_hz) and cadence_hz > 0):
            raise ValueError("cadence_hz must be positive")
        self.period_ns = int(round(NS_PER_S / cadence_hz))
        self._next: int | None = None

    def due(self, t_ns: int) -> bool:
        if self._next is None or t_ns >= self._next:
            base = t_ns if self._next is None else self._next
            # the next boundary after t_ns (periods missed entirely are skipped)
            self._next = base + ((t_ns - base) // self.period_ns + 1) * self.period_ns
            return True
        return False


def predictor_effects(base, model_effects):
    """The predictor's configured effects (``base``, e.g. the paper's ``linear_tire``) with a
    saved workbench model's *dynamics* effects joined: a tire model in the workbench model
    replaces the configured tire, any other effect is added (an effect of the same name is
    taken from the workbench model). Measurement effects are not part of the predictor."""
    from vdps_hil.model.effects.base import TireModel

    added = list(EffectSet(model_effects).dynamics)
    names = {e.name for e in added}
    new_tire = any(isinstance(e, TireModel) for e in added)
    keep = [e for e in base if e.name not in names and not (new_tire and isinstance(e, TireModel))]
    return EffectSet(keep + added)


__all__ = ["Cadence", "Predictor", "predictor_effects"]
