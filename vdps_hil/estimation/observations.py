"""Observation models h(x) of eq 9-11, one per measurement kind, with analytic Jacobians.

Every model is written for the full 12-state vector (``states.States``); the EKF maps its
Jacobian to the filter layout (H_filter = H_full E).

============  ===  =====================================================================  =====
kind          dim  h(x)                                                                   paper
============  ===  =====================================================================  =====
gnss_pos      3    p + (C_g^v)^T l_ant  (antenna position in {g}; l_ant the lever arm      y1^gps
                   from the CG in body axes, model file ``mounting.gnss_lever_arm_m``)
gnss_att      3    [phi_g, theta_g, psi_g] (residuals wrapped)                            y1^gps
gnss_vel      2    [|v_a,h|, atan2(v_a,y, v_a,x)] with v_a = v + (C_g^v)^T (w x l_ant)     (none)
                   (single-antenna speed and course over ground)
y2_gps        2    [C_r^v C_g^r](1, 1:2) = [c(th_v)c(psi_v), c(th_v)s(psi_v), s(th_v)]    y2^gps
                   C_g^r[:, 0:2] with psi_v the state; theta_v by eq 4 of the state (in the
                   Jacobian), or a given value (aux: e.g. eq 5's theta_v, then a constant).
                   A stale eq-5 theta_v (1 Hz) leaves a radial residual on the unit circle
                   that gets gated, hence the eq-4 default
y1_sus        2    [C_r^v(1,3), C_r^v(2,3)] = [sin th_v, sin ph_v cos th_v],               y1^sus
                   C_r^v = C_g^v (C_g^r)^T (eq 4, psi_r = 0)
y2_sus_plane  1    C_g^r(3,:) p = n . p (CG height above one road plane through the        y2^sus
                   origin; correction (c): only valid when that holds)
y2_sus_rate   1    n . v (rate of the CG height above the *local* road plane; the          (c)
                   locally referenced form of y2^sus, compared with the eq-5 z_r rate)
wheel_speed   1    (1 + k_w) sum_i a_i [cos d_i, sin d_i, 0] (C_g^v v + w x r_i)           (none)
                   (weighted mean forward speed of the wheels, module text below)
nhc           2    [(C_g^v v + w x r_p)_y, (C_g^v v + w x r_p)_z] (non-holonomic             (none)
                   constraint: no lateral or vertical velocity at the point r_p)
============  ===  =====================================================================  =====

Wheel speed (``WheelSpeed``; real cars, not in the paper): wheel i (order FL FR RR RL, centre at
r_i = (+-l, +-t, r_0 - h_cg) from the CG in body axes, model file geometry) rolls along its
heading d_i (front: steering wheel angle / steer ratio, rear 0) with the speed
s_i = cos d_i u_i + sin d_i v_i, (u_i, v_i) = the x, y of C_g^v v + w x r_i. The measurement is
z = sum_i a_i omega_i r_0 (weights a_i >= 0 summing to 1 over the wheels used, rolling radius
r_0 from the model file) and h = (1 + k_w) sum_i a_i s_i with k_w the wheel-speed scale state
(r_0 / r_true - 1; 0 when not carried). aux = (w_b, (d_1..d_4), (a_1..a_4)); w_b is the bias-
corrected body rate (None: zero rate, straight wheels, equal weights). Slip and braking are
handled by the pipeline (gate and inflate R).

Non-holonomic constraint (``NonHolonomic``): a wheeled vehicle on the ground does not move
sideways or vertically at the rear axle: z = [0, 0] with R = diag(sigma_lat^2, sigma_vert^2)
(the pipeline inflates sigma_lat with the lateral acceleration: tyre slip angles). r_p is the
rear axle centre on the ground, (-l_r, 0, -h_cg). aux: w_b (None: zero).

The paper's y1^sus also lists C_r^v(3,3) = cos ph_v cos th_v: it is a function of the other two
(unit column) and its linearisation is parallel to theirs, which makes S singular; it is left
out (it only matters near |theta_v| = 90 deg). With eq 5 the two kept components are *linear* in
the four deflections H_i (``measurements.suspension_measurement``), so their covariance is exact.

The measurements (z, R) these models are compared with are built from sensor quantities in
``measurements``.
"""

