"""Synthetic kinematic trajectories and Table-1 sensor streams for tests and benchmarks of the
estimator (no vehicle dynamics: an analytic motion on one road plane).

Test and benchmark support only: the pipeline never imports this module (it holds the drive's
truth, ``Truth``, beside its sensor streams: ``vdps_hil.experiments``' truth rule); nothing here
reads the simulator or a truth vehicle file (sensor geometry comes from a *model* vehicle file).

Trajectory (road frame {r}: the road plane through the ENU origin, bank phi_r, grade theta_r)::

    X(t) = R sin(W t) + A_s sin(w_s t)               W = V / R (a circle of radius R at speed V)
    Y(t) = R (1 - cos(W t)) + B sin(w_l t)           plus surge and a lateral slalom
    p_r  = [X, Y, h(t) + d_0] rotated by psi_0 about z_r, h = A_h sin(w_h t) (heave)
    psi_v = psi_0 + atan2(Y', X') + beta(t)          (beta: a sideslip sinusoid)
    phi_v = A_r sin(w_r t + 0.3),  theta_v = A_p sin(w_p t + 1.0)
    p_g  = (C_g^r)^T p_r, v_g, a_g likewise          C_g^r of eq 2 (psi_r = 0)
    C_g^v = C_r^v(phi_v, theta_v, psi_v) C_g^r      eq 4 -> (phi_g, theta_g, psi_g)
    w_b  = C_omega(phi_v, theta_v) [phi_v', theta_v', psi_v']   (road fixed in {g})
    f_b  = C_g^v (a_g + [0, 0, g])                    (specific force)
    H_i  = -(h + x_i sin th_v + y_i sin ph_v cos th_v)  (corner i at (x_i, y_i); inverts eq 5)

d_0 (``plane_offset_m``) = 0 puts the CG design plane through the origin, where the paper's
y2^sus = n . p holds exactly. Noise is white Gaussian at the Table 1 levels, seeded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vdps_hil.bus.samples import Sample, axis_fields, wheel_fields
from vdps_hil.units import GRAVITY_MPS2, deg2rad

_NS = 1_000_000_000


@dataclass(frozen=True)
class Maneuver:
    """Parameters of the analytic trajectory (module docstring). Angles in rad, SI."""

    duration_s: float = 30.0
    speed_mps: float = 25.0  # V (90 km/h, section 7)
    turn_radius_m: float = 300.0  # R
    surge_amp_m: float = 0.8  # A_s
    surge_freq_hz: float = 0.2
    slalom_amp_m: float = 0.4  # B
    slalom_freq_hz: float = 0.5
    heave_amp_m: float = 0.005  # A_h
    heave_freq_hz: float = 1.3
    roll_amp_rad: float = 0.03  # A_r
    roll_freq_hz: float = 0.5
    pitch_amp_rad: float = 0.01  # A_p
    pitch_freq_hz: float = 0.3
    sideslip_amp_rad: float = 0.01
    sideslip_freq_hz: float = 0.5
    bank_rad: float = float(deg2rad(2.0))  # phi_r (section 7: 2 deg)
    grade_rad: float = float(deg2rad(-2.0))  # theta_r (section 7: -2 deg, downhill)
    heading0_rad: float = 0.0  # psi_0
    plane_offset_m: float = 0.0  # d_0
    gravity_mps2: float = GRAVITY_MPS2


@dataclass(frozen=True)
class Table1:
    """Sensor rates [Hz] and noise standard deviations of the paper's Table 1 (SI)."""

    imu_hz: float = 1000.0
    gnss_hz: float = 5.0
    susp_hz: float = 1.0
    tacho_hz: float = 1000.0
    accel_mps2: float = 0.02
    gyro_radps: float = float(deg2rad(0.08))
    gnss_att_rad: float = float(deg2rad(0.4))
    gnss_pos_h_m: float = 1.0
    gnss_pos_v_m: float = 3.0
    susp_m: float = 0.001
    tacho_radps: float = float(deg2rad(2.0))


