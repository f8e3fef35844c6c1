"""Sensor models driven by the truth simulator: IMU, GNSS, tachometers, suspension displacement,
wheel torque and steering angle, each at its profile rate (``sim.profiles``) with its own seeded
random streams. They produce measured values in SI; ``sim.wire`` and ``sim.drive`` put them on
the real wire formats with the devices' timing.

IMU (Xsens MTi, sensor axes; ``model.effects.imu`` for the effect formulas)
--------------------------------------------------------------------------
::

    f_b  = f_cg + omega_dot x r + omega x (omega x r)          (f_cg = a_cg - g, body axes)
    f_b += measurement effects (imu_lever_arm: A(omega, omega_dot) r_e; imu_bias: + b_a, + b_g)
    f_s  = (I + E_a) C_b^s f_b + sigma_a n_a ,   w_s = (I + E_g) C_b^s omega + sigma_g n_g
    C_b^s = R(x, roll) R(y, pitch) R(z, yaw)      (mounting ``imu_rotation_rpy_rad``, eq 1 matrices)
    E = diag(s_x, s_y, s_z) + M   s ~ N(0, (scale_factor_ppm 1e-6)^2),
                                  M_ij ~ N(0, misalignment^2) for i != j, M_ii = 0

r is the mounting lever arm (vehicle ``imu_lever_arm_m``); E_a, E_g are drawn once per drive
(one unit's calibration residue) from a stream separate from the noise, so switching them on
leaves the noise sequence unchanged. The effects act in body axes (their formulas are written
there). Values go out as float32; the packet counter is k mod 2^16 and SampleTimeFine is the
device clock (simulation time, plus a ``clock_jump`` fault) in 100 us ticks.

GNSS (multi-antenna receiver, NMEA GGA + RMC + attitude sentence)
-----------------------------------------------------------------
::

    p_ant = p_cg + (C_g^v)^T r_ant          v_ant = (C_g^v)^T (v_b + omega x r_ant)     (ENU)
    (lat, lon, h) = geodetic(origin, p_ant + e),   alt_MSL = h - N_geoid
    e_E, e_N ~ sigma_h,  e_U ~ sigma_v      per axis; white (tau = 0) or first-order Gauss-Markov
    e_k = a e_(k-1) + sqrt(1 - a^2) sigma w_k,   a = exp(-T / tau),   e_0 ~ N(0, sigma^2)
    speed = |v_ant,EN + n_v|,  course = atan2(v_N, v_E) (paper yaw),  n_v ~ N(0, sigma_vel^2) per axis
    yaw, pitch, roll = psi_g, theta_g, phi_g + N(0, sigma_att^2)   (absolute body attitude, eq 1)

sigma_h is per horizontal axis (Table 1 "horizontal 1 m" read as the E and N standard
deviations), sigma_vel = ``VELOCITY_SIGMA_PER_POSITION_SIGMA`` * sigma_h (Doppler velocity is
about 20 times better than code position; Table 1 gives none), so a zero-noise profile has no
velocity noise either. N_geoid = ``GEOID_SEPARATION_M`` (printed in GGA: alt + separation
recovers h). UTC = the recording's simulated epoch (``record.schemas.DEFAULT_SIM_EPOCH_NS``,
2012-11-09T00:00Z) + t (+ a ``clock_jump``); the sentences carry the measurement epoch's time and
leave the receiver ``latency_s`` later (GNSS latency: the time tag stays the epoch's, as real
receivers do). Course is left empty below ``COURSE_MIN_SPEED_MPS``.

Chassis sensors (CAN, ``dbc/vdps.dbc``)
---------------------------------------
::

    tachometer  omega_i + N(0, sigma^2)                          wheel spin [rad/s]
    suspension  H_i + N(0, sigma^2)                              deflection from design ride height,
                                                                 compression positive [m]
    torque      T_i - B_i sat(omega_i / 2 rad/s) + N(0, sigma^2)  net applied wheel torque [N m]
                                                                 (as the truth's wheel_torque_nm_i)
    steering    delta_sw + N(0, sigma^2)                         steering wheel angle [rad]

Quantisation (profile ``[quantisation] dbc``)
---------------------------------------------
The CAN wire always quantises by the DBC scaling (step q; error uniform, variance q^2/12): a DBC
cannot carry more. The switch says whether that error is part of the profile's sigma:

* ``dbc = false`` (table1): the profile sigma is the total error of the value on the wire. The
  sensor draws sigma_eff = sqrt(max(sigma^2 - q^2/12, 0)) so that the decoded values scatter with
  the profile sigma (Table 1 "with no other error"); with sigma^2 < q^2/12 (e.g. sigma = 0) the
  wire's quantisation is all that remains.
* ``dbc = true``: the sensor draws the full sigma and the wire adds its quantisation on top
  (total variance sigma^2 + q^2/12): quantisation as an extra error source.

The IMU (float32) and NMEA (printed decimals) keep their formats' own resolution either way.

Sampling and random streams: :mod:`vdps_hil.sim.sampling` (every sensor samples the per-step
truth at its own rate, from its own seeded streams).

Symbols: f specific force [m/s^2], omega body rate [rad/s], omega_dot angular acceleration
[rad/s^2], r lever arm [m], C direction cosine matrix, sigma standard deviation (units of the
quantity), n, w standard normal draws, T sampling period [s], tau correlation time [s].
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from vdps_hil.codecs.nmea.attitude import format_attitude
from vdps_hil.codecs.nmea.position import format_gga, format_rmc
from vdps_hil.codecs.nmea.sentence import wrap_sentence
from vdps_hil.geodesy import DEFAULT_ORIGIN, EnuOrigin
from vdps_hil.model.core import BRAKE_HOLD_SPEED_RADPS
from vdps_hil.model.effects import ImuBias, ImuKinematics, ImuLeverArm, MeasurementEffect
from vdps_hil.model.frames import dcm_global_to_vehicle
from vdps_hil.model.params import Mounting
from vdps_hil.record.schemas import DEFAULT_SIM_EPOCH_NS
from vdps_hil.units import NS_PER_S

from .profiles import GnssProfile, ImuProfile, SensorProfile
from .sampling import Block, Sampler, rng_for

__all__ = ["ImuModel", "ImuOutput", "GnssModel", "GnssEpoch", "ChassisSensor", "chassis_sensors",
           "noise_budget_sigma",
           "GEOID_SEPARATION_M", "VELOCITY_SIGMA_PER_POSITION_SIGMA", "COURSE_MIN_SPEED_MPS",
           "ATTITUDE_LAYOUT"]

GEOID_SEPARATION_M = 20.0
"""Geoid separation N printed in GGA [m] (about the EGM96 undulation near the default origin;
only the consistency alt + N = ellipsoidal height matters)."""
VELOCITY_SIGMA_PER_POSITION_SIGMA = 0.05
"""GNSS velocity noise per horizontal axis = this [1/s] * the horizontal position sigma."""
COURSE_MIN_SPEED_MPS = 0.1
"""Below this speed over ground RMC prints an empty course (as receivers do at standstill)."""
GNSS_NUM_SATS = 14
GNSS_HDOP = 0.8
REACQUIRED_QUALITY = 1
"""GGA quality reported while a receiver re-acquires after an outage (standalone fix)."""

ATTITUDE_LAYOUT = {"PASHR": "PASHR", "HPR": "HPR", "PTNL_AVR": "PTNL,AVR"}
"""Profile ``attitude_sentence`` -> ``codecs.nmea`` layout."""


def noise_budget_sigma(sigma: float, resolution: float, quantise_dbc: bool) -> float:
    """The white-noise sigma a CAN sensor draws (module docstring, "Quantisation")."""
    if quantise_dbc:
        return sigma
    return math.sqrt(max(sigma * sigma - resolution * resolution / 12.0, 0.0))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack((a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                     a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), axis=1)


def lever_arm_accel(rate: np.ndarray, angular_accel: np.ndarray, r) -> np.ndarray:
    """omega_dot x r + omega x (omega x r) for every row (N, 3)."""
    rr = np.broadcast_to(np.asarray(r, dtype=float), rate.shape)
    return _cross(angular_accel, rr) + _cross(rate, _cross(rate, rr))


def _apply_effects_generic(effects: Sequence[MeasurementEffect], t_ns: np.ndarray,
                           fields: dict[str, np.ndarray], f_cg: np.ndarray, rate: np.ndarray,
                           wdot: np.ndarray) -> None:
    """Per-sample ``effect.apply`` for effects without a vectorised path (slow, exact)."""
    names = list(fields)
    for i in range(len(t_ns)):
        kin = ImuKinematics(t_ns[i] / NS_PER_S, tuple(f_cg[i]), tuple(rate[i]), tuple(wdot[i]))
        d = {k: float(fields[k][i]) for k in names}
        for e in effects:
            d = e.apply(d, kin)
        for k in names:
            fields[k][i] = d[k]


# ---------------------------------------------------------------------------------------------
# IMU
# ---------------------------------------------------------------------------------------------
@dataclass
class ImuOutput:
    """IMU samples: measurement times [ns], packet numbers k, specific force and rate in sensor
    axes (float64 here; float32 on the wire)."""

    t_ns: np.ndarray
    k: np.ndarray
    specific_force_mps2: np.ndarray
    angular_rate_radps: np.ndarray


class ImuModel:
    """The IMU of the module docstring. ``sample(block, faults)`` -> :class:`ImuOutput`."""

    F = ("specific_force_mps2_x", "specific_force_mps2_y", "specific_force_mps2_z")
    W = ("angular_rate_radps_x", "angular_rate_radps_y", "angular_rate_radps_z")

    def __init__(self, profile: ImuProfile, mounting: Mounting, effects: Sequence[MeasurementEffect],
                 seed: int, dt_ns: int):
        self.profile = profile
        self.sampler = Sampler(profile.rate_hz, dt_ns)
        self.lever_arm_m = np.asarray(mounting.imu_lever_arm_m, dtype=float)
        r, p, y = mounting.imu_rotation_rpy_rad
        self.c_body_to_sensor = dcm_global_to_vehicle(r, p, y)
        self._noise = rng_for(seed, "imu.noise")
        cal = rng_for(seed, "imu.calibration")
        # drawn whatever the switches: the noise stream and the other constants do not move
        raw_a = cal.standard_normal(3), cal.standard_normal((3, 3))
        raw_g = cal.standard_normal(3), cal.standard_normal((3, 3))
        self.error_accel = self._error_matrix(*raw_a)
        self.error_gyro = self._error_matrix(*raw_g)
        self._m_accel = (np.eye(3) + self.error_accel) @ self.c_body_to_sensor
        self._m_gyro = (np.eye(3) + self.error_gyro) @ self.c_body_to_sensor
        self.effects_fast: list[MeasurementEffect] = []
        self.effects_slow: list[MeasurementEffect] = []
        for e in effects:
            if not (set(e.FIELDS) & set(self.F + self.W)):
                continue
            (self.effects_fast if type(e) in (ImuBias, ImuLeverArm) else self.effects_slow).append(e)

    def _error_matrix(self, s: np.ndarray, m: np.ndarray) -> np.ndarray:
        e = m * self.profile.misalignment_rad
        np.fill_diagonal(e, s * self.profile.scale_factor_ppm * 1e-6)
        return e

    def sample(self, block: Block, faults=None) -> ImuOutput:
        rows, ks = self.sampler.pick(block)
        b = block.take(rows)
        f_cg, w, wd = b.specific_force, b.rate, b.angular_accel
        f = f_cg + lever_arm_accel(w, wd, self.lever_arm_m)
        wb = w.copy()
        for e in self.effects_fast:
            p = e.params
            if isinstance(e, ImuLeverArm):
                f += lever_arm_accel(w, wd, (p["lever_x_m"], p["lever_y_m"], p["lever_z_m"]))
            else:
                f += np.array([p[f"accel_bias_{a}_mps2"] for a in "xyz"])
                wb += np.array([p[f"gyro_bias_{a}_radps"] for a in "xyz"])
        if self.effects_slow:
            fields = {n: f[:, i] for i, n in enumerate(self.F)}
            fields.update({n: wb[:, i] for i, n in enumerate(self.W)})
            fields = {k: v.copy() for k, v in fields.items()}
            _apply_effects_generic(self.effects_slow, b.t_ns, fields, f_cg, w, wd)
            f = np.stack([fields[n] for n in self.F], axis=1)
            wb = np.stack([fields[n] for n in self.W], axis=1)
        n = len(ks)
        f_s = f @ self._m_accel.T + self.profile.accel_sigma_mps2 * self._noise.standard_normal((n, 3))
        w_s = wb @ self._m_gyro.T + self.profile.gyro_sigma_radps * self._noise.standard_normal((n, 3))
        if faults is not None:
            faults.imu_values(b.t_ns, f_s, w_s)
        return ImuOutput(b.t_ns, ks, f_s, w_s)

    def describe(self) -> dict:
        """The drawn unit constants (truth metadata)."""
        return {"accel_error_matrix": self.error_accel.tolist(),
                "gyro_error_matrix": self.error_gyro.tolist(),
                "c_body_to_sensor": self.c_body_to_sensor.tolist(),
                "lever_arm_m": self.lever_arm_m.tolist()}


# ---------------------------------------------------------------------------------------------
# GNSS
# ---------------------------------------------------------------------------------------------
@dataclass
class GnssEpoch:
    """One receiver epoch (measured values, SI and paper angles); ``state`` ok / lost /
    reacquiring."""

    t_ns: int
    state: str
    lat_deg: float
    lon_deg: float
    alt_msl_m: float
    speed_mps: float
    course_rad: float | None
    yaw_rad: float
    pitch_rad: float
    roll_rad: float


def _hhmmss(utc_s: float) -> str:
    """UTC seconds of day -> hhmmss.ss (centiseconds, as the GGA/RMC generators print)."""
    cs = int(round(utc_s * 100)) % (86400 * 100)
    hh, rem = divmod(cs, 360000)
    mm, rem = divmod(rem, 6000)
    ss, frac = divmod(rem, 100)
    return f"{hh:02d}{mm:02d}{ss:02d}.{frac:02d}"


class GnssModel:
    """The GNSS receiver of the module docstring. ``sample(block, faults)`` -> epochs;
    ``sentences(epoch, faults)`` -> the NMEA lines it sends for an epoch."""

    def __init__(self, profile: GnssProfile, mounting: Mounting, seed: int, dt_ns: int,
                 origin: EnuOrigin = DEFAULT_ORIGIN, epoch_ns: int = DEFAULT_SIM_EPOCH_NS):
        self.profile = profile
        self.sampler = Sampler(profile.rate_hz, dt_ns)
        self.antenna_m = np.asarray(mounting.gnss_lever_arm_m, dtype=float)
        self.origin = origin
        self.epoch_ns = int(epoch_ns)
        self.layout = ATTITUDE_LAYOUT[profile.attitude_sentence]
        self._pos_rng = rng_for(seed, "gnss.position")
        self._vel_rng = rng_for(seed, "gnss.velocity")
        self._att_rng = rng_for(seed, "gnss.attitude")
        self._sigma_pos = np.array([profile.pos_sigma_h_m, profile.pos_sigma_h_m, profile.pos_sigma_v_m])
        self.sigma_vel_mps = VELOCITY_SIGMA_PER_POSITION_SIGMA * profile.pos_sigma_h_m
        period_s = self.sampler.period_ns / NS_PER_S
        tau = profile.gauss_markov_tau_s
        self._a = math.exp(-period_s / tau) if tau > 0 else 0.0
        self._err: np.ndarray | None = None

    def _position_error(self) -> np.ndarray:
        w = self._pos_rng.standard_normal(3)
        if self._err is None or self._a == 0.0:
            self._err = self._sigma_pos * w
        else:
            self._err = self._a * self._err + math.sqrt(1.0 - self._a * self._a) * self._sigma_pos * w
        return self._err

    def sample(self, block: Block, faults=None) -> list[GnssEpoch]:
        rows, _ = self.sampler.pick(block)
        out = []
        sig_att = self.profile.attitude_sigma_rad
        for i in rows.tolist():
            t_ns = int(block.t_ns[i])
            # every draw is made whatever the fix state, so an outage does not shift the streams
            err = self._position_error()
            dv = self.sigma_vel_mps * self._vel_rng.standard_normal(2)
            datt = sig_att * self._att_rng.standard_normal(3)
            state = faults.gnss_fix_state(t_ns) if faults is not None else "ok"
            roll, pitch, yaw = block.euler[i]
            c = dcm_global_to_vehicle(roll, pitch, yaw)
            p_ant = block.pos[i] + c.T @ self.antenna_m
            w = block.rate[i]
            v_ant = c.T @ (block.vel_b[i] + np.cross(w, self.antenna_m))
            lat, lon, h = self.origin.to_geodetic(p_ant + err)
            ve, vn = v_ant[0] + dv[0], v_ant[1] + dv[1]
            speed = math.hypot(ve, vn)
            course = math.atan2(vn, ve) if speed >= COURSE_MIN_SPEED_MPS else None
            out.append(GnssEpoch(t_ns, state, lat, lon, h - GEOID_SEPARATION_M, speed, course,
                                 math.remainder(yaw + datt[0], 2 * math.pi), pitch + datt[1], roll + datt[2]))
        return out

    def utc(self, t_ns: int, faults=None) -> tuple[float, _dt.date]:
        """(UTC seconds of day, UTC date) of the receiver clock at true time t."""
        off = 0
        if faults is not None:
            o = faults.clock_offset_ns("gnss", np.array([t_ns]))
            off = 0 if o is None else int(o[0])
        ns = self.epoch_ns + t_ns + off
        days, rem = divmod(ns, 86400 * NS_PER_S)
        date = _dt.date(1970, 1, 1) + _dt.timedelta(days=days)
        return rem / NS_PER_S, date

    def sentences(self, ep: GnssEpoch, faults=None) -> list[bytes]:
        p = self.profile
        utc_s, date = self.utc(ep.t_ns, faults)
        if ep.state == "lost":
            time = _hhmmss(utc_s)
            return [wrap_sentence(f"GPGGA,{time},,,,,0,00,99.9,,,,,,"),
                    wrap_sentence(f"GPRMC,{time},V,,,,,,,{date.strftime('%d%m%y')},,,N")]
        quality = REACQUIRED_QUALITY if ep.state == "reacquiring" else p.fix_quality
        gga = format_gga(utc_s, ep.lat_deg, ep.lon_deg, ep.alt_msl_m, fix_quality=quality,
                         num_sats=GNSS_NUM_SATS, hdop=GNSS_HDOP, geoid_sep_m=GEOID_SEPARATION_M)
        rmc = format_rmc(utc_s, ep.lat_deg, ep.lon_deg, ep.speed_mps, ep.course_rad, date=date)
        sig = p.attitude_sigma_rad
        att = format_attitude(self.layout, utc_time_s=utc_s, yaw_rad=ep.yaw_rad,
                              pitch_rad=ep.pitch_rad, roll_rad=ep.roll_rad, yaw_sigma_rad=sig,
                              pitch_sigma_rad=sig, roll_sigma_rad=sig, quality=quality,
                              ins_status=0, num_sats=GNSS_NUM_SATS)
        return [gga, rmc, att]


# ---------------------------------------------------------------------------------------------
# Chassis sensors on CAN
# ---------------------------------------------------------------------------------------------
class ChassisSensor:
    """A chassis sensor: ``fields`` (catalogue names), rate, white noise per field, the truth
    extractor ``truth(block) -> (N, k)`` and the measurement effects that touch its fields.
    ``sample(block)`` -> (t_ns (N,), values (N, k))."""

    def __init__(self, name: str, fields: Sequence[str], rate_hz: float, sigma: float,
                 truth: Callable[[Block], np.ndarray], seed: int, dt_ns: int,
                 resolution: Sequence[float] | None = None, quantise_dbc: bool = False,
                 effects: Sequence[MeasurementEffect] = ()):
        self.name = name
        self.fields = tuple(fields)
        self.sampler = Sampler(rate_hz, dt_ns)
        res = resolution if resolution is not None else (0.0,) * len(self.fields)
        self.sigma = float(sigma)
        self.sigma_eff = np.array([noise_budget_sigma(sigma, q, quantise_dbc) for q in res])
        self.truth = truth
        self._rng = rng_for(seed, f"{name}.noise")
        self.effects = [e for e in effects if set(e.FIELDS) & set(self.fields)]

    def sample(self, block: Block) -> tuple[np.ndarray, np.ndarray]:
        rows, _ = self.sampler.pick(block)
        b = block.take(rows)
        v = np.array(self.truth(b), dtype=float).reshape(len(rows), len(self.fields))
        if self.effects:
            fields = {n: v[:, i].copy() for i, n in enumerate(self.fields)}
            _apply_effects_generic(self.effects, b.t_ns, fields, b.specific_force, b.rate, b.angular_accel)
            v = np.stack([fields[n] for n in self.fields], axis=1)
        v = v + self.sigma_eff * self._rng.standard_normal(v.shape)
        return b.t_ns, v


def _net_torque(b: Block) -> np.ndarray:
    s = np.clip(b.wheel_spin / BRAKE_HOLD_SPEED_RADPS, -1.0, 1.0)
    return b.drive_torque - b.brake_torque * s


def chassis_sensors(profile: SensorProfile, seed: int, dt_ns: int,
                    resolution: Mapping[str, float] | None = None,
                    effects: Sequence[MeasurementEffect] = ()) -> list[ChassisSensor]:
    """Tachometers, suspension, wheel torque and steering of ``profile`` (module docstring);
    ``resolution``: field -> DBC step for the quantisation switch."""
    res = resolution or {}
    q = profile.quantise_dbc

    def mk(name, fields, rate, sigma, truth):
        return ChassisSensor(name, fields, rate, sigma, truth, seed, dt_ns,
                             [res.get(f, 0.0) for f in fields], q, effects)

    def four(stem):
        return tuple(f"{stem}_{i}" for i in range(1, 5))

    return [mk("tachometer", four("wheel_speed_radps"), profile.tachometer.rate_hz,
               profile.tachometer.sigma_radps, lambda b: b.wheel_spin),
            mk("suspension", four("susp_deflection_m"), profile.suspension.rate_hz,
               profile.suspension.sigma_m, lambda b: b.susp),
            mk("wheel_torque", four("wheel_torque_nm"), profile.wheel_torque.rate_hz,
               profile.wheel_torque.sigma_nm, _net_torque),
            mk("steering", ("steer_wheel_angle_rad",), profile.steering.rate_hz,
               profile.steering.sigma_rad, lambda b: b.steer)]