from __future__ import annotations

import enum
import math

import numpy as np

from vdps_hil.estimation.kinematics import (dcm_gr_partials, dcm_gv_partials, road_normal,
                                            vehicle_angles_eq4)
from vdps_hil.estimation.states import N_EXT, N_FULL, AugStates, wrap_angle


class ObsKind(str, enum.Enum):
    """Measurement kinds the EKF can update with (values are stable names for counters/JSON)."""

    GNSS_POS = "gnss_pos"
    GNSS_ATT = "gnss_att"
    GNSS_VEL = "gnss_vel"
    Y2_GPS = "y2_gps"
    Y1_SUS = "y1_sus"
    Y2_SUS_PLANE = "y2_sus_plane"
    Y2_SUS_RATE = "y2_sus_rate"
    WHEEL_SPEED = "wheel_speed"
    NHC = "nhc"


class ObservationModel:
    """Base: ``h(x, aux)``, ``jacobian(x, aux)`` (dim x 12), ``residual(z, y)``.

    ``dof``: chi-square degrees of freedom of the NIS (= dim here). ``wrapped``: rows whose
    residuals are angles wrapped to [-pi, pi)."""

    kind: ObsKind
    dim: int
    wrapped: tuple[int, ...] = ()

    @property
    def dof(self) -> int:
        return self.dim

    def h(self, x: np.ndarray, aux=None) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def jacobian(self, x: np.ndarray, aux=None) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def residual(self, z: np.ndarray, y: np.ndarray) -> np.ndarray:
        r = z - y
        for i in self.wrapped:
            r[i] = wrap_angle(r[i])
        return r


class GnssPosition(ObservationModel):
    """Antenna position p + (C_g^v)^T l_ant in {g} [m]."""

    kind = ObsKind.GNSS_POS
    dim = 3

    def __init__(self, lever_arm_m=(0.0, 0.0, 0.0)):
        self.lever_arm_m = np.asarray(lever_arm_m, dtype=float).reshape(3)

    def h(self, x, aux=None):
        c = dcm_gv_partials(x[6], x[7], x[8])[0]
        return x[0:3] + c.T @ self.lever_arm_m

    def jacobian(self, x, aux=None):
        _, d_f, d_t, d_p = dcm_gv_partials(x[6], x[7], x[8])
        H = np.zeros((3, N_FULL))
        H[0, 0] = H[1, 1] = H[2, 2] = 1.0
        la = self.lever_arm_m
        H[:, 6] = d_f.T @ la
        H[:, 7] = d_t.T @ la
        H[:, 8] = d_p.T @ la
        return H


class GnssAttitude(ObservationModel):
    """Multi-antenna absolute attitude [phi_g, theta_g, psi_g] [rad]."""

    kind = ObsKind.GNSS_ATT
    dim = 3
    wrapped = (0, 1, 2)

    def h(self, x, aux=None):
        return x[6:9].copy()

    def jacobian(self, x, aux=None):
        H = np.zeros((3, N_FULL))
        H[0, 6] = H[1, 7] = H[2, 8] = 1.0
        return H


