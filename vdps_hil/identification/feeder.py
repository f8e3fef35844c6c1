"""The identifier's inputs (``IdentInputs``) built from the estimator's outputs only.

Paper section 5: the estimated states "are transformed into the aux-frame using the matrices of
eq 1-3" and fed, with the alpha-beta filtered rates and accelerations (eq 12), to the four RLS
problems (eq 20-23). ``IdentFeeder(model_vehicle).inputs(estimate, filtered)`` does that for one
instant; ``observe(sample)`` collects the IMU specific force between two calls. Every input is
an *estimate* (EKF state, alpha-beta outputs, sensor samples); simulator truth never enters.

Frames (``vdps_hil.conventions``; ``C_a^b`` maps coordinates in a to coordinates in b)::

    C_g^v = R(x, phi_g) R(y, theta_g) R(z, psi_g)              eq 1 (EKF attitude)
    C_g^r = R(x, phi_r) R(y, theta_r)                           eq 2 (psi_r = 0; EKF road angles)
    C_r^a = R(z, psi_v)                                         aux frame, section 2
    C_g^a = C_r^a C_g^r

Velocity and acceleration in the aux frame::

    [xd_a, yd_a, zd_a] = C_g^a v_g                              v_g: EKF CG velocity, ENU
    a_a = C_g^a (C_g^v)^T f_cg + G                              inertial CG acceleration in {a}
    G   = R(z, psi_v) R(x, phi_r) R(y, theta_r) [0, 0, -g]       eq 13 (``gravity_aux_mps2``)
    f_cg = C_bs f_s - wd x l - w x (w x l)                       IMU specific force at the CG

``f_s`` is the mean of the IMU samples of the last ``accel_window_s`` (2 ms: two samples at
1 kHz, 0.5 ms of lag) up to the estimate's time (``observe`` keeps the recent ones), rotated to the
body by the model file's ``imu_rotation_rpy_rad`` (C_bs = (C_g^v(rpy))^T, as the pipeline) and
moved to the CG by the lever arm ``l`` with the alpha-beta rate w and its derivative wd. We use
the specific force rather than differentiating the EKF velocity: the accelerometer has
0.02 m/s^2 of noise at 1 kHz (Table 1) and no lag, while the EKF velocity jumps at every GNSS
update (5 Hz), so its derivative has spikes; the two agree in the mean (the EKF integrates the
same specific force, eq 7 with correction (d)). An ESC cluster without f_z gets f_z = g.

Eq 13 writes the translation in the aux frame, which turns with the vehicle about the road
normal at psid_v, so the component derivatives are::

    xdd_a = a_a,x + yd_a psid_v,   ydd_a = a_a,y - xd_a psid_v,   zdd_a = a_a,z   (vertical "aux")
    zdd_a = f_cg,z + G_z                                                       (vertical "struts")

Vertical (``FeederConfig.vertical``, default ``"struts"``): eq 20 balances the strut forces
(along the body z axis) with m (zdd_a - G_z). Eq 13 writes the vehicle-frame forces in the aux
frame (small angles), but in a corner the body rolls by phi_v while the lateral acceleration
a_y is large, and the aux-frame vertical acceleration differs from the body-z one by about
a_y sin(phi_v) -- always of one sign (roll follows the lateral acceleration), so it biases the
mass: m_tot came out -0.59 % on the paper's scenario fed with the simulator's truth state, and
+0.07 % with ``"struts"``, where A = zdd_a - G_z is the specific force along the struts (body z,
the axis the springs act on). ``"aux"`` keeps the literal aux-frame value.
    [phid_v, thetad_v, psid_v] = C_omega(phi_v, theta_v)^-1 w    (eq 7's C_omega with the
                                                                   road-relative angles; road
                                                                   angles constant, eq 6)

Tire quantities from the physics core (``vdps_hil.model.core``: the same definitions the truth
simulator and the predictor use): the core's reduced model (``unsprung_dof=False``) is
evaluated at the estimated state -- body velocity v_b = C_g^v v_g, body rates w (alpha-beta),
wheel spins (alpha-beta), the estimated road plane (phi_r, theta_r) and the measured steering
wheel angle -- giving per wheel::

    d_1,2 = Ackermann(delta_sw / steer_ratio),  d_3,4 = 0                (stages.ackermann_angles)
    lambda_i = (r_i w_i - v_l,i) / max(|v_l,i|, v_floor)                  slip ratio
    alpha_i  = -atan(v_t,i / max(|v_l,i|, v_floor))                       slip angle

with v_l, v_t the wheel-centre velocity along and across the wheel in the road plane and
v_floor the core's slip speed floor (5 m/s). Suspension deflections and rates, wheel speeds and
accelerations, body rates and angular accelerations are the alpha-beta outputs
(``FilteredSignals``). Wheel torques and the steering angle come from the CAN bus at 100 Hz and
are held between frames; held, they are on average half a period and, at the estimate instants
(multiples of 10 ms, frames 0.5 ms after them), a whole period old: the front slip angle lagged
the simulator's by 12.9 ms on the paper's scenario, which the cornering problem (eq 22, whose
front and rear columns are nearly collinear) turned into C_alpha,r -12 % (linear-tire truth,
zero-noise sensors). With ``extrapolate_inputs`` (default) both are extrapolated to the
estimate time from their last two samples (``observe``)::

    u(t) = u_k + (u_k - u_k-1) (t - t_k) / (t_k - t_k-1),   0 <= t - t_k <= max_extrapolation_s

(otherwise the latest sample, as before; the linear term raises white sensor noise by at most
sqrt(1 + 2 ((t - t_k) / T)^2 + ...) ~ 2.2 at t - t_k = T).

For eq 23's ``"measured"`` moment form the inputs also carry the specific force at the CG in
body axes (``specific_force_b_mps2`` = f_cg above) and the road-relative roll and pitch
(``vehicle_angles_rad``, eq 4 of the estimate); for the excitation gates the EKF's 1-sigma of
the lateral velocity yd_a (``lateral_velocity_sigma_mps``, from the ENU velocity sigmas); for
the strut-force rows (``problems.suspension_gate``) how old the suspension deflections may be,
``susp_interval_s``: the longer of the interval between the last two suspension samples and the
newest one's age at the estimate's time (inf before two samples).

Symbols and units: v_g [m/s] ENU; f [m/s^2]; w [rad/s]; wd [rad/s^2]; l [m] (body axes);
angles [rad]; lambda [-]; alpha [rad]; G [m/s^2].
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from vdps_hil.bus.samples import Sample, axis_fields, wheel_fields
from vdps_hil.identification.inputs import IdentInputs
from vdps_hil.model.core import SLIP_SPEED_FLOOR_MPS, Env, Inputs, Model
from vdps_hil.model.frames import c_omega_inv, dcm_global_to_vehicle, rot_x, rot_y, rot_z
from vdps_hil.model.params import Vehicle
from vdps_hil.units import GRAVITY_MPS2

__all__ = ["FeederConfig", "IdentFeeder", "VERTICAL"]

VERTICAL = ("struts", "aux")

_SF = axis_fields("specific_force_mps2")
_TQ = wheel_fields("wheel_torque_nm")
_SUSP = wheel_fields("susp_deflection_m")
_NAN = math.nan
_MAX_IMU_AGE_NS = 100_000_000  # an older IMU sample does not stand for the estimate's instant


@dataclass(frozen=True)
class FeederConfig:
    """``slip_speed_floor_mps``: the core's v_floor for the slip denominators [m/s];
    ``gravity_mps2``: g for an ESC cluster's missing f_z; ``accel_window_s``: IMU samples of this
    span before the estimate are averaged (the latest one if none falls in it) [s];
    ``vertical``: "struts" or "aux" (module docstring); ``extrapolate_inputs``: steering and
    wheel torques extrapolated to the estimate time, at most ``max_extrapolation_s`` past their
    last sample (module docstring)."""

    slip_speed_floor_mps: float = SLIP_SPEED_FLOOR_MPS
    gravity_mps2: float = GRAVITY_MPS2
    accel_window_s: float = 0.002
    vertical: str = "struts"
    extrapolate_inputs: bool = True
    max_extrapolation_s: float = 0.05

    def __post_init__(self):
        if not (math.isfinite(self.slip_speed_floor_mps) and self.slip_speed_floor_mps > 0):
            raise ValueError("FeederConfig.slip_speed_floor_mps must be positive")
        if not (math.isfinite(self.accel_window_s) and self.accel_window_s >= 0):
            raise ValueError("FeederConfig.accel_window_s must be >= 0")
        if self.vertical not in VERTICAL:
            raise ValueError(f"FeederConfig.vertical must be one of {VERTICAL}, got {self.vertical!r}")


class IdentFeeder:
    """Estimates -> :class:`~vdps_hil.identification.inputs.IdentInputs` (module docstring).

    ``model_vehicle`` must be a *model* file (mounting, geometry, tire radius). ``inputs``
    returns None before the estimator is initialised; quantities it cannot form (no wheel
    speeds yet, no IMU sample since the last call) are NaN, which the identifier's RLS guard
    leaves out and counts. ``counters``: calls, inputs built, incomplete (some NaN), no_imu."""

    def __init__(self, model_vehicle: Vehicle, config: FeederConfig | None = None):
        if getattr(model_vehicle, "kind", None) != "model":
            raise ValueError("IdentFeeder reads only a model vehicle file (kind = \"model\"), never truth")
        self.vehicle = model_vehicle
        self.config = config or FeederConfig()
        self._model = Model(model_vehicle, (), unsprung_dof=False,
                            slip_speed_floor_mps=self.config.slip_speed_floor_mps)
        m = model_vehicle.mounting
        rpy = np.asarray(m.imu_rotation_rpy_rad, dtype=float)
        self._imu_rot = None if not rpy.any() else dcm_global_to_vehicle(*rpy).T  # sensor -> body
        arm = np.asarray(m.imu_lever_arm_m, dtype=float)
        self._arm = None if not arm.any() else arm
        self._h_cg = model_vehicle.geometry.h_cg_m
        self._recent: deque[tuple[int, float, float, float]] = deque(maxlen=256)
        self._win_ns = int(round(self.config.accel_window_s * 1e9))
        self._steer: deque[tuple[int, tuple[float, ...]]] = deque(maxlen=2)
        self._torque: deque[tuple[int, tuple[float, ...]]] = deque(maxlen=2)
        self._susp_t: deque[int] = deque(maxlen=2)  # times of the last two suspension samples
        self._max_ex_ns = int(round(self.config.max_extrapolation_s * 1e9))
        self.counters = {"calls": 0, "inputs": 0, "incomplete": 0, "no_imu": 0, "imu_samples": 0}

    # ------------------------------------------------------------------ IMU
    def observe(self, sample: Sample) -> None:
        """Keep the specific force of recent ``imu`` samples, the last two steering and
        wheel-torque samples and the times of the last two suspension samples (others are
        ignored)."""
        kind = sample.kind
        if kind == "imu":
            if not sample.valid:
                return
        elif kind == "suspension":
            hist = self._susp_t
            if sample.valid and (not hist or sample.t_ns > hist[-1]):
                g = sample.fields.get
                if (math.isfinite(g(_SUSP[0], _NAN)) or math.isfinite(g(_SUSP[1], _NAN))
                        or math.isfinite(g(_SUSP[2], _NAN)) or math.isfinite(g(_SUSP[3], _NAN))):
                    hist.append(sample.t_ns)
            return
        else:
            if (kind == "steer" or kind == "wheel_torque") and sample.valid:
                names = ("steer_wheel_angle_rad",) if kind == "steer" else _TQ
                vals = tuple(sample.fields.get(n, _NAN) for n in names)
                hist = self._steer if kind == "steer" else self._torque
                if all(math.isfinite(v) for v in vals) and (not hist or sample.t_ns > hist[-1][0]):
                    hist.append((sample.t_ns, vals))
            return
        g = sample.fields.get
        fx, fy, fz = g(_SF[0], _NAN), g(_SF[1], _NAN), g(_SF[2], _NAN)
        if not math.isfinite(fz):
            fz = self.config.gravity_mps2  # ESC cluster: no f_z
        if not math.isfinite(fx + fy):
            return
        self._recent.append((sample.t_ns, fx, fy, fz))
        self.counters["imu_samples"] += 1

    def _mean_specific_force(self, t_ns: int, omega, omega_dot) -> np.ndarray:
        """Mean of the samples in (t - window, t], or the newest one at or before t if none is
        in the window and it is at most ``_MAX_IMU_AGE_NS`` old."""
        sx = sy = sz = 0.0
        n = 0
        lo = t_ns - self._win_ns
        for t, fx, fy, fz in reversed(self._recent):
            if t > t_ns:
                continue
            if t <= lo and (n or t_ns - t > _MAX_IMU_AGE_NS):
                break
            sx, sy, sz, n = sx + fx, sy + fy, sz + fz, n + 1
            if t <= lo:
                break
        if n == 0:
            self.counters["no_imu"] += 1
            return np.full(3, _NAN)
        f = np.array([sx / n, sy / n, sz / n])
        if self._imu_rot is not None:
            f = self._imu_rot @ f
        if self._arm is not None and np.isfinite(omega).all() and np.isfinite(omega_dot).all():
            f = f - np.cross(omega_dot, self._arm) - np.cross(omega, np.cross(omega, self._arm))
        return f

    def _extrapolated(self, hist, t_ns: int, held: tuple[float, ...]) -> tuple[float, ...]:
        """The signal at ``t_ns`` from its last two samples (module docstring), else ``held``."""
        if not self.config.extrapolate_inputs or len(hist) < 2:
            return held
        (t0, v0), (t1, v1) = hist
        dt = t_ns - t1
        if dt < 0 or dt > self._max_ex_ns or t1 <= t0:
            return held
        f = dt / (t1 - t0)
        return tuple(b + (b - a) * f for a, b in zip(v0, v1))

    # ------------------------------------------------------------------ inputs
    def inputs(self, estimate, filtered) -> IdentInputs | None:
        """The identifier's inputs at ``estimate.t_ns`` (module docstring); None without an
        estimate."""
        self.counters["calls"] += 1
        if estimate is None:
            return None
        x = estimate.x
        phi_g, theta_g, psi_g, phi_r, theta_r, psi_v = (float(v) for v in x[6:12])
        phi_v, theta_v, _ = (float(v) for v in estimate.vehicle_angles_rad)
        c_gv, c_ga, grav = _frames(phi_g, theta_g, psi_g, phi_r, theta_r, psi_v)
        v_g = np.array(x[3:6], dtype=float)
        v_a = (c_ga @ v_g).tolist()
        omega = tuple(float(v) for v in filtered.angular_rate_radps)
        omega_dot = tuple(float(v) for v in filtered.angular_accel_radps2)
        # an ESC cluster has no roll/pitch rate (NaN): the kinematics below take them as 0, as the
        # estimator does; the inputs keep them NaN (not measured)
        rates_finite = math.isfinite(omega[0]) and math.isfinite(omega[1]) and math.isfinite(omega[2])
        w0, wd0 = np.array(omega), np.array(omega_dot)
        if math.isfinite(omega[2]) and not rates_finite:
            w0 = np.array([v if math.isfinite(v) else 0.0 for v in omega])
            wd0 = np.array([v if math.isfinite(v) else 0.0 for v in omega_dot])
        f_cg = self._mean_specific_force(int(estimate.t_ns), w0, wd0)
        a_a = (c_ga @ (c_gv.T @ f_cg)).tolist()
        a_a = (a_a[0] + grav[0], a_a[1] + grav[1], a_a[2] + grav[2])
        psi_v_dot = float((c_omega_inv(phi_v, theta_v) @ w0)[2])
        xdd = a_a[0] + v_a[1] * psi_v_dot
        ydd = a_a[1] - v_a[0] * psi_v_dot
        f_cg = f_cg.tolist()
        zdd = a_a[2] if self.config.vertical == "aux" else f_cg[2] + grav[2]
        t_est = int(estimate.t_ns)
        steer = self._extrapolated(self._steer, t_est, (float(filtered.steer_wheel_angle_rad),))[0]
        torque = self._extrapolated(self._torque, t_est, tuple(filtered.wheel_torque_nm))
        slip, alpha, delta = self._tire_kinematics(estimate, filtered, c_gv @ v_g, w0, steer)
        inp = IdentInputs(
            t_ns=t_est, xdd_a_mps2=xdd, ydd_a_mps2=ydd, zdd_a_mps2=zdd,
            xd_a_mps=v_a[0], yd_a_mps=v_a[1], psi_v_dot_radps=psi_v_dot,
            gravity_aux_mps2=grav, omega_radps=omega, omega_dot_radps2=omega_dot,
            susp_deflection_m=filtered.susp_deflection_m, susp_rate_mps=filtered.susp_rate_mps,
            wheel_speed_radps=filtered.wheel_speed_radps, wheel_accel_radps2=filtered.wheel_accel_radps2,
            wheel_torque_nm=torque, slip_ratio=slip, slip_angle_rad=alpha,
            wheel_angle_rad=delta, specific_force_b_mps2=tuple(f_cg),
            vehicle_angles_rad=(phi_v, theta_v), lateral_velocity_sigma_mps=_lateral_sigma(estimate, c_ga),
            susp_interval_s=self._susp_interval_s(t_est))
        self.counters["inputs"] += 1
        if not _all_finite(inp):
            self.counters["incomplete"] += 1
        return inp

    def _susp_interval_s(self, t_ns: int) -> float:
        """The longer of the last suspension sampling interval and the newest sample's age at
        ``t_ns`` [s]; inf before two samples (the strut forces' rates need two)."""
        hist = self._susp_t
        if len(hist) < 2:
            return math.inf
        return max(hist[1] - hist[0], t_ns - hist[1], 0) * 1e-9

    def _tire_kinematics(self, estimate, filtered, v_b: np.ndarray, omega: np.ndarray, steer: float | None = None):
        """Slip ratios, slip angles and road-wheel angles from the core (module docstring)."""
        x = estimate.x
        env = Env(float(x[9]), float(x[10]))
        n = env.normal_g
        h = self._h_cg
        w = [float(v) for v in omega]
        finite = math.isfinite(w[0]) and math.isfinite(w[1]) and math.isfinite(w[2])
        if not finite:
            w = [v if math.isfinite(v) else 0.0 for v in w]
        state = [h * n[0], h * n[1], h * n[2], float(x[6]), float(x[7]), float(x[8]),
                 float(v_b[0]), float(v_b[1]), float(v_b[2]), *w, *(float(v) for v in filtered.wheel_speed_radps)]
        if steer is None:
            steer = float(filtered.steer_wheel_angle_rad)
        slip, alpha, delta = self._model.corner_kinematics(state, Inputs(steer_wheel_angle_rad=steer), env)
        if not finite:  # the slips need the rates (v_w = v_b + w x r_w)
            slip = alpha = (_NAN,) * 4
        return slip, alpha, delta


_G_DOWN = np.array([0.0, 0.0, -GRAVITY_MPS2])
_RZ_0 = rot_z(0.0)  # R(z, psi_r = 0) of eq 2


def _frames(phi_g: float, theta_g: float, psi_g: float, phi_r: float, theta_r: float,
            psi_v: float) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float]]:
    """(C_g^v, C_g^a, G) of the module docstring: the products of ``frames.dcm_global_to_vehicle``
    (R_x R_y R_z), ``dcm_road_to_aux`` @ ``dcm_global_to_road`` (R_z(psi_v) (R_z(0) R_x R_y)) and
    ``inputs.gravity_aux_mps2`` ((R_z(psi_v) R_x R_y) [0, 0, -g]) in the same order, the three
    chains side by side in stacked numpy calls (BLAS per matrix: the same results as one call
    per product)."""
    rx_r, ry_r, rz_v = rot_x(phi_r), rot_y(theta_r), rot_z(psi_v)
    r = np.stack((rot_x(phi_g), _RZ_0, rz_v, rot_y(theta_g), rx_r, rx_r, rot_z(psi_g), ry_r, ry_r, rz_v))
    m = r[:3] @ r[3:6] @ r[6:9]  # C_g^v, C_g^r, R_z(psi_v) R_x(phi_r) R_y(theta_r)
    g = (m[2] @ _G_DOWN).tolist()
    return m[0], r[9] @ m[1], (g[0], g[1], g[2])


def _lateral_sigma(estimate, c_ga: np.ndarray) -> float:
    """1-sigma of yd_a from the EKF's ENU velocity sigmas (their correlation neglected):
    sqrt(sum_j C_ga[1, j]^2 sigma_v,j^2)."""
    c = c_ga[1].tolist()
    s = estimate.sigma
    a, b, d = c[0] * float(s[3]), c[1] * float(s[4]), c[2] * float(s[5])
    return math.sqrt(a * a + b * b + d * d)


def _all_finite(inp: IdentInputs) -> bool:
    vals = (inp.xdd_a_mps2, inp.ydd_a_mps2, inp.zdd_a_mps2, inp.xd_a_mps, inp.yd_a_mps, inp.psi_v_dot_radps,
            *inp.gravity_aux_mps2, *inp.omega_radps, *inp.omega_dot_radps2, *inp.susp_deflection_m,
            *inp.susp_rate_mps, *inp.wheel_speed_radps, *inp.wheel_accel_radps2, *inp.wheel_torque_nm,
            *inp.slip_ratio, *inp.slip_angle_rad, *inp.wheel_angle_rad)
    return all(map(math.isfinite, vals))