@dataclass
class Truth:
    """Truth arrays at times ``t_s`` (N,). ``x_full`` (N, 12) in ``States`` order."""

    t_s: np.ndarray
    x_full: np.ndarray
    accel_g: np.ndarray  # kinematic acceleration in {g} [m/s^2]
    specific_force_b: np.ndarray  # f_b [m/s^2]
    omega_b: np.ndarray  # w_b [rad/s]
    omega_dot_b: np.ndarray  # dw_b/dt [rad/s^2] (finite difference of the analytic w_b)
    vehicle_angles: np.ndarray  # (phi_v, theta_v, psi_v) [rad]
    heave_m: np.ndarray  # z_r of eq 5 [m]
    heave_rate_mps: np.ndarray


def _rot_batch(axis: str, a: np.ndarray) -> np.ndarray:
    """Eq 1 rotation matrices for an array of angles, shape (N, 3, 3)."""
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    if axis == "x":
        m = [[o, z, z], [z, c, s], [z, -s, c]]
    elif axis == "y":
        m = [[c, z, s], [z, o, z], [-s, z, c]]
    else:
        m = [[c, s, z], [-s, c, z], [z, z, o]]
    return np.moveaxis(np.array(m), (0, 1), (-2, -1))


def _c_omega_batch(phi, theta) -> np.ndarray:
    cp, sp, ct, st = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    o, z = np.ones_like(phi), np.zeros_like(phi)
    return np.moveaxis(np.array([[o, z, st], [z, -cp, ct * sp], [z, sp, ct * cp]]), (0, 1), (-2, -1))


def road_dcm(m: Maneuver) -> np.ndarray:
    """C_g^r = R(x, phi_r) R(y, theta_r) (eq 2, psi_r = 0)."""
    return _rot_batch("x", np.array([m.bank_rad]))[0] @ _rot_batch("y", np.array([m.grade_rad]))[0]


def truth(m: Maneuver, t_s) -> Truth:
    """Exact kinematics of the manoeuvre at the times ``t_s`` (vectorised)."""
    t = np.asarray(t_s, dtype=float)
    V, R = m.speed_mps, m.turn_radius_m
    W = V / R
    ws, wl = 2 * math.pi * m.surge_freq_hz, 2 * math.pi * m.slalom_freq_hz
    As, B = m.surge_amp_m, m.slalom_amp_m
    X = R * np.sin(W * t) + As * np.sin(ws * t)
    Y = R * (1 - np.cos(W * t)) + B * np.sin(wl * t)
    Xd = R * W * np.cos(W * t) + As * ws * np.cos(ws * t)
    Yd = R * W * np.sin(W * t) + B * wl * np.cos(wl * t)
    Xdd = -R * W * W * np.sin(W * t) - As * ws * ws * np.sin(ws * t)
    Ydd = R * W * W * np.cos(W * t) - B * wl * wl * np.sin(wl * t)
    wh = 2 * math.pi * m.heave_freq_hz
    h = m.heave_amp_m * np.sin(wh * t)
    hd = m.heave_amp_m * wh * np.cos(wh * t)
    hdd = -m.heave_amp_m * wh * wh * np.sin(wh * t)
    c0, s0 = math.cos(m.heading0_rad), math.sin(m.heading0_rad)
    pr = np.stack([c0 * X - s0 * Y, s0 * X + c0 * Y, h + m.plane_offset_m], axis=1)
    vr = np.stack([c0 * Xd - s0 * Yd, s0 * Xd + c0 * Yd, hd], axis=1)
    ar = np.stack([c0 * Xdd - s0 * Ydd, s0 * Xdd + c0 * Ydd, hdd], axis=1)
    cgr = road_dcm(m)
    p, v, a = pr @ cgr, vr @ cgr, ar @ cgr  # (C_g^r)^T p_r for row vectors
    # road-relative attitude and its rates
    wr, wp, wb = 2 * math.pi * m.roll_freq_hz, 2 * math.pi * m.pitch_freq_hz, 2 * math.pi * m.sideslip_freq_hz
    phi_v = m.roll_amp_rad * np.sin(wr * t + 0.3)
    phi_vd = m.roll_amp_rad * wr * np.cos(wr * t + 0.3)
    th_v = m.pitch_amp_rad * np.sin(wp * t + 1.0)
    th_vd = m.pitch_amp_rad * wp * np.cos(wp * t + 1.0)
    beta = m.sideslip_amp_rad * np.sin(wb * t + 0.7)
    betad = m.sideslip_amp_rad * wb * np.cos(wb * t + 0.7)
    course = np.unwrap(np.arctan2(Yd, Xd)) if t.size > 1 else np.arctan2(Yd, Xd)
    psi_v = m.heading0_rad + course + beta
    psi_vd = (Xd * Ydd - Yd * Xdd) / (Xd ** 2 + Yd ** 2) + betad
    crv = _rot_batch("x", phi_v) @ _rot_batch("y", th_v) @ _rot_batch("z", psi_v)
    cgv = crv @ cgr
    th_g = np.arcsin(np.clip(cgv[:, 0, 2], -1, 1))
    phi_g = np.arctan2(cgv[:, 1, 2], cgv[:, 2, 2])
    psi_g = np.arctan2(cgv[:, 0, 1], cgv[:, 0, 0])
    omega = np.einsum("nij,nj->ni", _c_omega_batch(phi_v, th_v), np.stack([phi_vd, th_vd, psi_vd], axis=1))
    fb = np.einsum("nij,nj->ni", cgv, a + np.array([0.0, 0.0, m.gravity_mps2]))
    x = np.zeros((t.size, 12))
    x[:, 0:3], x[:, 3:6] = p, v
    x[:, 6], x[:, 7], x[:, 8] = phi_g, th_g, psi_g
    x[:, 9], x[:, 10] = m.bank_rad, m.grade_rad
    x[:, 11] = (psi_v + math.pi) % (2 * math.pi) - math.pi
    if t.size > 2:
        omega_dot = np.gradient(omega, t, axis=0)
    else:
        omega_dot = np.zeros_like(omega)
    return Truth(t, x, a, fb, omega, omega_dot, np.stack([phi_v, th_v, psi_v], axis=1), h, hd)