class GnssVelocity(ObservationModel):
    """Single-antenna speed [m/s] and course [rad, CCW from East] over ground of the antenna.

    aux: body angular rate w_b [rad/s] (3,) for the lever-arm velocity (None: zero)."""

    kind = ObsKind.GNSS_VEL
    dim = 2
    wrapped = (1,)

    def __init__(self, lever_arm_m=(0.0, 0.0, 0.0)):
        self.lever_arm_m = np.asarray(lever_arm_m, dtype=float).reshape(3)
        self._arm = tuple(self.lever_arm_m.tolist())

    def _va(self, x, aux):
        parts = dcm_gv_partials(x[6], x[7], x[8])
        if aux is None:
            u = np.zeros(3)
        else:  # w x l, the products and differences of np.cross on plain floats (cheaper for one 3-vector)
            (w0, w1, w2), (l0, l1, l2) = (float(v) for v in aux), self._arm
            u = np.array([w1 * l2 - w2 * l1, w2 * l0 - w0 * l2, w0 * l1 - w1 * l0])
        return x[3:6] + parts[0].T @ u, u, parts

    def h(self, x, aux=None):
        va = self._va(x, aux)[0]
        return np.array([math.hypot(va[0], va[1]), math.atan2(va[1], va[0])])

    def jacobian(self, x, aux=None):
        va, u, (_, d_f, d_t, d_p) = self._va(x, aux)
        s2 = max(1e-12, va[0] ** 2 + va[1] ** 2)
        s = math.sqrt(s2)
        dva = np.zeros((3, N_FULL))  # d v_a / d x
        dva[0, 3] = dva[1, 4] = dva[2, 5] = 1.0
        dva[:, 6] = d_f.T @ u
        dva[:, 7] = d_t.T @ u
        dva[:, 8] = d_p.T @ u
        H = np.empty((2, N_FULL))
        H[0] = (va[0] * dva[0] + va[1] * dva[1]) / s
        H[1] = (va[0] * dva[1] - va[1] * dva[0]) / s2
        return H


class Y2Gps(ObservationModel):
    """y2^gps of eq 9: [C_r^v C_g^r](1, 1:2) as a function of (phi_r, theta_r, psi_v), theta_v
    a known parameter (aux, rad). Compared with [cos th_g cos psi_g, cos th_g sin psi_g] from the
    GNSS attitude (``y2_gps_measurement``)."""

    kind = ObsKind.Y2_GPS
    dim = 2

    @staticmethod
    def _theta_v(x, aux):
        if aux is None or not math.isfinite(float(aux)):
            return float(vehicle_angles_eq4(x[6:11], with_jacobian=False)[1])
        return float(aux)

    def h(self, x, aux=None):
        tv = self._theta_v(x, aux)
        cgr = dcm_gr_partials(x[9], x[10])[0]
        row = np.array([math.cos(tv) * math.cos(x[11]), math.cos(tv) * math.sin(x[11]), math.sin(tv)])
        return row @ cgr[:, 0:2]

    def jacobian(self, x, aux=None):
        tv = self._theta_v(x, aux)
        cgr, d_f, d_t = dcm_gr_partials(x[9], x[10])
        ct, st = math.cos(tv), math.sin(tv)
        cp, sp = math.cos(x[11]), math.sin(x[11])
        row = np.array([ct * cp, ct * sp, st])
        H = np.zeros((2, N_FULL))
        H[:, 9] = row @ d_f[:, 0:2]
        H[:, 10] = row @ d_t[:, 0:2]
        H[:, 11] = np.array([-ct * sp, ct * cp, 0.0]) @ cgr[:, 0:2]
        if aux is None or not math.isfinite(float(aux)):
            # theta_v from eq 4 of the state: chain rule through d theta_v / d (five angles)
            dh_dtv = np.array([-st * cp, -st * sp, ct]) @ cgr[:, 0:2]
            H[:, 6:11] += np.outer(dh_dtv, vehicle_angles_eq4(x[6:11])[1][1])
        return H


class Y1Sus(ObservationModel):
    """y1^sus of eq 9: [C_r^v(1,3), C_r^v(2,3)] = [sin th_v, sin ph_v cos th_v] with
    C_r^v = C_g^v (C_g^r)^T; depends on the five angles, not on psi_v."""

    kind = ObsKind.Y1_SUS
    dim = 2

    @staticmethod
    def _parts(x):
        cgv, g_f, g_t, g_p = dcm_gv_partials(x[6], x[7], x[8])
        cgr, r_f, r_t = dcm_gr_partials(x[9], x[10])
        # column 3 of C_r^v = C_g^v (C_g^r)^T is C_g^v n with n = row 3 of C_g^r
        n = cgr[2]
        return cgv, (g_f, g_t, g_p), n, (r_f[2], r_t[2])

    def h(self, x, aux=None):
        cgv, _, n, _ = self._parts(x)
        return cgv[0:2] @ n

    def jacobian(self, x, aux=None):
        cgv, dg, n, dn = self._parts(x)
        H = np.zeros((2, N_FULL))
        for k, d in enumerate(dg):
            H[:, 6 + k] = d[0:2] @ n
        for k, d in enumerate(dn):
            H[:, 9 + k] = cgv[0:2] @ d
        return H


