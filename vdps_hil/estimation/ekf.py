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

Corrections of the paper (``PaperFaithful``: True = as printed, the default False = corrected):

(a) ``a_psi_v_zero_rate``: eq 6 gives psi_v a zero rate, so between GPS epochs it lags the
    heading (by yaw rate x 0.2 s at 5 Hz). With psi_r = 0 only five of the six angles are
    independent; corrected, psi_v is *derived* from eq 4 (``StateLayout(psi_v_state=False)``)
    and the filter carries 11 states.
(b) ``b_y2_gps``: y2^gps is computed from the same GNSS attitude as y1^gps, so using both
    counts that attitude twice with independent noise. Corrected: y2^gps is dropped (with (a)
    corrected psi_v needs no observation of its own). Faithful: y2^gps is used with
    R = J R_att J^T + floor^2 I (``observations.y2_gps_measurement``; the isotropic floor, by
    default the angle sigma, keeps the lagging zero-rate psi_v from being gated on the radial
    direction of the unit-circle measurement, and also weakens the double counting).
(c) ``c_y2_sus_single_plane``: y2^sus = n . p assumes one road plane through the ENU origin.
    Corrected: that form is used only when ``road_plane_through_origin`` is configured true;
    otherwise the locally referenced form n . v = dz_r/dt (``observations.Y2SusRate``).
(d) ``d_accel_as_acceleration``: eq 7 integrates the accelerometer as if it measured the
    kinematic acceleration; it measures specific force. Corrected: gravity [0, 0, -g] is added.

Latency (measurement time-stamped in the past, t_m < filter time): the filter keeps a history
of (x, P) snapshots before every predict and update of the last ``history_s`` seconds. A late
measurement rewinds to the snapshot before t_m, predicts to t_m with the stored input, applies
the update, and re-propagates with the stored inputs, re-applying the stored later updates
(re-gated, not re-counted). Older than the history: rejected and counted ``too_old``.

Reset on NaN: a non-finite x or P after any step resets the filter to uninitialised (counted
``nan_resets``); the caller (pipeline) re-initialises from the next fixes. A measurement that
is entirely NaN is counted ``nan`` (partial NaN: those rows are dropped).

Process noise: white IMU noise sigma per sample at f_imu gives q = sigma^2 / f_imu for the mean
input (``kinematics``); axes an ESC cluster does not provide (w_x, w_y, f_z) are substituted by
0, 0, g with PSD 2 sigma_sub^2 tau_sub (first-order Markov at low frequency). Road angles (and
psi_v in the faithful (a) variant) are random walks.

Real-car extensions (not in the paper; every one OFF by default, so the paper's Table-1 set
runs eq 7-11 as before; the sensor sets of real cars in ``configs/sensorsets`` switch them on):

* IMU bias states (``gyro_bias``, ``accel_bias``; ``states.AugStates``): the inputs become
  w_b = w_meas - b_g, f_b = f_meas - b_a, with b random walks (``gyro_bias_rw`` [rad/s/sqrt(s)],
  ``accel_bias_rw`` [m/s^2/sqrt(s)]) and prior sigmas ``gyro_bias_sigma_radps``,
  ``accel_bias_sigma_mps2``; d x_dot / d b_g = -G_w, d x_dot / d b_a = -G_f (G = d f/d [f, w]).
  Only the axes the IMU has (ESC cluster: b_g,z, b_a,x, b_a,y).
* Wheel speed (``wheel_speed``): the ``wheel_speed`` observation (``observations.WheelSpeed``),
  optionally with the scale state k_w (``wheel_scale_state``, random walk ``wheel_scale_rw``).
* Non-holonomic constraint (``nonholonomic``): the ``nhc`` observation
  (``observations.NonHolonomic``).
* Re-acquisition (``reacquire``): after persistent gating of the position the caller resets
  position, velocity and yaw to the fixes (their cross-covariances dropped) and keeps the rest
  (attitude, biases); counted ``reacquisitions``.