def deflections(tr: Truth, geometry) -> np.ndarray:
    """Suspension deflections H_1..4 [m] (compression positive) that eq 5 maps back exactly to
    (z_r, theta_v, phi_v) of the truth (module docstring)."""
    phi_v, th_v = tr.vehicle_angles[:, 0], tr.vehicle_angles[:, 1]
    out = np.empty((tr.t_s.size, 4))
    for i, (xi, yi) in enumerate(geometry.corner_xy_m()):
        out[:, i] = -(tr.heave_m + xi * np.sin(th_v) + yi * np.sin(phi_v) * np.cos(th_v))
    return out


@dataclass
class SensorData:
    """Noisy Table-1 streams (times in integer ns). GNSS positions are of the antenna in ENU."""

    maneuver: Maneuver
    noise: Table1
    t_imu_ns: np.ndarray
    specific_force: np.ndarray
    angular_rate: np.ndarray
    t_gnss_ns: np.ndarray
    gnss_pos_enu: np.ndarray
    gnss_att: np.ndarray  # (roll, pitch, yaw) = (phi_g, theta_g, psi_g)
    t_susp_ns: np.ndarray
    susp_deflection: np.ndarray
    t_tacho_ns: np.ndarray
    wheel_speed: np.ndarray
    gnss_speed_course: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


def _times_ns(duration_s: float, rate_hz: float, offset_s: float = 0.0) -> np.ndarray:
    n = int(math.floor((duration_s - offset_s) * rate_hz + 1e-9)) + 1
    return np.round((offset_s + np.arange(n) / rate_hz) * _NS).astype(np.int64)


