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

Integration (the stiff wheel spin)
----------------------------------
The stiffest mode of the reduced model is the wheel spin under slip,
``tau = I_w max(|v_l|, v_floor) / (r^2 C_kappa)`` (0.5 ms at the slip speed floor with the
sedan-model's x1.5 prior of C_kappa): explicit RK2 needs dt <= 2 tau ~ 1 ms, 5000 steps for 5 s.
The body modes (roll, pitch, heave with rigid tires: 1.5-2.5 Hz; yaw/sideslip) are slow.
Default integrator ``ros2``: the 2-stage Rosenbrock W-method of Verwer et al. (SIAM J. Sci.
Comput. 20(4), 1999), gamma = 1 + 1/sqrt(2), L-stable, second order for ANY matrix J::

    (I - gamma h J) k1 = f(x_n)
    (I - gamma h J) k2 = f(x_n + h k1) - 2 k1
    x_{n+1} = x_n + 3/2 h k1 + 1/2 h k2

with J nonzero only in the four wheel-spin rows (the body rows are zero, so the solve is one
division per wheel): the diagonal J_ii = d omega_dot_i / d omega_i by a forward difference of
the core's f (clipped to <= 0), and, with ``jacobian_coupling`` (default), the coupling to the
body velocity from the slip kinematics of the core (kappa = (r omega - v_l) / max(|v_l|, v_floor),
v_l = (v_x - omega_z y_i) cos delta_i + (v_y + omega_z x_i) sin delta_i)::

    d omega_dot_i / d v_l = -J_ii (1 + kappa_i) / r_i,   then chained to v_x, v_y, omega_z

J is refreshed every ``jacobian_every`` steps (a W-method stays second order with a stale or
approximate J). On the body states the scheme IS Heun's method (RK2) exactly; on the wheel
spins it is linearly implicit, so the step is set by the body dynamics. Without the coupling
the wheel spin lags an accelerating body by ~0.6 h d(v/r)/dt (order reduction of the stiff
component): 0.88 m after 5 s of the left turn at h = 10 ms; with it 2.7 mm. Measured against
explicit RK2 at 1 ms (``tools/bench_predictor.py``, true parameters, 5 s)::

    case                     h = 10 ms (default)          h = 20 ms
    left turn (Fig 8)        2.7 mm, 0.001 deg, 7 ms      5.6 mm, 0.005 deg, 3.7 ms
    T2 = T3 = 1000 N m       0.22 m, 0.21 deg             0.44 m, 0.42 deg
    fishhook-suv (to PONR)   4 mm, 0.59 deg, same PONR    6 mm, 0.98 deg, same PONR

(CPU time of one 5 s prediction in pure Python, best of 15; explicit RK2 at 1 ms takes 56 ms).
``rk2`` (Heun, explicit) is available for reference and needs h below the wheel-spin stability
limit.

Evaluation of the core: with the paper's model and effect set (reduced model, ``linear_tire``
alone or with static rolling-radius factors) the steps call
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
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from vdps_hil.model.core import Env, Inputs, Model, ackermann_angles
from vdps_hil.model.effects import EffectConfigError, EffectSet, effects_from_names
from vdps_hil.model.frames import compose_absolute, decompose_vehicle, dcm_global_to_vehicle
from vdps_hil.model.params import CONFIG_DIR, IdentifiedParams, Vehicle
from vdps_hil.model.reduced import ReducedLinearCore
from vdps_hil.model.reduced import supports as reduced_supports
from vdps_hil.model.rollover import RolloverMonitor
from vdps_hil.units import NS_PER_S

DEFAULT_CONFIG_PATH = CONFIG_DIR / "prediction" / "default.toml"
ROS2_GAMMA = 1.0 + 1.0 / math.sqrt(2.0)
"""gamma of Verwer's ROS2 (L-stable choice)."""
ROLL_LIMIT_RAD = math.radians(85.0)
"""The prediction stops beyond this road-relative roll (the model has no body-ground contact)."""
INTEGRATORS = ("ros2", "rk2")
POSE_SOURCES = ("suspension", "estimate", "estimate_plane")


class PredictionConfigError(ValueError):
    """A prediction config that cannot be used; the message is one line."""