"""

from __future__ import annotations

import bisect
import math
import types
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from vdps_hil.estimation.kinematics import linearize, step, transition
from vdps_hil.estimation.observations import (ObsKind, make_models, rear_axle_ground_point,
                                              wheel_positions)
from vdps_hil.estimation.states import N_EXT, N_FULL, AugStates, States, StateLayout
from vdps_hil.units import GRAVITY_MPS2, deg2rad


def _chi2_tails(x: float, dof: int) -> tuple[float, float]:
    """(lower, upper) tail of the chi-square distribution with integer ``dof`` >= 1 at ``x``,
    each in closed form without cancellation: with h = x/2 and the series
    s = e^-h sum_{i<dof/2} h^i / i! (even dof) or e^-h sum_{i<(dof-1)/2} h^(i+1/2) / Gamma(i+3/2)
    (odd dof), upper = s (even) or erfc(sqrt h) + s (odd); lower = 1 - s (even) or
    erf(sqrt h) - s (odd) (the regularised incomplete gamma functions of dof/2, h)."""
    if not x > 0.0:
        return 0.0, 1.0
    h = 0.5 * x
    if dof % 2 == 0:
        term = total = 1.0
        for i in range(1, dof // 2):
            term *= h / i
            total += term
        s = math.exp(-h) * total
        return 1.0 - s, s
    r = math.sqrt(h)
    s = 0.0
    if dof > 1:
        term = total = r / math.gamma(1.5)
        for i in range(1, dof // 2):
            term *= h / (i + 0.5)
            total += term
        s = math.exp(-h) * total
    return math.erf(r) - s, math.erfc(r) + s


def chi2_cdf(x: float, dof: int) -> float:
    """Chi-square CDF for an integer ``dof`` >= 1 (:func:`_chi2_tails`)."""
    return _chi2_tails(x, dof)[0]


def chi2_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of the chi-square distribution with integer ``dof`` (the innovation
    gate), by bisection to adjacent doubles on the lower tail (p <= 0.5) or on the upper tail
    against 1 - p (exact in floating point for p > 0.5), so a gate probability near 1 keeps its
    precision. Tested against scipy's ``chi2.ppf``; computed here because importing
    ``scipy.stats`` costs every replay, bench and logger process ~0.4 s."""
    if not 0.0 < p < 1.0 or int(dof) != dof or dof < 1:
        raise ValueError(f"chi2_quantile needs 0 < p < 1 and an integer dof >= 1, got p={p!r}, dof={dof!r}")
    upper = p > 0.5
    q = 1.0 - p if upper else p

    def below(x: float) -> bool:  # is x below the quantile?
        lo_tail, up_tail = _chi2_tails(x, dof)
        return up_tail > q if upper else lo_tail < q

    lo, hi = 0.0, float(dof) + 10.0
    while below(hi):
        lo, hi = hi, 2.0 * hi
    while True:
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:  # adjacent doubles
            return hi
        if below(mid):
            lo = mid
        else:
            hi = mid


_TWO_PI = 2.0 * math.pi
_IMU_KINDS = ("6axis", "esc3")
_GNSS_KINDS = ("multi_antenna", "single_antenna", "none")


@dataclass(frozen=True)
class PaperFaithful:
    """One switch per documented correction; True implements the paper as printed."""

    a_psi_v_zero_rate: bool = False
    b_y2_gps: bool = False
    c_y2_sus_single_plane: bool = False
    d_accel_as_acceleration: bool = False

    @classmethod
    def all(cls) -> "PaperFaithful":
        return cls(True, True, True, True)

    @classmethod
    def only(cls, name: str) -> "PaperFaithful":
        """Only the named switch faithful (``"a_psi_v_zero_rate"`` ...)."""
        if name not in cls.__dataclass_fields__:
            raise ValueError(f"unknown paper_faithful switch {name!r}")
        return cls(**{name: True})

    def any(self) -> bool:
        return any((self.a_psi_v_zero_rate, self.b_y2_gps, self.c_y2_sus_single_plane,
                    self.d_accel_as_acceleration))