def make_sensor_data(m: Maneuver, vehicle, seed: int, noise: Table1 | None = None,
                     gnss_outage_s: tuple[float, float] | None = None,
                     wheel_radius_m: float | None = None) -> SensorData:
    """Seeded noisy streams of the manoeuvre for a *model* vehicle (geometry and GNSS lever arm).

    ``gnss_outage_s``: (start, end) [s] with no GNSS epochs. IMU sample k stamped t_k = k / f_imu
    carries the mean rate/force over its interval (t_k - T, t_k] (the truth at the interval's
    midpoint, exact to O(T^2), as an integrating IMU reports it),
    GNSS epochs at k / f_gnss + 0.5 ms, suspension at k / f_susp + 0.25 ms (distinct instants)."""
    nz = noise or Table1()
    rng = np.random.default_rng(seed)
    t_imu = _times_ns(m.duration_s, nz.imu_hz, 1.0 / nz.imu_hz)
    tr = truth(m, t_imu / _NS - 0.5 / nz.imu_hz)  # mean over (t_k - T, t_k], to O(T^2)
    f = tr.specific_force_b + rng.normal(0.0, nz.accel_mps2, tr.specific_force_b.shape)
    w = tr.omega_b + rng.normal(0.0, nz.gyro_radps, tr.omega_b.shape)
    t_g = _times_ns(m.duration_s, nz.gnss_hz, 0.0005)
    if gnss_outage_s is not None:
        tg_s = t_g / _NS
        t_g = t_g[(tg_s < gnss_outage_s[0]) | (tg_s >= gnss_outage_s[1])]
    trg = truth(m, t_g / _NS)
    lever = np.asarray(vehicle.mounting.gnss_lever_arm_m, dtype=float)
    cgv = (_rot_batch("x", trg.x_full[:, 6]) @ _rot_batch("y", trg.x_full[:, 7])
           @ _rot_batch("z", trg.x_full[:, 8]))
    ant = trg.x_full[:, 0:3] + np.einsum("nji,j->ni", cgv, lever)
    pos = ant + rng.normal(0.0, 1.0, ant.shape) * np.array([nz.gnss_pos_h_m, nz.gnss_pos_h_m, nz.gnss_pos_v_m])
    att = trg.x_full[:, 6:9] + rng.normal(0.0, nz.gnss_att_rad, (t_g.size, 3))
    att[:, 2] = (att[:, 2] + math.pi) % (2 * math.pi) - math.pi
    vel = trg.x_full[:, 3:6] + np.einsum("nji,nj->ni", cgv, np.cross(trg.omega_b, lever))
    sc = np.stack([np.hypot(vel[:, 0], vel[:, 1]) + rng.normal(0.0, 0.1, t_g.size),
                   np.arctan2(vel[:, 1], vel[:, 0])], axis=1)
    t_s = _times_ns(m.duration_s, nz.susp_hz, 0.00025)
    trs = truth(m, t_s / _NS)
    h = deflections(trs, vehicle.geometry) + rng.normal(0.0, nz.susp_m, (t_s.size, 4))
    t_t = _times_ns(m.duration_s, nz.tacho_hz, 0.5 / nz.tacho_hz)
    trt = truth(m, t_t / _NS)
    r_w = wheel_radius_m if wheel_radius_m is not None else vehicle.tire.rolling_radius_m
    ws = np.repeat((np.linalg.norm(trt.x_full[:, 3:6], axis=1) / r_w)[:, None], 4, axis=1)
    ws = ws + rng.normal(0.0, nz.tacho_radps, ws.shape)
    return SensorData(m, nz, t_imu, f, w, t_g, pos, att, t_s, h, t_t, ws, sc)


_SF, _AR = axis_fields("specific_force_mps2"), axis_fields("angular_rate_radps")
_SUSP, _WS = wheel_fields("susp_deflection_m"), wheel_fields("wheel_speed_radps")
_KIND_ORDER = {"imu": 0, "wheel_speed": 1, "suspension": 2, "gnss_pos": 3, "gnss_att": 4, "gnss_vel": 5}


