"""Multi-rate extended Kalman filter of the paper (eq 7-11) with documented corrections.

Filter cycle (driven by sample timestamps, integer ns)::

    predict_to(t):  x <- step(x, u, dt)                       (kinematics.step, eq 7 + (d))
                    P <- Phi P Phi^T + Q_d,   Phi = I + F dt + (F dt)^2 / 2
                    Q_d = (Phi Q_c Phi^T + Q_c) dt / 2,  Q_c = G diag(q_u) G^T + diag(q_rw)
    update(kind,z): nu = z - h(x) (angles wrapped),  S = H P H^T + R,  NIS = nu^T S^-1 nu
                    gate: NIS > chi2_quantile(p_gate, dof) -> rejected and counted
                    K = P H^T S^-1,  x <- x + K nu
                    P <- (I - K H) P (I - K H)^T + K R K^T                      (Joseph form)
                    nonlinear kinds: iterated EKF, x_i+1 = x + K_i (z - h(x_i) - H_i (x - x_i)),
                    H, K of the last iterate in the Joseph form (``update_iterations``)

Multi-rate (eq 10-11): each measurement kind is its own update when its sample arrives; a kind
that is absent (outage, sensor not fitted) simply never updates, so the filter runs predict-only
through outages. Kinds not enabled by the configuration are counted as ``disabled``, never a
crash.

Corrections of the paper (``PaperFaithful``: True = as printed, the default False = corrected;
(a) psi_v derived from eq 4, (b) y2^gps dropped, (c) locally referenced y2^sus, (d) gravity
added to the specific force), the process noise q_u, q_rw and the real-car extensions (IMU bias
states, wheel speed, non-holonomic constraint, re-acquisition) are switches of the configuration,
stated in full in the ``ekf_config`` module docstring; they decide the state layout and the
measurement kinds this filter runs.

Latency (measurement time-stamped in the past, t_m < filter time): the filter keeps a history
of (x, P) snapshots before every predict and update of the last ``history_s`` seconds. A late
measurement rewinds to the snapshot before t_m, predicts to t_m with the stored input, applies
the update, and re-propagates with the stored inputs, re-applying the stored later updates
(re-gated, not re-counted). Older than the history: rejected and counted ``too_old``.

Reset on NaN: a non-finite x or P after any step resets the filter to uninitialised (counted
``nan_resets``); the caller (pipeline) re-initialises from the next fixes. A measurement that
is entirely NaN is counted ``nan`` (partial NaN: those rows are dropped).
"""

from __future__ import annotations

import math
import types
from dataclasses import dataclass

import numpy as np

from vdps_hil import jit
from vdps_hil.estimation import ekf_kernels as PK
from vdps_hil.estimation import ekf_update_kernels as UK
from vdps_hil.estimation.chi2 import chi2_quantile
from vdps_hil.estimation.ekf_config import EkfConfig
from vdps_hil.estimation.ekf_history import Event, EventHistory
from vdps_hil.estimation.ekf_reference import propagate_reference, update_reference, wrap_positions
from vdps_hil.estimation.observations import (ObsKind, make_models, rear_axle_ground_point,
                                              wheel_positions)
from vdps_hil.estimation.states import N_EXT, AugStates, States


NONLINEAR_KINDS = (ObsKind.GNSS_VEL, ObsKind.Y2_GPS, ObsKind.Y1_SUS, ObsKind.Y2_SUS_PLANE, ObsKind.Y2_SUS_RATE)
"""Kinds updated with the iterated EKF (``EkfConfig.update_iterations``): their h couples angle
states multiplicatively, and a precise measurement (y1_sus: 4e-4 rad) linearised at a point
0.05 rad away (a fresh road estimate) leaves the plain EKF overconfident."""


@dataclass(frozen=True)
class UpdateResult:
    """Outcome of one update. ``status``: accepted, gated, nan, too_old, disabled,
    not_initialized. ``innovation`` and ``innovation_sigma`` (sqrt diag S) are per used row."""

    kind: ObsKind
    t_ns: int
    status: str
    innovation: tuple[float, ...] = ()
    innovation_sigma: tuple[float, ...] = ()
    nis: float = math.nan
    dof: int = 0
    gate: float = math.nan
    delayed: bool = False

    @property
    def accepted(self) -> bool:
        return self.status == "accepted"


_STATUSES = ("accepted", "gated", "nan", "too_old", "disabled", "not_initialized")