@dataclass(frozen=True)
class SensorSet:
    """Which sources exist. ``imu``: "6axis" (serial IMU) or "esc3" (ESC cluster on CAN: yaw
    rate, a_x, a_y only). ``gnss``: "multi_antenna" (position + attitude), "single_antenna"
    (position + speed/course) or "none". ``suspension``/``wheel_speeds``: fitted or not."""

    imu: str = "6axis"
    gnss: str = "multi_antenna"
    suspension: bool = True
    wheel_speeds: bool = True

    def __post_init__(self):
        if self.imu not in _IMU_KINDS:
            raise ValueError(f"SensorSet.imu must be one of {_IMU_KINDS}, got {self.imu!r}")
        if self.gnss not in _GNSS_KINDS:
            raise ValueError(f"SensorSet.gnss must be one of {_GNSS_KINDS}, got {self.gnss!r}")

    @classmethod
    def paper(cls) -> "SensorSet":
        """Table 1: 3-antenna GNSS, 6-axis IMU, four suspension sensors, tachometers."""
        return cls()


@dataclass(frozen=True)
class EkfConfig:
    """Filter configuration; the state layout and the enabled measurement kinds follow from it.

    Noise figures default to Table 1 (accelerometer 0.02 m/s^2 and gyro 0.08 deg/s at 1 kHz)."""

    sensors: SensorSet = field(default_factory=SensorSet)
    paper_faithful: PaperFaithful = field(default_factory=PaperFaithful)
    estimate_road: bool | None = None  # None: estimate road angles iff suspension is fitted
    road_plane_through_origin: bool = False  # (c): y2^sus = n.p valid (one plane through origin)
    use_gnss_velocity: bool = True  # speed/course updates when such samples arrive
    gravity_mps2: float = GRAVITY_MPS2
    imu_rate_hz: float = 1000.0
    accel_noise_mps2: float = 0.02  # per-sample sigma at imu_rate_hz (Table 1)
    gyro_noise_radps: float = float(deg2rad(0.08))  # per-sample sigma (Table 1)
    accel_model_psd: float = 0.0  # extra white acceleration PSD [(m/s^2)^2 s] (bias, vibration)
    gyro_model_psd: float = 0.0  # extra white rate PSD [(rad/s)^2 s]
    substitute_accel_sigma_mps2: float = 0.5  # esc3: f_z := g, error sigma
    substitute_gyro_sigma_radps: float = 0.05  # esc3: w_x = w_y := 0, error sigma
    substitute_corr_time_s: float = 0.2  # esc3: correlation time of the substitution error
    road_angle_rw: float = 3e-4  # road angle random walk [rad/sqrt(s)]
    psi_v_rw: float = 0.3  # faithful (a) only: psi_v random walk [rad/sqrt(s)]
    gate_probability: float | None = 0.9999  # chi-square gate; None disables gating
    history_s: float = 1.0  # latency buffer length [s]; 0 disables late measurements
    max_step_s: float = 0.05  # longest single predict step [s] (longer spans are split)
    update_iterations: int = 3  # iterated-EKF relinearisations for the nonlinear kinds (1 = EKF)
    # real-car extensions (module docstring); all off for the paper's Table-1 set
    gyro_bias: bool = False  # gyro bias states b_g (the axes the IMU has)
    accel_bias: bool = False  # accelerometer bias states b_a
    gyro_bias_sigma_radps: float = float(deg2rad(0.5))  # prior sigma of b_g
    accel_bias_sigma_mps2: float = 0.1  # prior sigma of b_a
    gyro_bias_rw: float = 1e-4  # b_g random walk [rad/s/sqrt(s)]
    accel_bias_rw: float = 1e-3  # b_a random walk [m/s^2/sqrt(s)]
    wheel_speed: bool = False  # wheel_speed rows (needs sensors.wheel_speeds)
    wheel_scale_state: bool = False  # wheel-speed scale state k_w (with wheel_speed)
    wheel_scale_sigma: float = 0.02  # prior sigma of k_w [-]
    wheel_scale_rw: float = 1e-4  # k_w random walk [1/sqrt(s)]
    nonholonomic: bool = False  # nhc rows (no lateral/vertical velocity at the rear axle)

    def __post_init__(self):
        for name in ("imu_rate_hz", "accel_noise_mps2", "gyro_noise_radps", "substitute_accel_sigma_mps2",
                     "substitute_gyro_sigma_radps", "substitute_corr_time_s", "max_step_s",
                     "gyro_bias_sigma_radps", "accel_bias_sigma_mps2", "wheel_scale_sigma"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"EkfConfig.{name} must be a positive finite number, got {v!r}")
        for name in ("gyro_bias", "accel_bias", "wheel_speed", "wheel_scale_state", "nonholonomic"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"EkfConfig.{name} must be true or false, got {getattr(self, name)!r}")
        for name in ("accel_model_psd", "gyro_model_psd", "road_angle_rw", "psi_v_rw", "history_s", "gravity_mps2",
                     "gyro_bias_rw", "accel_bias_rw", "wheel_scale_rw"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"EkfConfig.{name} must be a non-negative finite number, got {v!r}")
        if not (isinstance(self.update_iterations, int) and 1 <= self.update_iterations <= 20):
            raise ValueError(f"EkfConfig.update_iterations must be an integer in 1..20, got {self.update_iterations!r}")
        if self.gate_probability is not None and not (0.0 < self.gate_probability < 1.0):
            raise ValueError(f"EkfConfig.gate_probability must be in (0, 1) or None, got {self.gate_probability!r}")

    @property
    def road_estimated(self) -> bool:
        return self.sensors.suspension if self.estimate_road is None else bool(self.estimate_road)

    def with_real_car_rows(self) -> "EkfConfig":
        """This configuration with the real-car extensions on (module docstring): IMU bias states,
        the non-holonomic constraint and, when wheel speeds are fitted, the wheel-speed row and
        its scale state (what ``configs/sensorsets`` of real cars switch on; e.g. for a sensor set
        inferred from a recording without multi-antenna attitude)."""
        import dataclasses

        ws = self.sensors.wheel_speeds
        return dataclasses.replace(self, gyro_bias=True, accel_bias=True, nonholonomic=True, wheel_speed=ws,
                                   wheel_scale_state=ws)

    @property
    def gyro_bias_axes(self) -> tuple[int, ...]:
        """Body axes with a gyro bias state (ESC cluster: z only)."""
        if not self.gyro_bias:
            return ()
        return (2,) if self.sensors.imu == "esc3" else (0, 1, 2)

    @property
    def accel_bias_axes(self) -> tuple[int, ...]:
        """Body axes with an accelerometer bias state (ESC cluster: x, y)."""
        if not self.accel_bias:
            return ()
        return (0, 1) if self.sensors.imu == "esc3" else (0, 1, 2)

    @property
    def uses_wheel_speed(self) -> bool:
        return self.wheel_speed and self.sensors.wheel_speeds

    def layout(self) -> StateLayout:
        road = self.road_estimated
        return StateLayout(road_estimated=road, psi_v_state=road and self.paper_faithful.a_psi_v_zero_rate,
                           gyro_bias_axes=self.gyro_bias_axes, accel_bias_axes=self.accel_bias_axes,
                           wheel_scale=self.uses_wheel_speed and self.wheel_scale_state)

    def kinds(self) -> frozenset[ObsKind]:
        """Measurement kinds this configuration uses (eq 9 rows that exist for the sensors)."""
        s, pf, road = self.sensors, self.paper_faithful, self.road_estimated
        k: set[ObsKind] = set()
        if s.gnss != "none":
            k.add(ObsKind.GNSS_POS)
            if self.use_gnss_velocity:
                k.add(ObsKind.GNSS_VEL)
        if s.gnss == "multi_antenna":
            k.add(ObsKind.GNSS_ATT)
            if road and pf.b_y2_gps:
                k.add(ObsKind.Y2_GPS)
        if s.suspension and road:
            k.add(ObsKind.Y1_SUS)
            if pf.c_y2_sus_single_plane or self.road_plane_through_origin:
                k.add(ObsKind.Y2_SUS_PLANE)
            else:
                k.add(ObsKind.Y2_SUS_RATE)
        if self.uses_wheel_speed:
            k.add(ObsKind.WHEEL_SPEED)
        if self.nonholonomic:
            k.add(ObsKind.NHC)
        return frozenset(k)

    def input_psd(self) -> np.ndarray:
        """q_u = [q_ax, q_ay, q_az, q_wx, q_wy, q_wz] of the mean IMU input (module docstring)."""
        qa = self.accel_noise_mps2 ** 2 / self.imu_rate_hz + self.accel_model_psd
        qg = self.gyro_noise_radps ** 2 / self.imu_rate_hz + self.gyro_model_psd
        q = np.array([qa, qa, qa, qg, qg, qg])
        if self.sensors.imu == "esc3":
            tau = self.substitute_corr_time_s
            q[2] = 2.0 * self.substitute_accel_sigma_mps2 ** 2 * tau
            q[3] = q[4] = 2.0 * self.substitute_gyro_sigma_radps ** 2 * tau
        return q

    @property
    def gravity_in_model_mps2(self) -> float:
        """g added to the velocity equation: 0 when faithful (d)."""
        return 0.0 if self.paper_faithful.d_accel_as_acceleration else self.gravity_mps2


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