class Y2SusPlane(ObservationModel):
    """y2^sus of eq 9: n . p = C_g^r(3,1) x_g + C_g^r(3,2) y_g + C_g^r(3,3) z_g [m]."""

    kind = ObsKind.Y2_SUS_PLANE
    dim = 1

    def h(self, x, aux=None):
        n = road_normal(x[9], x[10])[0]
        return np.array([n @ x[0:3]])

    def jacobian(self, x, aux=None):
        n, dn_f, dn_t = road_normal(x[9], x[10])
        H = np.zeros((1, N_FULL))
        H[0, 0:3] = n
        H[0, 9] = dn_f @ x[0:3]
        H[0, 10] = dn_t @ x[0:3]
        return H


class Y2SusRate(ObservationModel):
    """Locally referenced y2^sus (correction (c)): n . v [m/s], the CG velocity normal to the
    local road plane, compared with the rate of eq 5's z_r over a short baseline."""

    kind = ObsKind.Y2_SUS_RATE
    dim = 1

    def h(self, x, aux=None):
        n = road_normal(x[9], x[10])[0]
        return np.array([n @ x[3:6]])

    def jacobian(self, x, aux=None):
        n, dn_f, dn_t = road_normal(x[9], x[10])
        H = np.zeros((1, N_FULL))
        H[0, 3:6] = n
        H[0, 9] = dn_f @ x[3:6]
        H[0, 10] = dn_t @ x[3:6]
        return H


def _cross(w, r):
    return (w[1] * r[2] - w[2] * r[1], w[2] * r[0] - w[0] * r[2], w[0] * r[1] - w[1] * r[0])


class WheelSpeed(ObservationModel):
    """Weighted mean forward speed of the wheels [m/s] (module docstring). Works on the full
    12-vector (k_w = 0) or the extended N_EXT vector (k_w = x[18]); the Jacobian has as many
    columns as x."""

    kind = ObsKind.WHEEL_SPEED
    dim = 1

    def __init__(self, wheel_positions_m=None):
        if wheel_positions_m is None:
            wheel_positions_m = np.zeros((4, 3))
        self.wheel_positions_m = np.asarray(wheel_positions_m, dtype=float).reshape(4, 3)
        self._r = [tuple(float(v) for v in row) for row in self.wheel_positions_m]

    def _terms(self, x, aux):
        """(A, B, c): sum a_i cos d_i, sum a_i sin d_i and sum a_i [cos d_i, sin d_i] . (w x r_i)."""
        if aux is None:
            w, d, a = (0.0, 0.0, 0.0), (0.0,) * 4, (0.25,) * 4
        else:
            w, d, a = aux
        A = B = c = 0.0
        for ri, di, ai in zip(self._r, d, a):
            if ai == 0.0:
                continue
            cd, sd = math.cos(di), math.sin(di)
            wr = _cross(w, ri)
            A += ai * cd
            B += ai * sd
            c += ai * (cd * wr[0] + sd * wr[1])
        return A, B, c

    @staticmethod
    def _scale(x):
        return float(x[AugStates.WHEEL_SCALE]) if x.shape[0] > AugStates.WHEEL_SCALE else 0.0

    def h(self, x, aux=None):
        cgv = dcm_gv_partials(x[6], x[7], x[8])[0]
        A, B, c = self._terms(x, aux)
        v = x[3:6]
        s = A * float(cgv[0] @ v) + B * float(cgv[1] @ v) + c
        return np.array([(1.0 + self._scale(x)) * s])

    def jacobian(self, x, aux=None):
        cgv, d_f, d_t, d_p = dcm_gv_partials(x[6], x[7], x[8])
        A, B, c = self._terms(x, aux)
        v = x[3:6]
        k1 = 1.0 + self._scale(x)
        H = np.zeros((1, x.shape[0] if x.shape[0] >= N_EXT else N_FULL))
        H[0, 3:6] = k1 * (A * cgv[0] + B * cgv[1])
        for col, d in ((6, d_f), (7, d_t), (8, d_p)):
            H[0, col] = k1 * (A * float(d[0] @ v) + B * float(d[1] @ v))
        if H.shape[1] > AugStates.WHEEL_SCALE:
            H[0, AugStates.WHEEL_SCALE] = A * float(cgv[0] @ v) + B * float(cgv[1] @ v) + c
        return H