class MultiRateEKF:
    """The multi-rate EKF of eq 7-11 (pure object: no threads, no devices, no clocks).

    ``x``/``P`` are the *filter* vector and covariance (``layout``); ``full_state()`` gives the
    12 states of eq 7 with derived/fixed ones filled in."""

    def __init__(self, config: EkfConfig | None = None, gnss_lever_arm_m=(0.0, 0.0, 0.0), wheel_positions_m=None,
                 nhc_point_m=(0.0, 0.0, 0.0), compiled: bool | None = None):
        self.config = config or EkfConfig()
        self.layout = self.config.layout()
        self._idx = self.layout.full_index
        self._n = self.layout.n
        self._aug = self.layout.augmented
        self._models = make_models(gnss_lever_arm_m, wheel_positions_m, nhc_point_m)
        self.compiled = jit.ENABLED if compiled is None else bool(compiled)
        """Predict and update run the compiled kernels (``ekf_kernels``, ``ekf_update_kernels``);
        False: their numpy reference (``ekf_reference``; the default with ``VDPS_JIT=0``)."""
        self._lay = PK.layout_arrays(self.layout)  # idx, pos, flags, yaw for the kernels
        m = self._models
        self._model_params = UK.model_params(m[ObsKind.GNSS_POS].lever_arm_m, m[ObsKind.NHC].point_m,
                                             m[ObsKind.WHEEL_SPEED].wheel_positions_m)
        self._kinds = self.config.kinds()
        self._q_in = self.config.input_psd()
        q_rw = np.zeros(N_EXT)
        q_rw[States.PHI_R] = q_rw[States.THETA_R] = self.config.road_angle_rw ** 2
        q_rw[States.PSI_V] = self.config.psi_v_rw ** 2
        q_rw[AugStates.BG_X:AugStates.BG_Z + 1] = self.config.gyro_bias_rw ** 2
        q_rw[AugStates.BA_X:AugStates.BA_Z + 1] = self.config.accel_bias_rw ** 2
        q_rw[AugStates.WHEEL_SCALE] = self.config.wheel_scale_rw ** 2
        self._q_rw_diag = q_rw[self._idx]
        self._q_rw = np.diag(self._q_rw_diag)
        self._pos_bg = [(self.layout.index(AugStates.BG_X + a), a) for a in self.layout.gyro_bias_axes]
        self._pos_ba = [(self.layout.index(AugStates.BA_X + a), a) for a in self.layout.accel_bias_axes]
        self._g = self.config.gravity_in_model_mps2
        p = self.config.gate_probability
        self._gates = {d: (chi2_quantile(p, d) if p is not None else math.inf) for d in range(1, 7)}
        self._gate_array = np.array([self._gates.get(d, math.inf) for d in range(7)])
        self._yaw_pos = [i for i, s in enumerate(self._idx) if s in (States.PSI_G, States.PSI_V)]
        self._iterations = {k: self.config.update_iterations for k in NONLINEAR_KINDS}
        self.plain_until_ns = -(1 << 62)  # updates before it are not iterated (set by imu_monitor after an outage)
        self._hist_ns = int(round(self.config.history_s * 1e9))
        self._max_step_ns = int(round(self.config.max_step_s * 1e9))
        self._f = np.array([0.0, 0.0, self.config.gravity_mps2])
        self._w = np.zeros(3)
        self._x: np.ndarray | None = None
        self._P: np.ndarray | None = None
        self._t: int | None = None
        self._hist = EventHistory(self._hist_ns)
        self._replaying = False
        self._last: UpdateResult | None = None
        self._last_innov = np.zeros(0)
        self._kind_counts = {k: dict.fromkeys(_STATUSES, 0) for k in ObsKind}
        self._counts = {"predicts": 0, "nan_resets": 0, "resets": 0, "initializations": 0,
                        "predict_backwards": 0, "delayed_updates": 0, "reacquisitions": 0}
        self.on_predict = None  # optional hook(Phi) for observability tracking
        self.on_update = None  # optional hook(H, R) for observability tracking

    @classmethod
    def from_vehicle(cls, vehicle, config: EkfConfig | None = None) -> "MultiRateEKF":
        """Antenna lever arm from a *model* vehicle file (``mounting.gnss_lever_arm_m``)."""
        if getattr(vehicle, "kind", "model") != "model":
            raise ValueError("the estimator reads only model vehicle files, not truth files")
        geo = vehicle.geometry
        return cls(config, gnss_lever_arm_m=vehicle.mounting.gnss_lever_arm_m,
                   wheel_positions_m=wheel_positions(geo, vehicle.tire.rolling_radius_m),
                   nhc_point_m=rear_axle_ground_point(geo))

    # ---------------------------------------------------------------- read-only properties
    @property
    def initialized(self) -> bool:
        return self._x is not None

    @property
    def t_ns(self) -> int | None:
        return self._t

    @property
    def x(self) -> np.ndarray:
        """Filter state (read-only view)."""
        return _ro(self._x)

    @property
    def P(self) -> np.ndarray:
        """Filter covariance (read-only view)."""
        return _ro(self._P)

    @property
    def kinds(self) -> frozenset[ObsKind]:
        return self._kinds

    @property
    def innovation(self) -> np.ndarray:
        """Innovation of the last update that got as far as computing one (read-only)."""
        return _ro(self._last_innov)

    @property
    def nis(self) -> float:
        return self._last.nis if self._last is not None else math.nan

    @property
    def last_update(self) -> UpdateResult | None:
        return self._last

    @property
    def counters(self) -> types.MappingProxyType:
        """Snapshot: global counters plus ``updates[kind][status]``."""
        d = dict(self._counts)
        d["updates"] = types.MappingProxyType({k.value: types.MappingProxyType(dict(v))
                                               for k, v in self._kind_counts.items()})
        return types.MappingProxyType(d)

    def bias(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(b_g [rad/s], b_a [m/s^2]) per body axis; 0 for axes without a bias state (and before
        initialisation)."""
        bg, ba = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        if self._x is not None:
            for i, a in self._pos_bg:
                bg[a] = float(self._x[i])
            for i, a in self._pos_ba:
                ba[a] = float(self._x[i])
        return tuple(bg), tuple(ba)

    def augmented_state(self) -> dict[str, tuple[float, float]]:
        """{name: (value, sigma)} of the bias and wheel-scale states carried (empty if none)."""
        if self._x is None:
            return {}
        return self.layout.augmented_values(self._x, self._P)

    def rejected(self) -> dict[str, int]:
        """Rejections per kind (gated + nan + too_old)."""
        return {k.value: v["gated"] + v["nan"] + v["too_old"] for k, v in self._kind_counts.items()}

    # ---------------------------------------------------------------- life cycle
    def initialize(self, t_ns: int, x0, P0) -> None:
        if not isinstance(t_ns, (int, np.integer)):
            raise TypeError(f"t_ns must be integer nanoseconds, got {type(t_ns).__name__}")
        x = self.layout.check_x(x0).copy()
        P = self.layout.check_p(P0).copy()
        if not (np.isfinite(x).all() and np.isfinite(P).all()):
            raise ValueError("initial state and covariance must be finite")
        if not np.allclose(P, P.T, atol=1e-12 * max(1.0, float(np.abs(P).max()))):
            raise ValueError("initial covariance must be symmetric")
        self._x, self._P, self._t = x, 0.5 * (P + P.T), int(t_ns)
        self._wrap()
        self._hist.clear()
        self._counts["initializations"] += 1

    def reacquire(self, t_ns: int, assignments) -> bool:
        """Re-acquisition after persistent gating (``ekf_config`` module docstring): at the filter time
        ``t_ns`` (predicted to first), set the full-vector states of ``assignments``
        ({full index: (value, sigma)}; states the layout does not carry are ignored), drop their
        cross-covariances and the latency history. False if not initialised."""
        if self._x is None or not self.predict_to(int(t_ns)) or self._x is None:
            return False
        for s, (v, sig) in assignments.items():
            i = self.layout.index(s)
            if i is None or not (math.isfinite(v) and math.isfinite(sig) and sig > 0):
                continue
            self._x[i] = v
            self._P[i, :] = 0.0
            self._P[:, i] = 0.0
            self._P[i, i] = sig * sig
        self._wrap()
        self._hist.clear()
        self._counts["reacquisitions"] += 1
        return True

    def reset(self, reason: str = "manual") -> None:
        """Back to uninitialised (x, P, history dropped; counters kept)."""
        self._x = self._P = self._t = None
        self._hist.clear()
        self._counts["resets"] += 1
        if reason == "nan":
            self._counts["nan_resets"] += 1

    def set_input(self, specific_force_mps2, angular_rate_radps) -> None:
        """Mean IMU input for the following predicts: specific force [m/s^2] and angular rate
        [rad/s] in body axes (esc3: missing axes already substituted by the caller).
        A non-finite input is taken as given: the predict that uses it resets the filter."""
        f = np.asarray(specific_force_mps2, dtype=float)
        w = np.asarray(angular_rate_radps, dtype=float)
        if f.shape != (3,) or w.shape != (3,):
            raise ValueError(f"IMU input must be two 3-vectors, got shapes {f.shape} and {w.shape}")
        self._f, self._w = f.copy(), w.copy()

    def set_input_psd(self, q_u=None) -> None:
        """Input-error PSD q_u (6,) of the next predicts (None: ``EkfConfig.input_psd()``; an IMU outage)."""
        self._q_in = self.config.input_psd() if q_u is None else np.array(q_u, dtype=float).reshape(6)

    # ---------------------------------------------------------------- predict
    def predict_to(self, t_ns: int) -> bool:
        """Propagate to ``t_ns`` with the current input. False if not initialised or t_ns is in
        the past (counted ``predict_backwards``)."""
        if self._x is None:
            return False
        t_ns = int(t_ns)
        if t_ns < self._t:
            self._counts["predict_backwards"] += 1
            return False
        if t_ns == self._t:
            return True
        if self._hist_ns > 0:
            self._record(True, t_ns, (self._f.copy(), self._w.copy()))
        while self._t < t_ns and self._x is not None:
            t_next = min(t_ns, self._t + self._max_step_ns)
            self._propagate((t_next - self._t) * 1e-9)
            self._t = t_next
        return self._x is not None

    def _propagate(self, dt: float) -> None:
        if self.compiled:
            x, P, phi = self._x.copy(), self._P.copy(), np.empty((self._n, self._n))
            idx, _, flags, yaw = self._lay
            PK.propagate(x, P, idx, flags, yaw, self._f, self._w, dt, self._g, self._q_in, self._q_rw_diag, phi)
        else:
            x, P, phi = propagate_reference(self.layout, self._x, self._P, self._f, self._w, dt, self._g,
                                            self._q_in, self._q_rw, self._yaw_pos)
        self._x, self._P = x, P
        self._counts["predicts"] += 1
        if self.on_predict is not None and not self._replaying:
            self.on_predict(phi)
        self._check_finite()

    # ---------------------------------------------------------------- update
    def update(self, kind, z, R, t_ns: int | None = None, aux=None) -> UpdateResult:
        """One update with measurement ``z`` (m,) and covariance ``R`` (m, m) of ``kind`` taken at
        ``t_ns`` (None: now). NaN rows of z are dropped; t_ns in the future predicts first; in
        the past uses the history (module docstring). Wrong shapes raise ValueError."""
        if kind.__class__ is not ObsKind:
            kind = ObsKind(kind)
        model = self._models[kind]
        z = np.asarray(z, dtype=float)
        R = np.asarray(R, dtype=float)
        if z.shape != (model.dim,):
            raise ValueError(f"{kind.value}: z must be 1-D of length {model.dim}, got shape {z.shape}")
        if R.shape != (model.dim, model.dim):
            raise ValueError(f"{kind.value}: R must be of shape ({model.dim}, {model.dim}), got {R.shape}")
        t_m = self._t if t_ns is None else int(t_ns)
        if kind not in self._kinds:
            return self._finish(UpdateResult(kind, t_m if t_m is not None else 0, "disabled"), True)
        if self._x is None:
            return self._finish(UpdateResult(kind, t_m if t_m is not None else 0, "not_initialized"), True)
        if t_m > self._t:
            self.predict_to(t_m)
            if self._x is None:
                return self._finish(UpdateResult(kind, t_m, "not_initialized"), True)
        if t_m >= self._t:
            return self._apply(kind, z, R, t_m, aux, count=True)
        return self._delayed(kind, z, R, t_m, aux)

    def _apply(self, kind: ObsKind, z, R, t_m: int, aux, count: bool, delayed: bool = False) -> UpdateResult:
        if not np.isfinite(z).any():
            return self._finish(UpdateResult(kind, t_m, "nan", delayed=delayed), count)
        if self._hist_ns > 0:
            self._record(False, t_m, (kind, z.copy(), R.copy(), aux))
        if self.compiled:
            status, dof, nis, gate, innov, sig, x, P, H, R = self._update_compiled(kind, z, R, aux, t_m)
        else:
            status, dof, nis, gate, innov, sig, x, P, H, R = update_reference(
                self._models[kind], self.layout, self._x, self._P, z, R, aux, self._iterations_at(kind, t_m),
                self._gates, self._yaw_pos)
        if not dof:  # non-finite R or innovation, or a singular S
            return self._finish(UpdateResult(kind, t_m, "nan", delayed=delayed), count)
        if count:
            self._last_innov = np.array(innov)
        res = UpdateResult(kind, t_m, status, innov, sig, nis, dof, gate, delayed)
        if status != "accepted":
            return self._finish(res, count)
        self._x, self._P = x, P
        if self.on_update is not None and not self._replaying:
            self.on_update(H, R)
        res = self._finish(res, count)
        self._check_finite()
        return res

    def _iterations_at(self, kind: ObsKind, t_m: int) -> int:
        """Iterations of an update of ``kind`` at ``t_m``: 1 before ``plain_until_ns``."""
        return 1 if t_m < self.plain_until_ns else self._iterations.get(kind, 1)

    def _update_compiled(self, kind: ObsKind, z, R, aux, t_m: int) -> tuple:
        """``update_reference``'s result from the compiled kernel (``ekf_update_kernels.update``)."""
        code = _KIND_CODE[kind]
        aux_arr, has_aux = _aux_array(code, aux)
        n, m = self._n, z.shape[0]
        x, P = self._x.copy(), self._P.copy()
        innov, sig, H, R_used = np.empty(m), np.empty(m), np.empty((m, n)), np.empty((m, m))
        idx, pos, flags, yaw = self._lay
        params, wheels = self._model_params
        st, dof, nis, gate, _ = UK.update(code, x, P, z, R, aux_arr, has_aux, idx, pos, flags, yaw, params, wheels,
                                          self._iterations_at(kind, t_m), self._gate_array, innov, sig, H, R_used)
        inn, sg = tuple(innov[:dof].tolist()), tuple(sig[:dof].tolist())
        return (_KERNEL_STATUS[st], dof, nis, gate, inn, sg, x, P, H[:dof], R_used[:dof, :dof])

    def _finish(self, res: UpdateResult, count: bool) -> UpdateResult:
        if count:
            self._kind_counts[res.kind][res.status] += 1
            self._last = res
        return res

    # ---------------------------------------------------------------- latency
    def _record(self, is_predict: bool, t1: int, payload: tuple) -> None:
        self._hist.record(Event(is_predict, self._t, self._x.copy(), self._P.copy(), t1, payload))

    def _delayed(self, kind: ObsKind, z, R, t_m: int, aux) -> UpdateResult:
        later = self._hist.take_from(t_m) if self._hist.reaches(t_m) else None  # the events to re-run
        if later is None:  # the history does not reach back to t_m
            return self._finish(UpdateResult(kind, t_m, "too_old", delayed=True), True)
        if not later:  # nothing after t_m: cannot happen since t_m < self._t, but be safe
            return self._apply(kind, z, R, self._t, aux, count=True, delayed=True)
        first = later[0]
        f_now, w_now = self._f, self._w
        self._x, self._P, self._t = first.x0.copy(), first.p0.copy(), first.t0
        self._counts["delayed_updates"] += 1
        try:
            if first.is_predict and first.t0 < t_m:
                self._f, self._w = first.payload
                self.predict_to(t_m)
            result = self._apply(kind, z, R, t_m, aux, count=True, delayed=True)
            self._replaying = True  # re-propagation: recorded again, not counted, no hooks
            for ev in later:
                if self._x is None:
                    break
                if ev.is_predict:
                    self._f, self._w = ev.payload
                    self.predict_to(ev.t1)
                else:
                    k, zz, rr, ax = ev.payload
                    self._apply(k, zz, rr, ev.t1, ax, count=False)
        finally:
            self._replaying = False
            self._f, self._w = f_now, w_now
        return result

    # ---------------------------------------------------------------- outputs
    def full_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(x_full (12,), P_full (12, 12)) with psi_v from eq 4 when derived and fixed road
        angles at zero variance."""
        if self._x is None:
            raise RuntimeError("filter not initialised")
        return self.layout.full_covariance(self._x, self._P)

    def _wrap(self) -> None:
        wrap_positions(self._x, self._yaw_pos)

    def _check_finite(self) -> None:
        x = self._x
        if x is not None and not (math.isfinite(_sum(x, None)) and math.isfinite(_sum(self._P, None))):
            self.reset("nan")


_sum = np.add.reduce  # ndarray.sum without its Python wrapper (axis None: the same reduction)
_KIND_CODE = {ObsKind(v): i for i, v in enumerate(UK.KIND_CODES)}
_KERNEL_STATUS = {UK.ACCEPTED: "accepted", UK.GATED: "gated", UK.NAN: "nan"}
_NO_AUX = np.zeros(11)


def _aux_array(code: int, aux) -> tuple[np.ndarray, bool]:
    """The ``aux`` of an update as the kernel's float array (``ekf_update_kernels``)."""
    if aux is None:
        return _NO_AUX, False
    if code == 7:  # wheel speed: (w, headings, weights)
        w, d, a = aux
        return np.array([*(float(v) for v in w), *(float(v) for v in d), *(float(v) for v in a)]), True
    if code == 3:  # y2_gps: theta_v
        return np.array([float(aux)]), True
    return np.array([float(v) for v in aux]), True


def _ro(a):
    if a is None:
        return None
    v = a.view()
    v.flags.writeable = False
    return v