def filter_jacobians(layout: StateLayout, x_ext, f_b, w_b) -> tuple[np.ndarray, np.ndarray]:
    """(F, G) of the continuous model in the filter layout at the extended state ``x_ext``
    (N_EXT) with the bias-corrected inputs ``f_b``, ``w_b``: F = d x_dot / d x (n x n),
    G = d x_dot / d [f, w] (n x 6). The bias columns are -G of their input axes (module
    docstring); augmented states have zero rows (random walks)."""
    idx = layout.full_index
    nk = layout.n_kinematic
    kin = idx[:nk]
    F12, G12 = linearize(x_ext[:N_FULL], f_b, w_b)
    if nk == layout.n:
        return F12[np.ix_(kin, kin)], G12[kin]
    n = layout.n
    F = np.zeros((n, n))
    F[:nk, :nk] = F12[np.ix_(kin, kin)]
    Gk = G12[kin]
    for j in range(nk, n):
        s = int(idx[j])
        if AugStates.BG_X <= s <= AugStates.BG_Z:
            F[:nk, j] = -Gk[:, 3 + s - AugStates.BG_X]
        elif AugStates.BA_X <= s <= AugStates.BA_Z:
            F[:nk, j] = -Gk[:, s - AugStates.BA_X]
    G = np.zeros((n, 6))
    G[:nk] = Gk
    return F, G