# ---------------------------------------------------------------------------------------------
# configuration
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PredictorConfig:
    """Horizon, step, integrator, cadence and model variant of the predictor.

    Defaults (``configs/prediction/default.toml``): horizon 5 s, step 10 ms with ``ros2``
    (linearly implicit wheel spin), Jacobian every step, one output sample per step (100 Hz),
    cadence 10 Hz, effects ``["linear_tire"]``, reduced model (``unsprung_dof = false``), slip
    speed floor 5 m/s, stop at the predicted point of no return, pose from the suspension
    (``pose_source``: "suspension", "estimate" or "estimate_plane", module docstring)."""

    horizon_s: float = 5.0
    step_s: float = 0.01
    integrator: str = "ros2"
    jacobian_every: int = 2
    jacobian_coupling: bool = True
    output_every: int = 1
    cadence_hz: float = 10.0
    effects: tuple[str, ...] = ("linear_tire",)
    effect_params: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    unsprung_dof: bool = False
    slip_speed_floor_mps: float = 5.0
    stop_at_point_of_no_return: bool = True
    pose_source: str = "suspension"

    def __post_init__(self):
        for name in ("horizon_s", "step_s", "cadence_hz", "slip_speed_floor_mps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise PredictionConfigError(f"predictor.{name} must be a positive finite number, got {v!r}")
        for name in ("jacobian_every", "output_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise PredictionConfigError(f"predictor.{name} must be an integer >= 1, got {v!r}")
        if self.integrator not in INTEGRATORS:
            raise PredictionConfigError(f"predictor.integrator must be one of {', '.join(INTEGRATORS)}, "
                                        f"got {self.integrator!r}")
        if self.pose_source not in POSE_SOURCES:
            raise PredictionConfigError(f"predictor.pose_source must be one of {', '.join(POSE_SOURCES)}, "
                                        f"got {self.pose_source!r}")
        if self.step_s > self.horizon_s:
            raise PredictionConfigError("predictor.step_s must not exceed horizon_s")
        if not isinstance(self.effects, tuple):
            object.__setattr__(self, "effects", tuple(self.effects))

    @property
    def n_steps(self) -> int:
        """Steps per prediction: round(horizon / step)."""
        return max(1, int(round(self.horizon_s / self.step_s)))

    @property
    def cadence_ns(self) -> int:
        return int(round(NS_PER_S / self.cadence_hz))


_PRED_KEYS = {f for f in PredictorConfig.__dataclass_fields__}


def _check_table(t: Any, allowed: set[str], where: str) -> dict:
    if not isinstance(t, Mapping):
        raise PredictionConfigError(f"{where}: expected a table")
    unknown = sorted(set(t) - allowed)
    if unknown:
        raise PredictionConfigError(f"{where}: unknown key {unknown[0]!r}")
    return dict(t)


def predictor_config_from_table(t: Mapping, where: str = "[predictor]") -> PredictorConfig:
    """A PredictorConfig from a TOML table (unknown keys and bad values: one-line errors)."""
    d = _check_table(t, _PRED_KEYS, where)
    if "effects" in d:
        e = d["effects"]
        if not isinstance(e, list) or not all(isinstance(n, str) for n in e):
            raise PredictionConfigError(f"{where}.effects: expected a list of effect names")
        d["effects"] = tuple(e)
    if "effect_params" in d:
        ep = d["effect_params"]
        if not isinstance(ep, Mapping) or not all(isinstance(v, Mapping) for v in ep.values()):
            raise PredictionConfigError(f"{where}.effect_params: expected tables of parameters")
    for b in ("unsprung_dof", "stop_at_point_of_no_return", "jacobian_coupling"):
        if b in d and not isinstance(d[b], bool):
            raise PredictionConfigError(f"{where}.{b}: expected true or false")
    for k in ("horizon_s", "step_s", "cadence_hz", "slip_speed_floor_mps"):
        if k in d and isinstance(d[k], int) and not isinstance(d[k], bool):
            d[k] = float(d[k])
    try:
        return PredictorConfig(**d)
    except TypeError as e:  # pragma: no cover - keys are checked above
        raise PredictionConfigError(f"{where}: {e}") from None


def load_prediction_document(path: str | Path | None = None) -> dict:
    """The prediction config TOML (``configs/prediction/default.toml`` by default) as a dict
    (tomllib: data only). Tables: ``[predictor]`` and ``[warning]``."""
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise PredictionConfigError(f"cannot read prediction config {p}: {e.__class__.__name__}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise PredictionConfigError(f"{p}: malformed TOML: {e}") from None
    unknown = sorted(set(doc) - {"schema_version", "predictor", "warning"})
    if unknown:
        raise PredictionConfigError(f"{p}: unknown key {unknown[0]!r}")
    if doc.get("schema_version", 1) != 1:
        raise PredictionConfigError(f"{p}: unsupported schema_version {doc.get('schema_version')!r}")
    return doc


def load_predictor_config(path: str | Path | None = None) -> PredictorConfig:
    """The ``[predictor]`` table of a prediction config file."""
    doc = load_prediction_document(path)
    return predictor_config_from_table(doc.get("predictor", {}), f"{path or DEFAULT_CONFIG_PATH}[predictor]")


# ---------------------------------------------------------------------------------------------
# initial state
# ---------------------------------------------------------------------------------------------
def _vec(v, n: int, name: str) -> tuple[float, ...]:
    t = tuple(float(e) for e in v)
    if len(t) != n:
        raise ValueError(f"PredictorInitialState.{name} needs {n} values, got {len(t)}")
    return t


@dataclass(frozen=True)
class PredictorInitialState:
    """The estimated state at t0 the prediction starts from (all SI; frames in
    :mod:`vdps_hil.conventions`), plus the last inputs before t0 (held-input mode).

    ``susp_deflection_m`` / ``susp_deflection_rate_mps`` may be None (no suspension sensors):
    then the attitude of the estimate and the design CG height are used."""

    t_ns: int
    pos_g_m: tuple[float, float, float]  # sprung CG, ENU [m]
    vel_g_mps: tuple[float, float, float]  # CG velocity, ENU [m/s]
    euler_g_rad: tuple[float, float, float]  # phi_g, theta_g, psi_g (eq 1) [rad]
    road_bank_rad: float  # phi_r [rad]
    road_grade_rad: float  # theta_r [rad]
    rate_b_radps: tuple[float, float, float]  # body rates p, q, r [rad/s]
    wheel_speed_radps: tuple[float, float, float, float]  # omega_1..4 [rad/s]
    susp_deflection_m: tuple[float, float, float, float] | None = None  # H_1..4 [m]
    susp_deflection_rate_mps: tuple[float, float, float, float] | None = None  # H_dot_1..4 [m/s]
    inputs: Inputs = field(default_factory=Inputs)  # last steering / torques before t0

    def __post_init__(self):
        object.__setattr__(self, "t_ns", int(self.t_ns))
        for name, n in (("pos_g_m", 3), ("vel_g_mps", 3), ("euler_g_rad", 3), ("rate_b_radps", 3),
                        ("wheel_speed_radps", 4)):
            object.__setattr__(self, name, _vec(getattr(self, name), n, name))
        for name in ("susp_deflection_m", "susp_deflection_rate_mps"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, _vec(v, 4, name))
        object.__setattr__(self, "road_bank_rad", float(self.road_bank_rad))
        object.__setattr__(self, "road_grade_rad", float(self.road_grade_rad))
        if not isinstance(self.inputs, Inputs):
            raise ValueError("PredictorInitialState.inputs must be an Inputs")
        core = (*self.pos_g_m, *self.vel_g_mps, *self.euler_g_rad, self.road_bank_rad,
                self.road_grade_rad, *self.rate_b_radps, *self.wheel_speed_radps)
        if not all(math.isfinite(v) for v in core):
            raise ValueError("PredictorInitialState has a non-finite value")

    @property
    def has_suspension(self) -> bool:
        return (self.susp_deflection_m is not None
                and all(math.isfinite(v) for v in self.susp_deflection_m))

    @classmethod
    def from_estimator(cls, estimate, filtered, *, brake_torque_nm: Sequence[float] = (0.0,) * 4
                       ) -> "PredictorInitialState":
        """From the estimator pipeline's outputs (``EstimatorPipeline.estimate()`` and
        ``.filtered()``, :mod:`vdps_hil.estimation.pipeline`):

        =========================  ==========================================================
        here                       from
        =========================  ==========================================================
        t_ns                       ``estimate.t_ns``
        pos_g_m, vel_g_mps         ``estimate.x`` [x_g, y_g, z_g], [xdot_g, ydot_g, zdot_g]
        euler_g_rad                ``estimate.x`` [phi_g, theta_g, psi_g]
        road_bank/grade_rad        ``estimate.x`` [phi_r, theta_r]
        rate_b_radps               ``filtered.angular_rate_radps`` (alpha-beta, eq 12)
        wheel_speed_radps          ``filtered.wheel_speed_radps``
        susp_deflection(_rate)     ``filtered.susp_deflection_m`` / ``susp_rate_mps`` (None if NaN)
        inputs                     ``filtered.steer_wheel_angle_rad``, ``wheel_torque_nm``
                                   (the bus torque is the net wheel torque; brakes 0 unless
                                   given)
        =========================  ==========================================================

        Raises ValueError when a required value is missing (NaN): the caller sends the warning
        with status "sensor missing" then."""
        x = [float(v) for v in estimate.x]
        if len(x) < 11:
            raise ValueError("estimate.x must hold the 12 states of eq 7")
        susp = tuple(filtered.susp_deflection_m)
        srate = tuple(filtered.susp_rate_mps)
        if not all(math.isfinite(v) for v in susp):
            susp, srate = None, None
        elif not all(math.isfinite(v) for v in srate):
            srate = None
        steer = float(filtered.steer_wheel_angle_rad)
        torque = tuple(float(v) for v in filtered.wheel_torque_nm)
        if not math.isfinite(steer) or not all(math.isfinite(v) for v in torque):
            raise ValueError("steering or wheel torque missing: no held inputs")
        return cls(t_ns=int(estimate.t_ns), pos_g_m=tuple(x[0:3]), vel_g_mps=tuple(x[3:6]),
                   euler_g_rad=tuple(x[6:9]), road_bank_rad=x[9], road_grade_rad=x[10],
                   rate_b_radps=tuple(filtered.angular_rate_radps),
                   wheel_speed_radps=tuple(filtered.wheel_speed_radps),
                   susp_deflection_m=susp, susp_deflection_rate_mps=srate,
                   inputs=Inputs(steer, torque, tuple(brake_torque_nm)))

    @classmethod
    def from_truth_for_tests_only(cls, snapshot: Mapping[str, Any], *,
                                  with_suspension: bool = True) -> "PredictorInitialState":
        """TEST/BENCH ONLY: from a truth simulator snapshot (``Simulator.truth`` / ``snapshot()``).
        The pipeline never calls this (it never sees truth). Drive torque = net wheel torque +
        brake torque (exact while the wheel rolls forward faster than 2 rad/s)."""
        s = snapshot
        susp = tuple(s[f"susp_deflection_m_{i}"] for i in range(1, 5)) if with_suspension else None
        srate = tuple(s[f"susp_deflection_rate_mps_{i}"] for i in range(1, 5)) if with_suspension else None
        brakes = tuple(float(s.get(f"brake_torque_nm_{i}", 0.0)) for i in range(1, 5))
        drive = tuple(float(s[f"wheel_torque_nm_{i}"]) + brakes[i - 1] for i in range(1, 5))
        return cls(t_ns=int(s["t_ns"]), pos_g_m=(s["pos_e_m"], s["pos_n_m"], s["pos_u_m"]),
                   vel_g_mps=(s["vel_g_mps_e"], s["vel_g_mps_n"], s["vel_g_mps_u"]),
                   euler_g_rad=(s["roll_g_rad"], s["pitch_g_rad"], s["yaw_g_rad"]),
                   road_bank_rad=s["road_bank_rad"], road_grade_rad=s["road_grade_rad"],
                   rate_b_radps=(s["rate_b_radps_x"], s["rate_b_radps_y"], s["rate_b_radps_z"]),
                   wheel_speed_radps=tuple(s[f"wheel_speed_radps_{i}"] for i in range(1, 5)),
                   susp_deflection_m=susp, susp_deflection_rate_mps=srate,
                   inputs=Inputs(float(s["steer_wheel_angle_rad"]), drive, brakes))


# ---------------------------------------------------------------------------------------------
# inputs over the horizon
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class InputTrajectory:
    """Recorded inputs over the horizon: times relative to t0 [s] (non-decreasing), steering
    wheel angle [rad], drive torques (N, 4) [N m] and brake torques (N, 4) [N m, >= 0; default 0].
    Linear interpolation between samples, held beyond the ends."""

    t_s: np.ndarray
    steer_wheel_angle_rad: np.ndarray
    wheel_torque_nm: np.ndarray
    brake_torque_nm: np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.t_s, dtype=float)
        s = np.asarray(self.steer_wheel_angle_rad, dtype=float)
        w = np.asarray(self.wheel_torque_nm, dtype=float)
        b = np.zeros_like(w) if self.brake_torque_nm is None else np.asarray(self.brake_torque_nm, dtype=float)
        if t.ndim != 1 or t.size == 0 or s.shape != t.shape or w.shape != (t.size, 4) or b.shape != (t.size, 4):
            raise ValueError("InputTrajectory: t_s (N,), steer (N,), wheel/brake torques (N, 4)")
        if np.any(np.diff(t) < 0) or not (np.all(np.isfinite(t)) and np.all(np.isfinite(s))
                                          and np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise ValueError("InputTrajectory: times must not decrease and values must be finite")
        if np.any(b < 0):
            raise ValueError("InputTrajectory: brake torques are magnitudes >= 0")
        for k, v in (("t_s", t), ("steer_wheel_angle_rad", s), ("wheel_torque_nm", w), ("brake_torque_nm", b)):
            object.__setattr__(self, k, v)

    def at(self, t_rel_s: float) -> Inputs:
        t = self.t_s
        steer = float(np.interp(t_rel_s, t, self.steer_wheel_angle_rad))
        tq = tuple(float(np.interp(t_rel_s, t, self.wheel_torque_nm[:, k])) for k in range(4))
        br = tuple(float(np.interp(t_rel_s, t, self.brake_torque_nm[:, k])) for k in range(4))
        return Inputs(steer, tq, br)


InputSource = Callable[[float], Inputs]
"""``u(t_rel_s) -> Inputs``: inputs at a time after t0."""


# ---------------------------------------------------------------------------------------------
# result
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PredictionResult:
    """One prediction. Arrays share the first axis (N output samples, ``t_s[0] = 0`` at t0).

    ``pos_g_m`` ENU (anchored on the estimate at t0), ``euler_g_rad`` (phi_g, theta_g, psi_g),
    ``euler_v_rad`` (phi_v, theta_v, psi_v relative to the road, eq 4), ``vel_b_mps``,
    ``rate_b_radps``, ``wheel_speed_radps``, ``normal_load_n`` (eq 14, per wheel), ``ltr``
    ((F_right - F_left) / sum, as the simulator's), ``roll_rate_v_radps`` (d phi_v / dt).
    Events (times after t0 [s], None when not predicted): ``tip_up_t_s`` (start of the 0.2 s
    interval), ``point_of_no_return_t_s`` (``model.rollover`` definitions on the predicted
    trajectory). ``stop_reason``: horizon, point_of_no_return, roll_limit, non_finite."""

    t0_ns: int
    t_s: np.ndarray
    pos_g_m: np.ndarray
    euler_g_rad: np.ndarray
    euler_v_rad: np.ndarray
    vel_b_mps: np.ndarray
    rate_b_radps: np.ndarray
    wheel_speed_radps: np.ndarray
    normal_load_n: np.ndarray
    ltr: np.ndarray
    roll_rate_v_radps: np.ndarray
    road_bank_rad: float
    road_grade_rad: float
    tip_up_t_s: float | None
    tip_up_side: str | None
    point_of_no_return_t_s: float | None
    point_of_no_return_side: str | None
    stop_reason: str
    input_mode: str
    n_steps: int
    n_f_evals: int

    @property
    def horizon_reached_s(self) -> float:
        return float(self.t_s[-1])

    @property
    def rollover_predicted(self) -> bool:
        return self.point_of_no_return_t_s is not None

    def t_abs_ns(self) -> np.ndarray:
        """Absolute sample times [ns]."""
        return self.t0_ns + np.rint(self.t_s * NS_PER_S).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# predictor
# ---------------------------------------------------------------------------------------------
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
        lay = self.model.layout
        self._wheel_slice = lay.wheel_spin
        self._n_state = lay.size
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
        cfg = self.config
        x, env, offset = self.core_state(init)
        if inputs is None:
            mode, held = "held", init.inputs
        elif isinstance(inputs, Inputs):
            mode, held = "held", inputs
        elif isinstance(inputs, InputTrajectory):
            mode, held, src = "driven", None, inputs.at
        elif callable(inputs):
            mode, held, src = "driven", None, inputs
        else:
            raise TypeError("inputs must be None, Inputs, an InputTrajectory or a callable u(t_rel_s)")
        if self.reduced_core is not None:
            run = self._propagate_reduced(x, env, held, None if held is not None else src)
            return self._result(init, *run[:3], env, offset, *run[3:5], mode, *run[5:])
        h = cfg.step_s
        n_steps = cfg.n_steps
        f = self.model.f
        ws = self._wheel_slice
        w0, w1 = ws.start, ws.stop
        gh = ROS2_GAMMA * h
        ros2 = cfg.integrator == "ros2"
        jac_every = cfg.jacobian_every
        out_every = cfg.output_every
        monitor = RolloverMonitor(self.model.static_load_n, self._track_half_m,
                                  self.vehicle.geometry.h_cg_m)
        winv = [1.0, 1.0, 1.0, 1.0]
        coupling = cfg.jacobian_coupling
        cvx, cvy, cwz = [0.0] * 4, [0.0] * 4, [0.0] * 4
        u_c = None
        cd = sd = (0.0,) * 4
        geo = self.vehicle.geometry
        ratio, wheelbase, t_f = geo.steer_ratio, geo.wheelbase_m, geo.track_half_front_m
        radii = self.model.rolling_radius_m
        corner_xy = self.model.corner_xy
        vfloor = self.model.slip_speed_floor_mps
        h15, h05, hh = 1.5 * h, 0.5 * h, 0.5 * h
        n_eval = 0
        xs: list[list[float]] = []
        fzs: list[tuple] = []
        ts: list[float] = []
        stop = "horizon"
        atan2 = math.atan2
        n = 0
        u = held
        while True:
            t_rel = n * h
            if held is None:
                u = src(t_rel)
            out = {"_want_air": False}
            f0 = f(x, u, env, out)
            n_eval += 1
            rec = out["_rec"]
            record = n % out_every == 0 or n == n_steps
            # road-relative roll for the rollover monitor (n_b = C_r^v e_z)
            nx, ny, nz = out["_normal_b"]
            fz = (rec[0][2], rec[1][2], rec[2][2], rec[3][2])
            ended = _keep_step(xs, fzs, ts, monitor, cfg.stop_at_point_of_no_return, record, t_rel, x, fz,
                               atan2(ny, nz), nx)
            if ended is not None:
                stop = ended
                break
            if n >= n_steps:
                break
            if ros2:
                if n % jac_every == 0:
                    xp = list(x)
                    eps = []
                    for i in range(w0, w1):
                        e_ = 1e-4 * max(1.0, abs(x[i]))
                        xp[i] += e_
                        eps.append(e_)
                    fp = f(xp, u, env)
                    n_eval += 1
                    if coupling and (u is not u_c):
                        u_c = u
                        d1, d2 = ackermann_angles(u.steer_wheel_angle_rad / ratio, wheelbase, t_f)
                        cd = (math.cos(d1), math.cos(d2), 1.0, 1.0)
                        sd = (math.sin(d1), math.sin(d2), 0.0, 0.0)
                    above = abs(x[6]) > vfloor
                    for k in range(4):
                        jd = (fp[w0 + k] - f0[w0 + k]) / eps[k]
                        if jd > 0.0 or jd != jd:
                            jd = 0.0
                        winv[k] = 1.0 / (1.0 - gh * jd)
                        if coupling:
                            # d omega_dot / d v_l = J_kk * (d kappa / d v_l) / (d kappa / d omega)
                            fac = -jd * ((1.0 + rec[k][3]) if above else 1.0) / radii[k]
                            xi, yi = corner_xy[k]
                            cvx[k] = gh * fac * cd[k]
                            cvy[k] = gh * fac * sd[k]
                            cwz[k] = gh * fac * (xi * sd[k] - yi * cd[k])
                k1 = list(f0)
                a6, a7, a11 = k1[6], k1[7], k1[11]
                for k in range(4):
                    k1[w0 + k] = (k1[w0 + k] + cvx[k] * a6 + cvy[k] * a7 + cwz[k] * a11) * winv[k]
                f1 = f([a + h * b for a, b in zip(x, k1)], u, env)
                n_eval += 1
                k2 = [c - 2.0 * b for b, c in zip(k1, f1)]
                a6, a7, a11 = k2[6], k2[7], k2[11]
                for k in range(4):
                    k2[w0 + k] = (k2[w0 + k] + cvx[k] * a6 + cvy[k] * a7 + cwz[k] * a11) * winv[k]
                x = [a + h15 * b + h05 * c for a, b, c in zip(x, k1, k2)]
            else:
                f1 = f([a + h * b for a, b in zip(x, f0)], u, env)
                n_eval += 1
                x = [a + hh * (b + c) for a, b, c in zip(x, f0, f1)]
            n += 1
            if not math.isfinite(x[6] + x[9] + x[12] + x[3] + x[4]):
                stop = "non_finite"
                break
        return self._result(init, xs, fzs, ts, env, offset, monitor, stop, mode, n, n_eval)

    def _propagate_reduced(self, x: list, env: Env, held: Inputs | None, src: InputSource | None):
        """The integration loop of :meth:`predict` on :class:`ReducedLinearCore`: the same steps,
        stop rules and ROS2 W-method as the generic loop, with the wheel-spin Jacobian in closed
        form instead of a forward difference and the W-solve written out for the four wheel rows.
        Returns (states, loads, times, monitor, stop reason, steps, f-evaluations)."""
        cfg = self.config
        core = self.reduced_core
        F, jacobian, inputs_of = core.f, core.wheel_spin_jacobian, core.inputs
        h = cfg.step_s
        n_steps, out_every, jac_every = cfg.n_steps, cfg.output_every, cfg.jacobian_every
        ros2, coupling = cfg.integrator == "ros2", cfg.jacobian_coupling
        stop_ponr = cfg.stop_at_point_of_no_return
        gh, h15, h05 = ROS2_GAMMA * h, 1.5 * h, 0.5 * h
        monitor = RolloverMonitor(self.model.static_load_n, self._track_half_m,
                                  self.vehicle.geometry.h_cg_m)
        radii, corner_xy = self.model.rolling_radius_m, self.model.corner_xy
        vfloor = self.model.slip_speed_floor_mps
        w0 = w1 = w2 = w3 = 1.0
        cx0 = cx1 = cx2 = cx3 = cy0 = cy1 = cy2 = cy3 = cz0 = cz1 = cz2 = cz3 = 0.0
        uc_c = kc = None
        atan2, isfinite = math.atan2, math.isfinite
        uc = inputs_of(held) if held is not None else None
        xs: list[list[float]] = []
        fzs: list = []
        ts: list[float] = []
        stop = "horizon"
        n = n_eval = 0
        while True:
            t_rel = n * h
            if src is not None:
                uc = inputs_of(src(t_rel))
            f0, fz, (nx, ny, nz), kap, den = F(x, uc, env)
            n_eval += 1
            record = n % out_every == 0 or n == n_steps
            ended = _keep_step(xs, fzs, ts, monitor, stop_ponr, record, t_rel, x, fz, atan2(ny, nz), nx)
            if ended is not None:
                stop = ended
                break
            if n >= n_steps:
                break
            if not ros2:
                f1 = F([a + h * b for a, b in zip(x, f0)], uc, env)[0]
                n_eval += 1
                x = [a + h05 * (b + c) for a, b, c in zip(x, f0, f1)]
            else:
                if n % jac_every == 0:
                    j0, j1, j2, j3 = [0.0 if (j > 0.0 or j != j) else j for j in jacobian(x, uc, fz, den)]
                    w0, w1, w2, w3 = (1.0 / (1.0 - gh * j0), 1.0 / (1.0 - gh * j1),
                                      1.0 / (1.0 - gh * j2), 1.0 / (1.0 - gh * j3))
                    if coupling:
                        if uc is not uc_c:
                            # gh / r_i times (cos d_i, sin d_i, x_i sin d_i - y_i cos d_i): v_l -> v_x, v_y, omega_z
                            uc_c = uc
                            kc = ([gh / radii[k] * uc[0][k][0] for k in range(4)]
                                  + [gh / radii[k] * uc[0][k][1] for k in range(4)]
                                  + [gh / radii[k] * (corner_xy[k][0] * uc[0][k][1] - corner_xy[k][1] * uc[0][k][0])
                                     for k in range(4)])
                        # d omega_dot / d v_l = J_kk * (d kappa / d v_l) / (d kappa / d omega)
                        if abs(x[6]) > vfloor:
                            q = (-j0 * (1.0 + kap[0]), -j1 * (1.0 + kap[1]), -j2 * (1.0 + kap[2]),
                                 -j3 * (1.0 + kap[3]))
                        else:
                            q = (-j0, -j1, -j2, -j3)
                        (cx0, cx1, cx2, cx3, cy0, cy1, cy2, cy3, cz0, cz1, cz2, cz3) = [
                            a * b for a, b in zip(q + q + q, kc)]
                # stage 1: k1 = W^-1 f(x_n) (W = I on the body rows)
                k1 = f0
                a6, a7, a11 = k1[6], k1[7], k1[11]
                k1[12] = (k1[12] + cx0 * a6 + cy0 * a7 + cz0 * a11) * w0
                k1[13] = (k1[13] + cx1 * a6 + cy1 * a7 + cz1 * a11) * w1
                k1[14] = (k1[14] + cx2 * a6 + cy2 * a7 + cz2 * a11) * w2
                k1[15] = (k1[15] + cx3 * a6 + cy3 * a7 + cz3 * a11) * w3
                # stage 2: k2 = W^-1 (f(x_n + h k1) - 2 k1); x_n+1 = x_n + 3/2 h k1 + 1/2 h k2
                f1 = F([a + h * b for a, b in zip(x, k1)], uc, env)[0]
                n_eval += 1
                xn = [a + h15 * b + h05 * (c - 2.0 * b) for a, b, c in zip(x, k1, f1)]  # body rows
                a6, a7, a11 = f1[6] - 2.0 * k1[6], f1[7] - 2.0 * k1[7], f1[11] - 2.0 * k1[11]
                xn[12] = x[12] + h15 * k1[12] + h05 * (f1[12] - 2.0 * k1[12] + cx0 * a6 + cy0 * a7 + cz0 * a11) * w0
                xn[13] = x[13] + h15 * k1[13] + h05 * (f1[13] - 2.0 * k1[13] + cx1 * a6 + cy1 * a7 + cz1 * a11) * w1
                xn[14] = x[14] + h15 * k1[14] + h05 * (f1[14] - 2.0 * k1[14] + cx2 * a6 + cy2 * a7 + cz2 * a11) * w2
                xn[15] = x[15] + h15 * k1[15] + h05 * (f1[15] - 2.0 * k1[15] + cx3 * a6 + cy3 * a7 + cz3 * a11) * w3
                x = xn
            n += 1
            if not isfinite(x[6] + x[9] + x[12] + x[3] + x[4]):
                stop = "non_finite"
                break
        return xs, fzs, ts, monitor, stop, n, n_eval

    def _result(self, init, xs, fzs, ts, env: Env, offset, monitor: RolloverMonitor, stop: str,
                mode: str, n_steps: int, n_eval: int) -> PredictionResult:
        X = np.asarray(xs, dtype=float)
        t = np.asarray(ts, dtype=float)
        fz = np.asarray(fzs, dtype=float)
        pos = X[:, 0:3] + offset
        eul = X[:, 3:6].copy()
        eul_v = vehicle_angles(eul, env.bank_rad, env.grade_rad)
        w = X[:, 9:12]
        tt = np.tan(eul_v[:, 1])
        roll_rate_v = w[:, 0] - tt * np.sin(eul_v[:, 0]) * w[:, 1] - tt * np.cos(eul_v[:, 0]) * w[:, 2]
        left = fz[:, 0] + fz[:, 3]
        right = fz[:, 1] + fz[:, 2]
        tot = left + right
        ltr = np.divide(right - left, tot, out=np.zeros_like(tot), where=tot > 0)
        tu, pn = monitor.tip_up, monitor.point_of_no_return
        return PredictionResult(
            t0_ns=init.t_ns, t_s=t, pos_g_m=pos, euler_g_rad=eul, euler_v_rad=eul_v,
            vel_b_mps=X[:, 6:9].copy(), rate_b_radps=w.copy(), wheel_speed_radps=X[:, 12:16].copy(),
            normal_load_n=fz, ltr=ltr, roll_rate_v_radps=roll_rate_v,
            road_bank_rad=env.bank_rad, road_grade_rad=env.grade_rad,
            tip_up_t_s=tu.t_s if tu else None, tip_up_side=tu.side if tu else None,
            point_of_no_return_t_s=pn.t_s if pn else None, point_of_no_return_side=pn.side if pn else None,
            stop_reason=stop, input_mode=mode, n_steps=n_steps, n_f_evals=n_eval)


def _keep_step(xs: list, fzs: list, ts: list, monitor: "RolloverMonitor", stop_ponr: bool, record: bool,
               t_rel: float, x: list, fz, phi_v: float, nx: float) -> str | None:
    """One integration step's bookkeeping, the same in both loops of :class:`Predictor`: a
    recorded step keeps (state, wheel loads, time) and feeds the rollover monitor the
    road-relative roll ``phi_v`` and its rate (Euler-rate relation with theta_v = asin(n_x)).
    Returns why the prediction stops here -- ``"point_of_no_return"`` (the monitor found it and
    ``stop_ponr``), ``"roll_limit"`` (|phi_v| past ``ROLL_LIMIT_RAD``; that step is kept even
    when not a recorded one) -- or None."""
    if record:
        xs.append(x)
        fzs.append(fz)
        ts.append(t_rel)
        tt = math.tan(math.asin(max(-1.0, min(1.0, nx))))
        monitor.update(t_rel, fz, phi_v, x[9] - tt * math.sin(phi_v) * x[10] - tt * math.cos(phi_v) * x[11])
        if stop_ponr and monitor.point_of_no_return is not None:
            return "point_of_no_return"
    if abs(phi_v) > ROLL_LIMIT_RAD:
        if not record:
            xs.append(x), fzs.append(fz), ts.append(t_rel)
        return "roll_limit"
    return None


def vehicle_angles(euler_g_rad: np.ndarray, bank_rad: float, grade_rad: float) -> np.ndarray:
    """Eq 4 vectorised: absolute angles (N, 3) -> road-relative (phi_v, theta_v, psi_v) (N, 3),
    C_r^v = C_g^v (C_g^r)^T with psi_r = 0."""
    e = np.atleast_2d(np.asarray(euler_g_rad, dtype=float))
    sf, cf = np.sin(e[:, 0]), np.cos(e[:, 0])
    st, ct = np.sin(e[:, 1]), np.cos(e[:, 1])
    sp, cp = np.sin(e[:, 2]), np.cos(e[:, 2])
    c = np.empty((e.shape[0], 3, 3))
    c[:, 0, 0], c[:, 0, 1], c[:, 0, 2] = ct * cp, ct * sp, st
    c[:, 1, 0] = -cf * sp - sf * st * cp
    c[:, 1, 1] = cf * cp - sf * st * sp
    c[:, 1, 2] = sf * ct
    c[:, 2, 0] = sf * sp - cf * st * cp
    c[:, 2, 1] = -sf * cp - cf * st * sp
    c[:, 2, 2] = cf * ct
    from vdps_hil.model.frames import dcm_global_to_road
    cr = c @ dcm_global_to_road(bank_rad, grade_rad).T
    return np.stack([np.arctan2(cr[:, 1, 2], cr[:, 2, 2]),
                     np.arcsin(np.clip(cr[:, 0, 2], -1.0, 1.0)),
                     np.arctan2(cr[:, 0, 1], cr[:, 0, 0])], axis=1)


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


__all__ = ["Cadence", "DEFAULT_CONFIG_PATH", "InputSource", "InputTrajectory", "PredictionConfigError",
           "PredictionResult", "Predictor", "PredictorConfig", "PredictorInitialState",
           "load_prediction_document", "load_predictor_config", "predictor_config_from_table",
           "vehicle_angles"]
