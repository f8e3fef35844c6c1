"""Initial state and re-acquisition state of the EKF from the newest aiding data.

Initialisation (``initial_state``): at a GNSS fix once a heading is known (GNSS yaw, or course
at speed): attitude from the GNSS attitude (or roll/pitch from the mean specific force and yaw
from the course), velocity from speed/course or the difference of two fixes, road angles from a
recent suspension sample with eq 4 (road normal n = (C_g^v)^T C_r^v e_3), position =
fix - (C_g^v)^T l (l the GNSS antenna lever arm). After a NaN reset of the EKF the pipeline
re-initialises at the next fix.

Re-acquisition (``reacquisition_states``): after ``reacquire_after_gated`` consecutive gated
``gnss_pos`` updates (0, the default: never; the real-car sensor sets use 5) position, velocity
and yaw are reset to the newest fix (velocity and yaw from the GNSS speed/course when fresh and
moving, else from the last two fixes), their cross-covariances dropped, attitude and biases kept
(``MultiRateEKF.reacquire``; counted ``reacquisitions``).

"Fresh" aiding data is at most ``init_max_age_s`` from the fix's time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vdps_hil.estimation.kinematics import vehicle_angles_eq4
from vdps_hil.model.frames import dcm_gv
from vdps_hil.estimation.states import States

_NAN = math.nan


@dataclass
class LatestAiding:
    """The newest aiding data the pipeline has seen (times with the latencies removed)."""

    fix: tuple | None = None  # (t, enu, sigma_h, sigma_v)
    prev_fix: tuple | None = None  # the fix before
    att: tuple | None = None  # (t, [roll, pitch, yaw], sigmas)
    vel: tuple | None = None  # (t, speed, course)
    susp: tuple | None = None  # (t, SuspensionMeasurement)


def fresh(item, t: int, max_age_ns: int) -> bool:
    """Whether ``item`` (a tuple starting with its time) exists and is at most ``max_age_ns`` from t."""
    return item is not None and abs(t - item[0]) <= max_age_ns


def _attitude(t: int, aid: LatestAiding, level_f, gravity_mps2: float, cfg):
    """(roll, pitch, yaw, their prior sigmas, GNSS attitude used) at the fix of time t; yaw NaN
    when no heading is known (module docstring)."""
    # lf: mean specific force f_b [m/s^2] (levelling: pitch = asin(f_x / |f|), roll = atan2(f_y, f_z))
    max_age = int(cfg.init_max_age_s * 1e9)
    att_ok = fresh(aid.att, t, max_age)
    roll = pitch = yaw = _NAN
    s_att = [cfg.init_level_sigma_rad, cfg.init_level_sigma_rad, cfg.init_course_sigma_rad]
    if att_ok:
        z, sig = aid.att[1], aid.att[2]
        roll, pitch, yaw = (float(v) for v in z)
        s_att = [2.0 * v for v in sig]
    vel_ok = fresh(aid.vel, t, max_age)
    if not math.isfinite(yaw) and vel_ok and aid.vel[1] >= cfg.gnss_course_min_speed_mps \
            and math.isfinite(aid.vel[2]):
        yaw = aid.vel[2]
        s_att[2] = cfg.init_course_sigma_rad
    if not math.isfinite(yaw):
        return roll, pitch, yaw, s_att, att_ok
    if not (math.isfinite(roll) and math.isfinite(pitch)):
        lf = level_f
        if lf is None:
            lf = (0.0, 0.0, gravity_mps2)
        fn = math.sqrt(lf[0] ** 2 + lf[1] ** 2 + lf[2] ** 2) or 1.0
        if not math.isfinite(pitch):
            pitch = math.asin(max(-1.0, min(1.0, lf[0] / fn)))
            s_att[1] = cfg.init_level_sigma_rad
        if not math.isfinite(roll):
            roll = math.atan2(lf[1], lf[2])
            s_att[0] = cfg.init_level_sigma_rad
    return roll, pitch, yaw, s_att, att_ok


def initial_state(t: int, aid: LatestAiding, level_f, gravity_mps2: float, lever, layout, cfg):
    """(x0, P0) in the filter ``layout`` at the fix of time t (``aid.fix``), or None while no
    heading is known (module docstring). ``level_f``: recent mean specific force (None: level),
    ``lever``: GNSS antenna lever arm [m] (body axes), ``cfg``: ``PipelineConfig``."""
    # sh, sv: horizontal / vertical fix sigma [m]; s_att: prior sigmas of roll, pitch, yaw [rad];
    # c: C_g^v of eq 1; x, sig: the 12 states of eq 7 and their prior sigmas
    _, enu, sh, sv = aid.fix
    roll, pitch, yaw, s_att, att_ok = _attitude(t, aid, level_f, gravity_mps2, cfg)
    if not math.isfinite(yaw):
        return None
    vel_ok = fresh(aid.vel, t, int(cfg.init_max_age_s * 1e9))
    c = dcm_gv(roll, pitch, yaw)
    x = np.zeros(12)
    x[0:3] = enu - c.T @ lever
    sig = np.zeros(12)
    sig[0:3] = (sh, sh, sv)
    if vel_ok and aid.vel[1] >= cfg.gnss_course_min_speed_mps and math.isfinite(aid.vel[2]):
        x[3:5] = (aid.vel[1] * math.cos(aid.vel[2]), aid.vel[1] * math.sin(aid.vel[2]))
        sig[3:6] = (1.0, 1.0, 1.0)
    elif aid.prev_fix is not None and 0 < t - aid.prev_fix[0] <= int(cfg.init_max_age_s * 1e9):
        dt = (t - aid.prev_fix[0]) * 1e-9
        x[3:5] = (enu[0:2] - aid.prev_fix[1][0:2]) / dt
        sig[3:5] = math.sqrt(2.0) * sh / dt + 1.0
        sig[5] = 2.0
    else:
        sig[3:6] = cfg.init_velocity_sigma_mps
    x[6:9] = (roll, pitch, yaw)
    sig[6:9] = s_att
    sig[9:12] = cfg.init_road_sigma_rad
    if fresh(aid.susp, t, int(cfg.init_max_age_s * 1e9)) and layout.road_estimated:
        sm = aid.susp[1]
        # road normal in {g}: n = (C_g^v)^T C_r^v e_3, C_r^v e_3 = [s th_v, s ph_v c th_v, c ph_v c th_v]
        col = np.array([math.sin(sm.theta_v_rad), math.sin(sm.phi_v_rad) * math.cos(sm.theta_v_rad),
                        math.cos(sm.phi_v_rad) * math.cos(sm.theta_v_rad)])
        n = c.T @ col
        x[9] = -math.asin(max(-1.0, min(1.0, n[1])))
        x[10] = math.atan2(-n[0], n[2])
        sig[9:11] = 2.0 * max(s_att[0], s_att[1]) if att_ok else cfg.init_road_sigma_rad
    if layout.psi_v_state:
        x[11] = vehicle_angles_eq4(x[6:11], with_jacobian=False)[2]
    x0 = layout.from_full(x)
    ec = cfg.ekf
    sig_aug = [ec.gyro_bias_sigma_radps] * 3 + [ec.accel_bias_sigma_mps2] * 3 + [ec.wheel_scale_sigma]
    sig = np.concatenate([sig, sig_aug])
    P0 = np.diag(sig[layout.full_index] ** 2)
    return x0, P0


def reacquisition_states(t: int, t_now: int, enu, sh: float, sv: float, x_full, aid: LatestAiding, lever,
                         cfg) -> dict:
    """{full state index: (value, sigma)} to reset at the filter time ``t_now`` from the fix
    ``enu`` (sigmas ``sh``, ``sv``) of time t (module docstring); ``x_full``: the filter's full
    state, ``cfg``: ``PipelineConfig``."""
    # xf: full state of eq 7; sh, sv: fix sigmas [m]; s_vel, s_yaw: sigmas of the reset velocity
    # [m/s] and yaw [rad] (s_yaw None: yaw kept); lead: age of the fix behind the filter [s]
    xf = x_full
    yaw, s_yaw = float(xf[States.PSI_G]), None
    vel, s_vel = None, cfg.init_velocity_sigma_mps
    max_age = int(cfg.init_max_age_s * 1e9)
    if fresh(aid.vel, t, max_age) and aid.vel[1] >= cfg.gnss_course_min_speed_mps \
            and math.isfinite(aid.vel[2]):
        sp, crs = aid.vel[1], aid.vel[2]
        vel, s_vel = (sp * math.cos(crs), sp * math.sin(crs)), cfg.reacquire_velocity_sigma_mps
        yaw, s_yaw = crs, cfg.init_course_sigma_rad
    elif aid.prev_fix is not None and 0 < t - aid.prev_fix[0] <= max_age:
        dt = (t - aid.prev_fix[0]) * 1e-9
        vel = ((enu[0] - aid.prev_fix[1][0]) / dt, (enu[1] - aid.prev_fix[1][1]) / dt)
        s_vel = math.sqrt(2.0) * sh / dt + cfg.reacquire_velocity_sigma_mps
        if math.hypot(*vel) >= cfg.gnss_course_min_speed_mps:
            yaw, s_yaw = math.atan2(vel[1], vel[0]), cfg.init_course_sigma_rad
    if vel is None:
        vel = (float(xf[3]), float(xf[4]))
    c = dcm_gv(float(xf[6]), float(xf[7]), yaw)
    lead = (t_now - t) * 1e-9  # the fix is older than the filter: carry it forward
    p = np.asarray(enu, dtype=float) - c.T @ lever
    a = {States.X_G: (p[0] + vel[0] * lead, sh), States.Y_G: (p[1] + vel[1] * lead, sh),
         States.Z_G: (p[2], sv), States.XDOT_G: (vel[0], s_vel), States.YDOT_G: (vel[1], s_vel),
         States.ZDOT_G: (0.0, min(s_vel, 2.0))}
    if s_yaw is not None:
        a[States.PSI_G] = (yaw, s_yaw)
    return a