def to_samples(data: SensorData, origin, imu_fields: str = "6axis", gnss: str = "multi_antenna",
               suspension: bool = True, wheel_speeds: bool = True) -> list[Sample]:
    """Bus samples (catalogue fields only) in time order. ``origin``: ``geodesy.EnuOrigin`` used
    to express the antenna ENU positions as WGS-84 (GGA altitude with zero geoid separation).
    ``imu_fields="esc3"`` keeps only yaw rate, a_x and a_y; ``gnss="single_antenna"`` replaces
    the attitude by speed/course samples."""
    out: list[Sample] = []
    for k, t in enumerate(data.t_imu_ns.tolist()):
        f, w = data.specific_force[k], data.angular_rate[k]
        if imu_fields == "esc3":
            fields = {_SF[0]: float(f[0]), _SF[1]: float(f[1]), _AR[2]: float(w[2])}
        else:
            fields = {_SF[0]: float(f[0]), _SF[1]: float(f[1]), _SF[2]: float(f[2]),
                      _AR[0]: float(w[0]), _AR[1]: float(w[1]), _AR[2]: float(w[2])}
        out.append(Sample(t, "imu", "imu", fields))
    if wheel_speeds:
        for k, t in enumerate(data.t_tacho_ns.tolist()):
            out.append(Sample(t, "can.vdps", "wheel_speed", dict(zip(_WS, data.wheel_speed[k].tolist()))))
    if suspension:
        for k, t in enumerate(data.t_susp_ns.tolist()):
            out.append(Sample(t, "can.vdps", "suspension", dict(zip(_SUSP, data.susp_deflection[k].tolist()))))
    if gnss != "none":
        for k, t in enumerate(data.t_gnss_ns.tolist()):
            lat, lon, hgt = origin.to_geodetic(data.gnss_pos_enu[k])
            out.append(Sample(t, "gnss", "gnss_pos", {"gnss_lat_deg": lat, "gnss_lon_deg": lon, "gnss_alt_m": hgt,
                                                      "gnss_geoid_sep_m": 0.0, "gnss_fix_quality": 1.0}))
            if gnss == "multi_antenna":
                r, p, y = data.gnss_att[k].tolist()
                out.append(Sample(t, "gnss", "gnss_att", {"gnss_roll_rad": r, "gnss_pitch_rad": p, "gnss_yaw_rad": y}))
            else:
                s, c = data.gnss_speed_course[k].tolist()
                out.append(Sample(t, "gnss", "gnss_vel", {"gnss_speed_mps": s, "gnss_course_rad": c}))
    out.sort(key=lambda s: (s.t_ns, _KIND_ORDER.get(s.kind, 9)))
    return out


# --------------------------------------------------------------------------------------------
# a direct EKF driver (the pipeline does the same from bus samples; this skips the bus)


@dataclass
class EkfTrace:
    """What ``drive_ekf`` recorded after each predict step: filter x (K, n), P (K, n, n), the
    full state and its sigmas (K, 12), and the truth (K, 12) at the same instants."""

    t_ns: np.ndarray
    x: np.ndarray
    P: np.ndarray
    x_full: np.ndarray
    sigma_full: np.ndarray
    truth_full: np.ndarray
    full_index: np.ndarray
    yaw_filter_positions: tuple[int, ...]

    @property
    def t_s(self) -> np.ndarray:
        return self.t_ns / _NS

    def errors_full(self) -> np.ndarray:
        e = self.x_full - self.truth_full
        for i in (8, 11):
            e[:, i] = (e[:, i] + math.pi) % (2 * math.pi) - math.pi
        return e

    def nees(self) -> np.ndarray:
        """Normalised estimation error squared of the filter states per record."""
        e = self.x - self.truth_full[:, self.full_index]
        for i in self.yaw_filter_positions:
            e[:, i] = (e[:, i] + math.pi) % (2 * math.pi) - math.pi
        return np.einsum("ki,ki->k", e, np.linalg.solve(self.P, e[:, :, None])[:, :, 0])


def initial_state(m: Maneuver, layout, t_s: float, sigma_full, rng) -> tuple[np.ndarray, np.ndarray]:
    """(x0, P0) in the filter layout: truth at ``t_s`` plus a draw from P0 = diag(sigma^2)."""
    xt = truth(m, np.array([t_s])).x_full[0]
    sig = np.asarray(sigma_full, dtype=float)[layout.full_index]
    x0 = layout.from_full(xt) + rng.normal(0.0, 1.0, sig.size) * sig
    return x0, np.diag(sig ** 2)