def _event_end(ev: "_Event") -> int:
    return ev.t1


@dataclass
class _Event:
    is_predict: bool
    t0: int  # filter time before the event
    x0: np.ndarray
    p0: np.ndarray
    t1: int  # predict: end time; update: measurement time
    payload: tuple


class MultiRateEKF:
    """The multi-rate EKF of eq 7-11 (pure object: no threads, no devices, no clocks).

    ``x``/``P`` are the *filter* vector and covariance (``layout``); ``full_state()`` gives the
    12 states of eq 7 with derived/fixed ones filled in."""

    def __init__(self, config: EkfConfig | None = None, gnss_lever_arm_m=(0.0, 0.0, 0.0), wheel_positions_m=None,
                 nhc_point_m=(0.0, 0.0, 0.0)):
        self.config = config or EkfConfig()
        self.layout = self.config.layout()
        self._idx = self.layout.full_index
        self._n = self.layout.n
        self._aug = self.layout.augmented
        self._ix = np.ix_(self._idx, self._idx)
        self._models = make_models(gnss_lever_arm_m, wheel_positions_m, nhc_point_m)
        self._kinds = self.config.kinds()
        self._q_in = self.config.input_psd()
        q_rw = np.zeros(N_EXT)
        q_rw[States.PHI_R] = q_rw[States.THETA_R] = self.config.road_angle_rw ** 2
        q_rw[States.PSI_V] = self.config.psi_v_rw ** 2
        q_rw[AugStates.BG_X:AugStates.BG_Z + 1] = self.config.gyro_bias_rw ** 2
        q_rw[AugStates.BA_X:AugStates.BA_Z + 1] = self.config.accel_bias_rw ** 2
        q_rw[AugStates.WHEEL_SCALE] = self.config.wheel_scale_rw ** 2
        self._q_rw = np.diag(q_rw[self._idx])
        self._pos_bg = [(self.layout.index(AugStates.BG_X + a), a) for a in self.layout.gyro_bias_axes]
        self._pos_ba = [(self.layout.index(AugStates.BA_X + a), a) for a in self.layout.accel_bias_axes]
        self._g = self.config.gravity_in_model_mps2
        p = self.config.gate_probability
        self._gates = {d: (chi2_quantile(p, d) if p is not None else math.inf) for d in range(1, 7)}
        self._yaw_pos = [i for i, s in enumerate(self._idx) if s in (States.PSI_G, States.PSI_V)]
        self._iterations = {k: self.config.update_iterations for k in NONLINEAR_KINDS}
        self._hist_ns = int(round(self.config.history_s * 1e9))
        self._max_step_ns = int(round(self.config.max_step_s * 1e9))
        self._f = np.array([0.0, 0.0, self.config.gravity_mps2])
        self._w = np.zeros(3)
        self._x: np.ndarray | None = None
        self._P: np.ndarray | None = None
        self._t: int | None = None
        self._hist: deque[_Event] = deque()
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
        """Re-acquisition after persistent gating (module docstring): at the filter time
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
        idx, n = self._idx, self._n
        if self._aug:
            xe = np.zeros(N_EXT)
            xe[idx] = self._x
            f = self._f - xe[AugStates.BA_X:AugStates.BA_Z + 1]
            w = self._w - xe[AugStates.BG_X:AugStates.BG_Z + 1]
            F, G = filter_jacobians(self.layout, xe, f, w)
            xn = xe.copy()
            xn[:N_FULL] = step(xe[:N_FULL], f, w, dt, self._g)
        else:
            xf = np.zeros(N_FULL)
            xf[idx] = self._x
            F, G = linearize(xf, self._f, self._w)
            xn = step(xf, self._f, self._w, dt, self._g)
            if n != N_FULL:
                F = F[self._ix]
                G = G[idx]
        phi = transition(F, dt)
        qc = (G * self._q_in) @ G.T + self._q_rw
        qd = (phi @ qc @ phi.T + qc) * (0.5 * dt)
        P = phi @ self._P @ phi.T + qd
        self._P = 0.5 * (P + P.T)
        self._x = xn[idx]
        self._wrap()
        self._counts["predicts"] += 1
        if self.on_predict is not None and not self._replaying:
            self.on_predict(phi)
        self._check_finite()

    # ---------------------------------------------------------------- update
    def update(self, kind, z, R, t_ns: int | None = None, aux=None) -> UpdateResult:
        """One update with measurement ``z`` (m,) and covariance ``R`` (m, m) of ``kind`` taken at
        ``t_ns`` (None: now). NaN rows of z are dropped; t_ns in the future predicts first; in
        the past uses the history (module docstring). Wrong shapes raise ValueError."""
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
        model = self._models[kind]
        ok = np.isfinite(z)
        if not ok.any():
            return self._finish(UpdateResult(kind, t_m, "nan", delayed=delayed), count)
        if self._hist_ns > 0:
            self._record(False, t_m, (kind, z.copy(), R.copy(), aux))
        xf, E = self.layout.expand(self._x, ext=self._aug)
        y = model.h(xf, aux)
        H = model.jacobian(xf, aux)
        H = H @ (E if H.shape[1] == E.shape[0] else E[:H.shape[1]])
        nu = model.residual(z, y)
        if not ok.all():
            nu, H, R = nu[ok], H[ok], R[np.ix_(ok, ok)]
        if not np.isfinite(R).all() or not np.isfinite(nu).all():
            return self._finish(UpdateResult(kind, t_m, "nan", delayed=delayed), count)
        P = self._P
        PHt = P @ H.T
        S = H @ PHt + R
        try:
            S_inv = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            return self._finish(UpdateResult(kind, t_m, "nan", delayed=delayed), count)
        nis = float(nu @ S_inv @ nu)
        dof = int(nu.shape[0])
        gate = self._gates.get(dof, math.inf)
        innov = tuple(float(v) for v in nu)
        sig = tuple(float(math.sqrt(max(0.0, S[i, i]))) for i in range(dof))
        if count:
            self._last_innov = nu.copy()
        if not math.isfinite(nis) or nis > gate:
            status = "gated" if math.isfinite(nis) else "nan"
            return self._finish(UpdateResult(kind, t_m, status, innov, sig, nis, dof, gate, delayed), count)
        K = PHt @ S_inv
        x0 = self._x
        x_new = x0 + K @ nu
        for _ in range(self._iterations.get(kind, 1) - 1):
            # iterated EKF (Gauss-Newton): relinearise at the new estimate
            dx = x_new - x0
            xf_i, E_i = self.layout.expand(x_new, ext=self._aug)
            H_i = model.jacobian(xf_i, aux)
            H_i = H_i @ (E_i if H_i.shape[1] == E_i.shape[0] else E_i[:H_i.shape[1]])
            nu_i = model.residual(z, model.h(xf_i, aux))
            if not ok.all():
                H_i, nu_i = H_i[ok], nu_i[ok]
            PHt_i = P @ H_i.T
            try:
                K_i = PHt_i @ np.linalg.inv(H_i @ PHt_i + R)
            except np.linalg.LinAlgError:
                break
            x_next = x0 + K_i @ (nu_i + H_i @ dx)
            H, K = H_i, K_i
            step_size = float(np.abs(x_next - x_new).max())
            x_new = x_next
            if not math.isfinite(step_size) or step_size < 1e-12:
                break
        self._x = x_new
        ikh = np.eye(self._n) - K @ H
        P = ikh @ P @ ikh.T + K @ R @ K.T
        self._P = 0.5 * (P + P.T)
        self._wrap()
        if self.on_update is not None and not self._replaying:
            self.on_update(H, R)
        res = self._finish(UpdateResult(kind, t_m, "accepted", innov, sig, nis, dof, gate, delayed), count)
        self._check_finite()
        return res

    def _finish(self, res: UpdateResult, count: bool) -> UpdateResult:
        if count:
            self._kind_counts[res.kind][res.status] += 1
            self._last = res
        return res

    # ---------------------------------------------------------------- latency
    def _record(self, is_predict: bool, t1: int, payload: tuple) -> None:
        self._hist.append(_Event(is_predict, self._t, self._x.copy(), self._P.copy(), t1, payload))
        horizon = self._t - self._hist_ns
        while self._hist and self._hist[0].t1 < horizon:
            self._hist.popleft()

    def _delayed(self, kind: ObsKind, z, R, t_m: int, aux) -> UpdateResult:
        hist = self._hist
        if not hist or hist[0].t0 > t_m:
            return self._finish(UpdateResult(kind, t_m, "too_old", delayed=True), True)
        # the first event ending after t_m (the history is in processing order, so its end
        # times t1 never decrease: each event ends at or after the filter time it starts from)
        i = bisect.bisect_right(hist, t_m, key=_event_end)
        if i == len(hist):  # nothing after t_m: cannot happen since t_m < self._t, but be safe
            return self._apply(kind, z, R, self._t, aux, count=True, delayed=True)
        first = hist[i]
        if first.t0 > t_m:  # history does not reach back to t_m
            return self._finish(UpdateResult(kind, t_m, "too_old", delayed=True), True)
        later = [hist.pop() for _ in range(len(hist) - i)]
        later.reverse()
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
        for i in self._yaw_pos:
            v = self._x[i]
            if v >= math.pi or v < -math.pi:
                self._x[i] = (v + math.pi) % _TWO_PI - math.pi

    def _check_finite(self) -> None:
        if self._x is not None and not (math.isfinite(float(self._x.sum())) and math.isfinite(float(self._P.sum()))):
            self.reset("nan")


def _ro(a):
    if a is None:
        return None
    v = a.view()
    v.flags.writeable = False
    return v