class NonHolonomic(ObservationModel):
    """Lateral and vertical body velocity [m/s] at the point r_p (module docstring)."""

    kind = ObsKind.NHC
    dim = 2

    def __init__(self, point_m=(0.0, 0.0, 0.0)):
        self.point_m = np.asarray(point_m, dtype=float).reshape(3)
        self._r = tuple(float(v) for v in self.point_m)

    def h(self, x, aux=None):
        cgv = dcm_gv_partials(x[6], x[7], x[8])[0]
        wr = (0.0, 0.0, 0.0) if aux is None else _cross(aux, self._r)
        v = x[3:6]
        return np.array([float(cgv[1] @ v) + wr[1], float(cgv[2] @ v) + wr[2]])

    def jacobian(self, x, aux=None):
        cgv, d_f, d_t, d_p = dcm_gv_partials(x[6], x[7], x[8])
        v = x[3:6]
        H = np.zeros((2, N_FULL))
        H[:, 3:6] = cgv[1:3]
        H[:, 6] = d_f[1:3] @ v
        H[:, 7] = d_t[1:3] @ v
        H[:, 8] = d_p[1:3] @ v
        return H


def wheel_positions(geometry, rolling_radius_m: float) -> np.ndarray:
    """Wheel centres r_i (4 x 3, order FL FR RR RL) from the CG in body axes (x fwd, y left,
    z up): (l_f, t_f), (l_f, -t_f), (-l_r, -t_r), (-l_r, t_r), height r_0 - h_cg."""
    z = rolling_radius_m - geometry.h_cg_m
    lf, lr = geometry.l_f_m, geometry.l_r_m
    tf, tr = geometry.track_half_front_m, geometry.track_half_rear_m
    return np.array([[lf, tf, z], [lf, -tf, z], [-lr, -tr, z], [-lr, tr, z]])


def rear_axle_ground_point(geometry) -> np.ndarray:
    """r_p of the non-holonomic constraint: the rear axle centre on the ground (-l_r, 0, -h_cg)."""
    return np.array([-geometry.l_r_m, 0.0, -geometry.h_cg_m])


def make_models(gnss_lever_arm_m=(0.0, 0.0, 0.0), wheel_positions_m=None,
                nhc_point_m=(0.0, 0.0, 0.0)) -> dict[ObsKind, ObservationModel]:
    """One model instance per kind (the registry the EKF uses)."""
    return {
        ObsKind.GNSS_POS: GnssPosition(gnss_lever_arm_m),
        ObsKind.GNSS_ATT: GnssAttitude(),
        ObsKind.GNSS_VEL: GnssVelocity(gnss_lever_arm_m),
        ObsKind.Y2_GPS: Y2Gps(),
        ObsKind.Y1_SUS: Y1Sus(),
        ObsKind.Y2_SUS_PLANE: Y2SusPlane(),
        ObsKind.Y2_SUS_RATE: Y2SusRate(),
        ObsKind.WHEEL_SPEED: WheelSpeed(wheel_positions_m),
        ObsKind.NHC: NonHolonomic(nhc_point_m),
    }