def drive_ekf(ekf, data: SensorData, vehicle, decimation: int = 10, heave_rate_sigma_mps: float = 0.05,
              gnss_att_sigma_rad: float | None = None, on_epoch=None, y2_gps_floor: float | None = None) -> EkfTrace:
    """Run an initialised EKF over ``data``: IMU samples averaged in blocks of ``decimation``
    (one predict per block), GNSS and suspension updates at their own times (the pipeline's
    policy, without the bus). ``on_epoch(kind, k)`` may return False to skip epoch k of
    ``"gnss"``/``"susp"``. Returns the per-predict trace."""
    from vdps_hil.estimation.measurements import ZrRateBuilder, suspension_measurement
    from vdps_hil.estimation.observations import ObsKind

    nz = data.noise
    kinds = ekf.kinds
    geo = vehicle.geometry
    t_imu = data.t_imu_ns
    cs_f = np.vstack([np.zeros(3), np.cumsum(data.specific_force, axis=0)])
    cs_w = np.vstack([np.zeros(3), np.cumsum(data.angular_rate, axis=0)])
    blocks = t_imu[decimation - 1::decimation]
    events: list[tuple[int, int, str, int]] = [(int(t), 0, "imu", 0) for t in blocks]
    events += [(int(t), 1, "gnss", k) for k, t in enumerate(data.t_gnss_ns)]
    events += [(int(t), 2, "susp", k) for k, t in enumerate(data.t_susp_ns)]
    events.sort()
    r_pos = np.diag([nz.gnss_pos_h_m ** 2, nz.gnss_pos_h_m ** 2, nz.gnss_pos_v_m ** 2])
    s_att = nz.gnss_att_rad if gnss_att_sigma_rad is None else gnss_att_sigma_rad
    r_att = np.eye(3) * s_att ** 2
    zr_rate = ZrRateBuilder(heave_rate_sigma_mps=heave_rate_sigma_mps)
    rec_t, rec_x, rec_p, rec_xf, rec_sf = [], [], [], [], []
    i_used = int(np.searchsorted(t_imu, ekf.t_ns, side="right"))
    layout = ekf.layout
    from vdps_hil.estimation.measurements import y2_gps_measurement

    for t, _, kind, k in events:
        if not ekf.initialized or t < ekf.t_ns:
            continue
        j = int(np.searchsorted(t_imu, t, side="right"))
        if j > i_used:
            ekf.set_input((cs_f[j] - cs_f[i_used]) / (j - i_used), (cs_w[j] - cs_w[i_used]) / (j - i_used))
            i_used = j
        ekf.predict_to(t)
        if kind == "imu":
            if ekf.initialized:
                xf, pf = ekf.full_state()
                rec_t.append(t)
                rec_x.append(ekf.x.copy())
                rec_p.append(ekf.P.copy())
                rec_xf.append(xf)
                rec_sf.append(np.sqrt(np.maximum(np.diag(pf), 0.0)))
            continue
        if on_epoch is not None and on_epoch(kind, k) is False:
            continue
        if kind == "gnss":
            if ObsKind.GNSS_POS in kinds:
                ekf.update(ObsKind.GNSS_POS, data.gnss_pos_enu[k], r_pos, t)
            if ObsKind.GNSS_ATT in kinds:
                ekf.update(ObsKind.GNSS_ATT, data.gnss_att[k], r_att, t)
            if ObsKind.Y2_GPS in kinds:
                z, r = y2_gps_measurement(data.gnss_att[k, 1], data.gnss_att[k, 2], s_att, s_att, y2_gps_floor)
                ekf.update(ObsKind.Y2_GPS, z, r, t)  # theta_v from eq 4 of the state
        else:
            sm = suspension_measurement(data.susp_deflection[k], geo.l_f_m, geo.l_r_m, geo.track_half_front_m,
                                        geo.track_half_rear_m, nz.susp_m)
            if ObsKind.Y1_SUS in kinds:
                ekf.update(ObsKind.Y1_SUS, sm.y1, sm.r_y1, t)
            if ObsKind.Y2_SUS_PLANE in kinds:
                ekf.update(ObsKind.Y2_SUS_PLANE, np.array([sm.z_r_m]), np.array([[sm.var_z_r_m2]]), t)
            if ObsKind.Y2_SUS_RATE in kinds:
                zr = zr_rate.push(t, sm.z_r_m, sm.var_z_r_m2)
                if zr is not None:
                    ekf.update(ObsKind.Y2_SUS_RATE, zr[0], zr[1], t)
    t_arr = np.array(rec_t, dtype=np.int64)
    tr = truth(data.maneuver, t_arr / _NS)
    yaw_pos = tuple(i for i, s in enumerate(layout.full_index) if s in (8, 11))
    n = layout.n
    return EkfTrace(t_arr, np.array(rec_x).reshape(-1, n), np.array(rec_p).reshape(-1, n, n),
                    np.array(rec_xf).reshape(-1, 12), np.array(rec_sf).reshape(-1, 12), tr.x_full,
                    layout.full_index, yaw_pos)
