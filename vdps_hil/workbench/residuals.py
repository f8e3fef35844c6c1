"""Model against measurement: the residual of every equation of eq 13, the GNSS/IMU innovations
of the measurement effects, and the input-driven simulation error over fixed horizons.

Equation residuals (one row per table row; "measured" = the estimator's signals, "model" = the
paper's reduced model, ``model.core.Model(vehicle, effects, unsprung_dof=False)``, evaluated at
the estimated state with the recorded inputs; the state is built exactly as the predictor builds
its initial state, ``prediction.predictor.Predictor.core_state``)::

    long, lat, vert    r = m f_meas - (F_tire + F_eff)          [N]    f: IMU specific force at the CG
    roll, pitch, yaw   r = I (omega_dot_meas - omega_dot_model)  [N m]  (I_x, I_y, I_z)
    wheel_i            r = I_w (omega_dot_i,meas - omega_dot_i,model)   [N m]
    wheel_speed_i      r = v_l,i (1 + kappa_q,i) - r_i omega_i,meas     [m/s]

Writing the force balance with the specific force (f = a - g) keeps gravity, and so the road
grade and bank, out of it: m f = F_tire + F_eff is eq 13 with m G moved to the left. The
``wheel_speed_i`` rows are the kinematic form of the wheel-spin equation: v_l,i is the wheel
centre's speed along the wheel from the estimated body motion, kappa_q,i = (T_i + T_eff,i -
I_w omega_dot_i) / (r_i C_kappa,i) the slip the measured spin balance asks for (eq 15), so a
wrong rolling radius (``low_pressure_tire``) or slip stiffness shows here.

Nuisance directions (``nuisance``, per row): the estimator's body velocity errors (delta v_x,
delta v_y: a 0.05 m/s lateral velocity error moves the slip angles by 0.002 rad and the axle
forces by 300 N; central differences of the residual) and the four longitudinal tire forces
F_a,i (exact: a force along the wheel heading e_l at the contact point r_c, i.e. (e_l, r_c x
e_l) on the body and -r_i on the wheel's spin). The ranking removes the force directions row by
row -- the longitudinal tire forces are then taken from the measured spin balance instead of
eq 15, whose slip stiffnesses are poorly known -- and lets the velocity errors vary slowly in
time within the estimator's own sigma (``ranking``), so an effect is judged only on what the
estimator's errors cannot explain.

Noise per equation (``sigma``): the robust spread of the residual above 3 Hz, scaled to the
table's bandwidth (the residual of an unmodelled effect is slow; the sensor noise is not).

Innovations of the measurement effects (:class:`Innovations`): the IMU integrated open loop
(strapdown, ENU, from the estimator's state at the table's first row) against every GNSS
measurement -- attitude (roll, pitch, yaw), horizontal antenna velocity (speed and course) and
antenna position::

    C_dot = -[omega x] C,   v_dot = C^T f + g,   p_dot = v        (C = C_g^v, eq 1)
    e = z_GNSS - h(strapdown)

These are the estimator's own innovations, taken over the whole drive instead of one filter step,
so a slow sensor error accumulates instead of being absorbed by the next update. Nuisance: the
initial attitude, velocity and position (9 columns). An effect's column is the change of e when
its field regressors (``MeasurementEffect.regressors``) are taken out of the readings.

Simulation error (:func:`simulation_errors`): the predictor (``prediction.predictor``),
input-driven by the recorded steering and wheel torques, started from the estimate every
``every_s`` seconds; its CG position, road-relative attitude and speed against the estimate at
0.5, 1 and 2 s after the start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.signal import butter, filtfilt

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import EQUATIONS as DYNAMIC_EQUATIONS
from vdps_hil.model.effects.base import ImuKinematics, MeasurementEffect
from vdps_hil.model.frames import dcm_gv_batch
from vdps_hil.model.params import Vehicle
from vdps_hil.prediction.config import PredictorConfig
from vdps_hil.prediction.initial_state import InputTrajectory, PredictorInitialState
from vdps_hil.prediction.predictor import Predictor
from vdps_hil.units import GRAVITY_MPS2

from .dataset import DriveTable

__all__ = ["INNOVATION_CHANNELS", "EQUATIONS", "DYNAMIC_EQUATIONS", "KINEMATIC_EQUATIONS", "EQUATION_LABELS", "EQUATION_UNITS",
           "EquationResiduals", "compute_residuals", "RowStates", "row_states", "Innovations",
           "compute_innovations", "parameter_columns", "SimErrors", "simulation_errors", "HORIZONS_S", "MIN_SPEED_MPS",
           "effect_quantities"]

KINEMATIC_EQUATIONS: tuple[str, ...] = tuple(f"wheel_speed_{i}" for i in range(1, 5))
EQUATIONS: tuple[str, ...] = tuple(DYNAMIC_EQUATIONS) + KINEMATIC_EQUATIONS
EQUATION_LABELS = {"long": "longitudinal force", "lat": "lateral force", "vert": "vertical force",
                   "roll": "roll moment", "pitch": "pitch moment", "yaw": "yaw moment",
                   **{f"wheel_{i}": f"wheel {i} spin" for i in range(1, 5)},
                   **{f"wheel_speed_{i}": f"wheel {i} speed" for i in range(1, 5)}}
EQUATION_UNITS = {"long": "N", "lat": "N", "vert": "N", "roll": "N m", "pitch": "N m", "yaw": "N m",
                  **{f"wheel_{i}": "N m" for i in range(1, 5)}, **{f"wheel_speed_{i}": "m/s" for i in range(1, 5)}}
HORIZONS_S = (0.5, 1.0, 2.0)
MIN_SPEED_MPS = 5.0
"""Rows slower than this are left out (slip is undefined near standstill; core low-speed floor)."""
_EQ = {e: k for k, e in enumerate(EQUATIONS)}
NUISANCE_NAMES = ("vel_b_x", "vel_b_y", "slip_1", "slip_2", "slip_3", "slip_4")


# ----------------------------------------------------------------------------- states per row
@dataclass
class RowStates:
    """Per usable table row: the core state x, inputs u, road env, plus what the residual needs."""

    index: np.ndarray
    x: list
    u: list
    env: list
    meas: np.ndarray  # (n, 22): f(3), omega_dot(3), wheel_accel(4), wheel speeds(4), H(4), H_dot(4)
    has_susp: bool


def row_states(table: DriveTable, vehicle: Vehicle) -> RowStates:
    """The reduced model's state at every usable row (``Predictor.core_state``: pose and heave
    from the suspension when it is measured, eq 5)."""
    pred = Predictor(vehicle, PredictorConfig(horizon_s=0.02, step_s=0.01))
    c = table.columns
    need = ["specific_force_b_mps2_x", "specific_force_b_mps2_y", "specific_force_b_mps2_z",
            "rate_b_radps_x", "rate_b_radps_y", "rate_b_radps_z", "steer_wheel_angle_rad",
            *[f"wheel_speed_radps_{i}" for i in range(1, 5)], *[f"wheel_torque_nm_{i}" for i in range(1, 5)],
            *[f"vel_g_mps_{a}" for a in "enu"], "roll_g_rad", "pitch_g_rad", "yaw_g_rad"]
    ok = np.ones(len(table), bool)
    for n in need:
        ok &= np.isfinite(c[n])
    speed = np.hypot(c["vel_g_mps_e"], c["vel_g_mps_n"])
    ok &= speed >= MIN_SPEED_MPS
    has_susp = table.has("susp_deflection_m_1", "susp_deflection_rate_mps_1")
    idx = np.flatnonzero(ok)
    xs, us, envs = [], [], []
    meas = np.column_stack([c["specific_force_b_mps2_x"], c["specific_force_b_mps2_y"], c["specific_force_b_mps2_z"],
                            c["angular_accel_b_radps2_x"], c["angular_accel_b_radps2_y"], c["angular_accel_b_radps2_z"],
                            *[c[f"wheel_accel_radps2_{i}"] for i in range(1, 5)],
                            *[c[f"wheel_speed_radps_{i}"] for i in range(1, 5)],
                            *[c[f"susp_deflection_m_{i}"] for i in range(1, 5)],
                            *[c[f"susp_deflection_rate_mps_{i}"] for i in range(1, 5)]])[idx]
    for k in idx:
        susp = tuple(c[f"susp_deflection_m_{i}"][k] for i in range(1, 5)) if has_susp else None
        rate = tuple(c[f"susp_deflection_rate_mps_{i}"][k] for i in range(1, 5)) if has_susp else None
        if susp is not None and not all(math.isfinite(v) for v in susp + rate):
            susp = rate = None
        init = PredictorInitialState(
            t_ns=0, pos_g_m=(0.0, 0.0, 0.0),
            vel_g_mps=(c["vel_g_mps_e"][k], c["vel_g_mps_n"][k], c["vel_g_mps_u"][k]),
            euler_g_rad=(c["roll_g_rad"][k], c["pitch_g_rad"][k], c["yaw_g_rad"][k]),
            road_bank_rad=_fin(c["road_bank_rad"][k]), road_grade_rad=_fin(c["road_grade_rad"][k]),
            rate_b_radps=(c["rate_b_radps_x"][k], c["rate_b_radps_y"][k], c["rate_b_radps_z"][k]),
            wheel_speed_radps=tuple(c[f"wheel_speed_radps_{i}"][k] for i in range(1, 5)),
            susp_deflection_m=susp, susp_deflection_rate_mps=rate)
        x0, env, _ = pred.core_state(init)
        xs.append(x0)
        envs.append(env)
        us.append(Inputs(c["steer_wheel_angle_rad"][k], tuple(c[f"wheel_torque_nm_{i}"][k] for i in range(1, 5))))
    return RowStates(idx, xs, us, envs, meas, has_susp)


def _fin(v: float) -> float:
    return float(v) if math.isfinite(v) else 0.0


# ----------------------------------------------------------------------------- one row
class _RowModel:
    """Residual vector of one row for one model (vehicle + dynamics effects)."""

    def __init__(self, vehicle: Vehicle, effects: EffectSet):
        self.model = Model(vehicle, EffectSet(effects.dynamics), unsprung_dof=False)
        p = vehicle.params
        self.m = p.mass_kg
        self.inertia = (p.inertia_x_kgm2, p.inertia_y_kgm2, p.inertia_z_kgm2)
        self.iw = vehicle.tire.wheel_inertia_kgm2
        self.c_kappa = p.tracking_stiffness_n
        self.corners = vehicle.geometry.corner_xy_m()
        self.axles = [vehicle.axle(i) for i in range(4)]
        self._spring = [(a.spring_c1_npm, a.spring_c2_per_m, a.spring_c3_m, a.static_compression_m, a.damper_nspm,
                         a.unsprung_mass_kg * GRAVITY_MPS2) for a in self.axles]
        self.last_ws = [0.0] * 8
        self.last_slip_cols = None
        self._zw = self.model.wheel_centre_z_m
        tire = self.model.effects.tire
        self._tire = None if tire is None or tire.name == "linear_tire" else tire
        self._fz0 = self.model.static_load_n
        self._calpha = self.model.c_alpha

    def residual(self, x, u, env, meas, want_named: bool = False, want_slip: bool = False):
        """(r (14,) list, named quantities or None) at one row; ``meas`` a sequence of 22
        measured values (``RowStates.meas``)."""
        m = self.model
        raw: dict = {"_want_air": want_named}
        xd = m.f(x, u, env, raw)
        ax, ay, az = raw["_acc_b"]
        gx, gy, gz = raw["_g_b"]
        mass = self.m
        ix, iy, iz = self.inertia
        r = [mass * (meas[0] - (ax - gx)), mass * (meas[1] - (ay - gy)), mass * (meas[2] - (az - gz)),
             ix * (meas[3] - xd[9]), iy * (meas[4] - xd[10]), iz * (meas[5] - xd[11]),
             0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        vx, vy = x[6], x[7]
        wz = x[11]
        rec = raw["_rec"]
        if len(meas) > 14 and meas[14] == meas[14] and meas[18] == meas[18]:
            self._measured_loads(r, rec, raw["_normal_b"], meas)
        iw = self.iw
        ws = self.last_ws
        cos, sin, sqrt = math.cos, math.sin, math.sqrt
        nx, ny, nz = raw["_normal_b"]
        wx, wy = x[9], x[10]
        vz = x[8]
        zw = self._zw
        for i in range(4):
            rc = rec[i]
            tq, teff, delta, ri = rc[7], rc[8], rc[9], rc[10]
            r[6 + i] = iw * (meas[6 + i] - xd[12 + i])
            xi, yi = self.corners[i]
            # wheel-centre velocity along the wheel's heading in the road plane (as the core)
            cd, sd = cos(delta), sin(delta)
            hn = cd * nx + sd * ny
            lx, ly, lz = cd - hn * nx, sd - hn * ny, -hn * nz
            inv = 1.0 / sqrt(lx * lx + ly * ly + lz * lz)
            vwx = vx + wy * zw - wz * yi
            vwy = vy + wz * xi - wx * zw
            vwz = vz + wx * yi - wy * xi
            vl = (vwx * lx + vwy * ly + vwz * lz) * inv
            kq = (tq + teff - iw * meas[6 + i]) / (ri * self.c_kappa[i])
            if self._tire is not None:
                kq = self._slip_for_force(i, rc, kq * self.c_kappa[i], kq)
            r[10 + i] = vl * (1.0 + kq) - ri * meas[10 + i]
            ws[i] = vl
            ws[4 + i] = kq
        named = m._named(x, xd, raw, env) if want_named else None
        if want_slip:
            self.last_slip_cols = self._slip_columns(rec, raw["_normal_b"])
        return r, named

    def _measured_loads(self, r, rec, n_b, meas) -> None:
        """Normal loads from the measured deflections and rates (eq 14, as eq 20 and 23 use them)
        instead of the rigid-tire pose: the difference dF_z,i acts along the road normal n at the
        contact point r_c,i = r_w,i - h_w n, so r -= (n dF, r_c x n dF)."""
        nx, ny, nz = n_b
        zw = self.model.wheel_centre_z_m
        exp = math.exp
        for i in range(4):
            c1, c2, c3, sc, ds, mug = self._spring[i]
            hs = sc + meas[14 + i]
            fsp = c1 * exp(c2 * ((hs if hs < 10.0 else 10.0) - c3)) * hs
            if fsp + mug <= 0.0:
                fz = 0.0
            else:
                fz = fsp + ds * meas[18 + i] + mug
                if fz < 0.0:
                    fz = 0.0
            rc = rec[i]
            d = fz - rc[2]
            hw = rc[11]
            xi, yi = self.corners[i]
            rcx, rcy, rcz = xi - hw * nx, yi - hw * ny, zw - hw * nz
            fx, fy, fz_ = nx * d, ny * d, nz * d
            r[0] -= fx
            r[1] -= fy
            r[2] -= fz_
            r[3] -= rcy * fz_ - rcz * fy
            r[4] -= rcz * fx - rcx * fz_
            r[5] -= rcx * fy - rcy * fx

    def _slip_for_force(self, i: int, rc, fa_target: float, k0: float) -> float:
        """The slip ratio at which the model's tire law gives the longitudinal force the spin
        balance measured (Newton from the linear tire's value, at the corner's slip angle and
        load; combined slip lowers the longitudinal stiffness of a saturating tire)."""
        tf = self._tire.tire_forces
        fz, alp = rc[2], rc[4]
        ck, ca, fz0 = self.c_kappa[i], self._calpha[i], self._fz0[i]
        k = k0
        for _ in range(3):
            f0 = tf(fz, fz0, k, alp, ck, ca)[0]
            h = 1e-5
            df = (tf(fz, fz0, k + h, alp, ck, ca)[0] - f0) / h
            if not df > 0.05 * ck:
                break
            k = k + (fa_target - f0) / df
        return k

    def _slip_columns(self, rec, n_b) -> np.ndarray:
        """(14, 8): d(residual)/d(F_a,i) (columns 0-3) -- a longitudinal tire force along the
        wheel's heading in the road plane e_l at the contact point (force e_l, moment r_c x e_l,
        wheel spin -r_i) -- and d(residual)/d(F_b,i) (columns 4-7, along e_t = n x e_l, times the
        slip angle: the cornering-stiffness columns of the linear tire)."""
        nx, ny, nz = n_b
        zw = self.model.wheel_centre_z_m
        out = np.zeros((14, 8))
        for i in range(4):
            delta, ri, hw, alp = rec[i][9], rec[i][10], rec[i][11], rec[i][4]
            cd, sd = math.cos(delta), math.sin(delta)
            hn = cd * nx + sd * ny
            lx, ly, lz = cd - hn * nx, sd - hn * ny, -hn * nz
            inv = 1.0 / math.sqrt(lx * lx + ly * ly + lz * lz)
            lx, ly, lz = lx * inv, ly * inv, lz * inv
            tx, ty, tz = ny * lz - nz * ly, nz * lx - nx * lz, nx * ly - ny * lx
            xi, yi = self.corners[i]
            rcx, rcy, rcz = xi - hw * nx, yi - hw * ny, zw - hw * nz
            out[0, i], out[1, i], out[2, i] = -lx, -ly, -lz
            out[3, i] = -(rcy * lz - rcz * ly)
            out[4, i] = -(rcz * lx - rcx * lz)
            out[5, i] = -(rcx * ly - rcy * lx)
            out[6 + i, i] = ri
            k = 4 + i
            out[0, k], out[1, k], out[2, k] = -tx * alp, -ty * alp, -tz * alp
            out[3, k] = -(rcy * tz - rcz * ty) * alp
            out[4, k] = -(rcz * tx - rcx * tz) * alp
            out[5, k] = -(rcx * ty - rcy * tx) * alp
        return out


def effect_quantities(model: Model, named: dict, x, table_row: dict | None = None) -> dict:
    """Named quantities an effect's ``regressors`` needs at one row (``Model.regressor_quantities``
    plus the state's wheel speeds)."""
    q = dict(named)
    for i in range(4):
        q[f"wheel_speed_radps_{i + 1}"] = x[12 + i]
    q["vel_b_mps_x"], q["vel_b_mps_y"], q["vel_b_mps_z"] = x[6], x[7], x[8]
    for k, a in enumerate("xyz"):
        q[f"rate_b_radps_{a}"] = x[9 + k]
    if table_row:
        q.update(table_row)
    return model.regressor_quantities(q)


# ----------------------------------------------------------------------------- all rows
@dataclass
class EquationResiduals:
    """Residuals of eq 13 (module docstring) on the usable rows of a table.

    ``values`` (n, 14) in ``EQUATIONS`` order (NaN: not evaluated), ``t_s`` (n,), ``index`` rows
    of the table, ``sigma`` (14,) noise per equation, ``nuisance`` (n, 14, 6) (``NUISANCE_NAMES``)
    or None, ``quantities`` per row (named quantities for the effects' regressors)."""

    t_s: np.ndarray
    index: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    nuisance: np.ndarray | None
    quantities: list
    available: np.ndarray
    vehicle: Vehicle
    effects: EffectSet
    states: RowStates = field(repr=False, default=None)
    ws_parts: np.ndarray | None = field(repr=False, default=None)  # (n, 8): v_l,i and kappa_q,i
    meas: np.ndarray | None = field(repr=False, default=None)  # (n, 22) measured side used
    lateral_unit: np.ndarray | None = field(repr=False, default=None)  # (n, 14, 4) d r / d C_alpha,i (linear tire)

    def rms(self) -> dict[str, float]:
        """RMS per equation over the rows (available equations only)."""
        out = {}
        for k, e in enumerate(EQUATIONS):
            if self.available[k]:
                v = self.values[:, k]
                v = v[np.isfinite(v)]
                out[e] = float(np.sqrt(np.mean(v * v))) if len(v) else math.nan
        return out

    def column(self, eq: str) -> np.ndarray:
        return self.values[:, _EQ[eq]]


def compute_residuals(table: DriveTable, vehicle: Vehicle, effects: EffectSet | Sequence = (), *,
                      states: RowStates | None = None, with_nuisance: bool = True,
                      with_quantities: bool = True) -> EquationResiduals:
    """The residuals of every equation (module docstring) for a model = model vehicle (with its
    identified parameters) + effects (dynamics effects act in the core; measurement effects are
    taken out of the measured specific force)."""
    effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
    st = states if states is not None else row_states(table, vehicle)
    rm = _RowModel(vehicle, effects)
    n = len(st.index)
    vals = np.full((n, 14), np.nan)
    nuis = np.zeros((n, 14, 6)) if with_nuisance else None
    lat = np.zeros((n, 14, 4)) if with_nuisance else None
    quants = []
    meas = st.meas.copy()
    meas = _remove_measurement_effects(table, st, effects, meas)
    ws = np.zeros((n, 8))
    meas_rows = meas.tolist()
    for j in range(n):
        x, u, env = st.x[j], st.u[j], st.env[j]
        r, named = rm.residual(x, u, env, meas_rows[j], want_named=with_quantities, want_slip=with_nuisance)
        vals[j] = r
        ws[j] = rm.last_ws
        r = np.array(r)
        slip = rm.last_slip_cols if with_nuisance else None
        if with_quantities:
            quants.append(effect_quantities(rm.model, named, x))
        if with_nuisance:
            for c, (slot, h) in enumerate(((6, 0.02), (7, 0.02))):
                xp = list(x)
                xp[slot] += h
                nuis[j, :, c] = (np.array(rm.residual(xp, u, env, meas_rows[j])[0]) - r) / h
            nuis[j, :, 2:6] = slip[:, 0:4]
            lat[j] = slip[:, 4:8]
    avail = np.ones(14, bool)
    if not st.has_susp:
        avail[2:5] = False  # vert, roll, pitch need the suspension forces (eq 14)
        vals[:, 2:5] = np.nan
    bad = ~np.all(np.isfinite(vals[:, avail]), axis=1)
    vals[bad] = np.nan
    sigma = _noise_sigma(vals, table.period_s) if with_nuisance else np.full(14, np.nan)
    return EquationResiduals(table.t_s[st.index], st.index, vals, sigma, nuis, quants, avail, vehicle, effects, st,
                             ws, meas, lat)


def parameter_columns(res: EquationResiduals, param: str, table: DriveTable | None = None) -> np.ndarray:
    """d(model side)/d(parameter) = -d r/d p on every row, (n, 14), for one of the ten identified
    parameters. Mass and inertias enter eq 13 linearly (r_long = m f - F, r_roll = I_x wd_x -
    (I_y - I_z) q r - M_x, ...); the slip stiffness C_kappa,i enters the wheel-speed row through
    kappa_q = (...)/(r C_kappa) (the dynamic rows see it only along the slip nuisance); the
    cornering stiffnesses by central differences of the model."""
    n = len(res.t_s)
    out = np.zeros((n, 14))
    meas = res.meas
    st = res.states
    if param == "mass_kg":
        out[:, 0:3] = -meas[:, 0:3]
        return out
    if param.startswith("inertia_"):
        ax = "xyz".index(param[8])
        w = np.array([x[9:12] for x in st.x]) if n else np.zeros((0, 3))
        p_, q_, r_ = w[:, 0], w[:, 1], w[:, 2]
        # d r_roll/d(Ix, Iy, Iz) = (wd_x, -q r, q r); pitch: (r p, wd_y, -r p); yaw: (-p q, p q, wd_z)
        d = {0: (meas[:, 3], r_ * p_, -p_ * q_), 1: (-q_ * r_, meas[:, 4], p_ * q_), 2: (q_ * r_, -r_ * p_, meas[:, 5])}[ax]
        for k in range(3):
            out[:, 3 + k] = -d[k]
        return out
    if param.startswith("tracking_stiffness_"):
        i = int(param.split("_")[2]) - 1
        c = getattr(res.vehicle.params, param)
        out[:, 10 + i] = res.ws_parts[:, i] * res.ws_parts[:, 4 + i] / c
        return out
    eff = res.effects
    linear = (eff.tire is None or eff.tire.name == "linear_tire") and not any(
        e.HOOKS and ("cornering_stiffness_factor" in e.HOOKS or "compliance_steer" in e.HOOKS) for e in eff.dynamics)
    if linear and res.lateral_unit is not None and param.startswith("cornering_stiffness_"):
        # F_b,i = C_alpha,axle / 2 alpha_i (eq 17): d r / d C_axle = sum over the axle's tires
        wheels = (0, 1) if param.endswith("front_nprad") else (2, 3)
        return -0.5 * (res.lateral_unit[:, :, wheels[0]] + res.lateral_unit[:, :, wheels[1]])
    v = getattr(res.vehicle.params, param)
    h = 1e-3 * abs(v)
    tab = table
    r_hi = compute_residuals(tab, res.vehicle.with_params(**{param: v + h}), res.effects, states=st,
                             with_nuisance=False, with_quantities=False)
    return np.nan_to_num((res.values - r_hi.values) / h)


def _remove_measurement_effects(table: DriveTable, st: RowStates, effects: EffectSet, meas: np.ndarray) -> np.ndarray:
    """Specific force with the model's measurement effects taken out (first order)."""
    ms = [e for e in effects.measurement]
    if not ms:
        return meas
    c = table.columns
    out = meas.copy()
    for j, k in enumerate(st.index):
        kin = _kin(c, k)
        fields = {f"specific_force_mps2_{a}": meas[j, q] for q, a in enumerate("xyz")}
        for e in ms:
            app = e.apply(fields, kin)
            for q, a in enumerate("xyz"):
                out[j, q] -= app[f"specific_force_mps2_{a}"] - fields[f"specific_force_mps2_{a}"]
    return out


def _kin(c, k) -> ImuKinematics:
    return ImuKinematics(0.0, tuple(c[f"specific_force_b_mps2_{a}"][k] for a in "xyz"),
                         tuple(c[f"rate_b_radps_{a}"][k] for a in "xyz"),
                         tuple(c[f"angular_accel_b_radps2_{a}"][k] for a in "xyz"))


def _noise_sigma(vals: np.ndarray, period_s: float, f_hp_hz: float = 3.0, f_c_hz: float = 10.0) -> np.ndarray:
    """Robust spread of each residual above f_hp, scaled to the band up to f_c (module docstring)."""
    out = np.full(vals.shape[1], np.nan)
    if period_s <= 0 or vals.shape[0] < 30:
        return out
    b, a = butter(2, f_hp_hz * 2.0 * period_s, btype="highpass")
    for k in range(vals.shape[1]):
        v = vals[:, k]
        ok = np.isfinite(v)
        if ok.sum() < 30:
            continue
        hp = filtfilt(b, a, v[ok])
        s = 1.4826 * float(np.median(np.abs(hp - np.median(hp))))
        out[k] = s * math.sqrt(f_c_hz / max(f_c_hz - f_hp_hz, 1.0))
    return out


# ----------------------------------------------------------------------------- innovations
INNOVATION_CHANNELS = ("att_roll", "att_pitch", "att_yaw", "vel_e", "vel_n", "pos_e", "pos_n", "pos_u")
INNOVATION_UNITS = {"att_roll": "rad", "att_pitch": "rad", "att_yaw": "rad", "vel_e": "m/s", "vel_n": "m/s",
                    "pos_e": "m", "pos_n": "m", "pos_u": "m"}


@dataclass
class Innovations:
    """GNSS against the open-loop strapdown (module docstring): one row per GNSS value.

    ``t_s`` (m,), ``channel`` (m,) index into ``INNOVATION_CHANNELS``, ``values`` (m,),
    ``sigma`` (m,), ``nuisance`` (m, 9) columns for the initial attitude (3, rotation about the
    ENU axes), velocity (3) and position (3)."""

    t_s: np.ndarray
    channel: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    nuisance: np.ndarray
    _ctx: dict = field(repr=False, default_factory=dict)

    def __len__(self) -> int:
        return len(self.t_s)

    def effect_columns(self, effect: MeasurementEffect, params: Sequence[str]) -> np.ndarray:
        """(m, len(params)): the innovations theta leaves when it is in the readings, per unit of
        each parameter: e = z - h(f + theta d) ~ e_0 - theta dh/dtheta (finite differences of the
        strapdown with the field regressors d taken out of the readings)."""
        ctx = self._ctx
        if not len(self.t_s) or not params:
            return np.zeros((len(self.t_s), len(params)))
        c = ctx["table"].columns
        n = len(ctx["t"])
        base_f, base_w = ctx["f"], ctx["w"]
        dfs = [np.zeros((n, 3)) for _ in params]
        dws = [np.zeros((n, 3)) for _ in params]
        for k in range(n):
            reg = effect.regressors(_kin(c, ctx["rows"][k]))
            for q, a in enumerate("xyz"):
                rf = reg.get(f"specific_force_mps2_{a}", {})
                rw = reg.get(f"angular_rate_radps_{a}", {})
                for j, p in enumerate(params):
                    dfs[j][k, q] = rf.get(p, 0.0)
                    dws[j][k, q] = rw.get(p, 0.0)
        # step sizes: the effect's default magnitude (or 1e-3 of a unit)
        spec = effect.param_specs()
        steps = [abs(spec[p].default) if spec[p].default else 1e-3 for p in params]
        fb = np.stack([base_f] + [base_f - h * d for h, d in zip(steps, dfs)])
        wb = np.stack([base_w] + [base_w - h * d for h, d in zip(steps, dws)])
        traj = _strapdown(ctx["t"], fb, wb, ctx["c0"], ctx["v0"], ctx["p0"])
        h_all = _observe(traj, ctx)
        # e = z - h(f + theta d): an effect theta in the readings leaves e ~ -theta dh/dtheta
        return np.column_stack([(h_all[1 + j] - h_all[0]) / steps[j] for j in range(len(params))])


def _strapdown(t, f, w, c0, v0, p0):
    """Open-loop integration for a batch (B, n, 3) of readings: (C (B,n,3,3), v (B,n,3),
    p (B,n,3)). C0 (B,3,3) or (3,3)."""
    b, n = f.shape[0], f.shape[1]
    C = np.empty((b, n, 3, 3))
    v = np.empty((b, n, 3))
    p = np.empty((b, n, 3))
    c = np.broadcast_to(c0, (b, 3, 3)).copy()
    vv = np.broadcast_to(v0, (b, 3)).copy()
    pp = np.broadcast_to(p0, (b, 3)).copy()
    g = np.array([0.0, 0.0, -GRAVITY_MPS2])
    C[:, 0], v[:, 0], p[:, 0] = c, vv, pp
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        wm = 0.5 * (w[:, k] + w[:, k + 1])
        fm = 0.5 * (f[:, k] + f[:, k + 1])
        # C_{k+1} = exp(-[w dt x]) C_k  (Rodrigues)
        th = wm * dt
        ang = np.linalg.norm(th, axis=1)
        s = np.where(ang > 1e-12, np.sin(ang) / np.maximum(ang, 1e-300), 1.0)
        cc = np.where(ang > 1e-12, (1.0 - np.cos(ang)) / np.maximum(ang * ang, 1e-300), 0.5)
        K = np.zeros((b, 3, 3))
        K[:, 0, 1], K[:, 0, 2] = -th[:, 2], th[:, 1]
        K[:, 1, 0], K[:, 1, 2] = th[:, 2], -th[:, 0]
        K[:, 2, 0], K[:, 2, 1] = -th[:, 1], th[:, 0]
        R = np.eye(3)[None] - s[:, None, None] * K + cc[:, None, None] * (K @ K)
        c_mid = c
        acc = np.einsum("bji,bj->bi", c_mid, fm) + g
        c = R @ c
        acc = 0.5 * (acc + np.einsum("bji,bj->bi", c, fm) + g)
        vn = vv + acc * dt
        pp = pp + 0.5 * (vv + vn) * dt
        vv = vn
        C[:, k + 1], v[:, k + 1], p[:, k + 1] = c, vv, pp
    return C, v, p


def _observe(traj, ctx) -> np.ndarray:
    """Predicted GNSS values (B, m) for the strapdown batch, in the order of the innovation rows."""
    C, v, p = traj
    b = C.shape[0]
    t = ctx["t"]
    rows = ctx["obs"]
    out = np.empty((b, len(rows)))
    lever = ctx["lever"]
    w = ctx["w"]
    for j, (ch, ts) in enumerate(rows):
        k = int(np.clip(np.searchsorted(t, ts) - 1, 0, len(t) - 2))
        a = (ts - t[k]) / (t[k + 1] - t[k])
        if ch < 3:
            e0 = _euler(C[:, k])
            e1 = _euler(C[:, k + 1])
            d = e1 - e0
            d[:, 2] = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
            out[:, j] = e0[:, ch] + a * d[:, ch]
        elif ch < 5:
            cm = C[:, k]
            va = v[:, k] * (1 - a) + v[:, k + 1] * a + np.einsum("bji,j->bi", cm, np.cross(w[k], lever))
            out[:, j] = va[:, ch - 3]
        else:
            cm = C[:, k]
            pa = p[:, k] * (1 - a) + p[:, k + 1] * a + np.einsum("bji,j->bi", cm, lever)
            out[:, j] = pa[:, ch - 5]
    return out


def _euler(c):
    """(phi, theta, psi) from C_g^v batches (B,3,3) (``frames.euler_ypr_from_dcm``)."""
    th = np.arcsin(np.clip(c[:, 0, 2], -1.0, 1.0))
    ph = np.arctan2(c[:, 1, 2], c[:, 2, 2])
    ps = np.arctan2(c[:, 0, 1], c[:, 0, 0])
    return np.stack([ph, th, ps], axis=1)


def _rot_about(axis: int, ang: float) -> np.ndarray:
    """Rotation of the ENU frame by ``ang`` about one of its axes, as C_g^v post-factor."""
    c, s = math.cos(ang), math.sin(ang)
    r = np.eye(3)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def compute_innovations(table: DriveTable, gnss_speed_sigma_mps: float = 0.1,
                        min_course_speed_mps: float = 3.0) -> Innovations:
    """GNSS against the open-loop strapdown (module docstring)."""
    c = table.columns
    names = [f"specific_force_b_mps2_{a}" for a in "xyz"] + [f"rate_b_radps_{a}" for a in "xyz"] + list(
        ("roll_g_rad", "pitch_g_rad", "yaw_g_rad", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u",
         "pos_g_m_e", "pos_g_m_n", "pos_g_m_u"))
    ok = np.ones(len(table), bool)
    for n in names:
        ok &= np.isfinite(c[n])
    rows = np.flatnonzero(ok)
    empty = Innovations(np.zeros(0), np.zeros(0, int), np.zeros(0), np.zeros(0), np.zeros((0, 9)))
    if len(rows) < 20:
        return empty
    # one contiguous span (the longest run of usable rows)
    breaks = np.flatnonzero(np.diff(rows) > 1)
    starts = np.r_[0, breaks + 1]
    ends = np.r_[breaks, len(rows) - 1]
    j = int(np.argmax(ends - starts))
    rows = rows[starts[j]:ends[j] + 1]
    t = table.t_s[rows]
    f = np.column_stack([c[f"specific_force_b_mps2_{a}"][rows] for a in "xyz"])[None]
    w = np.column_stack([c[f"rate_b_radps_{a}"][rows] for a in "xyz"])[None]
    k0 = rows[0]
    c0 = dcm_gv_batch(np.array([c["roll_g_rad"][k0]]), np.array([c["pitch_g_rad"][k0]]),
                      np.array([c["yaw_g_rad"][k0]]))[0]
    v0 = np.array([c[f"vel_g_mps_{a}"][k0] for a in "enu"])
    p0 = np.array([c[f"pos_g_m_{a}"][k0] for a in "enu"])
    lever = np.asarray(table.vehicle.mounting.gnss_lever_arm_m, dtype=float)
    obs, vals, sig = [], [], []
    g = table.gnss
    lo, hi = t[0], t[-1]
    if "att" in g:
        a = g["att"]
        for ch, key in enumerate(("roll", "pitch", "yaw")):
            for ts, z, s in zip(a["t_s"], a[f"{key}_rad"], a[f"{key}_sigma_rad"]):
                if lo <= ts <= hi and math.isfinite(z):
                    obs.append((ch, ts))
                    vals.append(z)
                    sig.append(s if (math.isfinite(s) and s > 0) else math.radians(0.4))
    if "vel" in g:
        a = g["vel"]
        for ts, sp, co in zip(a["t_s"], a["speed_mps"], a["course_rad"]):
            if lo <= ts <= hi and math.isfinite(sp + co) and sp >= min_course_speed_mps:
                for ch, z in ((3, sp * math.cos(co)), (4, sp * math.sin(co))):
                    obs.append((ch, ts))
                    vals.append(z)
                    sig.append(gnss_speed_sigma_mps)
    if "pos" in g:
        a = g["pos"]
        for ts, e, nn, u, sh, sv in zip(a["t_s"], a["e_m"], a["n_m"], a["u_m"], a["sigma_h_m"], a["sigma_v_m"]):
            if lo <= ts <= hi and math.isfinite(e + nn + u):
                sh = sh if (math.isfinite(sh) and sh > 0) else 1.0
                sv = sv if (math.isfinite(sv) and sv > 0) else 3.0
                for ch, z, s in ((5, e, sh), (6, nn, sh), (7, u, sv)):
                    obs.append((ch, ts))
                    vals.append(z)
                    sig.append(s)
    if not obs:
        return empty
    ctx = {"t": t, "f": f[0], "w": w[0], "c0": c0, "v0": v0, "p0": p0, "lever": lever, "obs": obs, "rows": rows,
           "table": table}
    # nominal + initial-attitude perturbations (rotation of the ENU frame about E, N, U)
    h = 1e-3
    c0s = np.stack([c0] + [c0 @ _rot_about(ax, h).T for ax in range(3)])
    n = len(t)
    traj = _strapdown(t, np.repeat(f, 4, axis=0), np.repeat(w, 4, axis=0), c0s, np.repeat(v0[None], 4, 0),
                      np.repeat(p0[None], 4, 0))
    hh = _observe(traj, ctx)
    ch = np.array([o[0] for o in obs])
    ts = np.array([o[1] for o in obs])
    values = np.array(vals) - hh[0]
    att = ch < 3
    values[att & (ch == 2)] = (values[att & (ch == 2)] + np.pi) % (2 * np.pi) - np.pi
    nuis = np.zeros((len(obs), 9))
    for ax in range(3):
        d = hh[1 + ax] - hh[0]
        d[ch == 2] = (d[ch == 2] + np.pi) % (2 * np.pi) - np.pi
        nuis[:, ax] = d / h
    dt = ts - t[0]
    for q in range(3):
        nuis[:, 3 + q] = np.where(ch == 3 + q, 1.0, 0.0) + np.where(ch == 5 + q, dt, 0.0)
        nuis[:, 6 + q] = np.where(ch == 5 + q, 1.0, 0.0)
    del n
    return Innovations(ts, ch, values, np.array(sig), nuis, ctx)


# ----------------------------------------------------------------------------- simulation error
@dataclass
class SimErrors:
    """Input-driven prediction errors against the estimate: per start (``t0_s``) and horizon
    (``HORIZONS_S``): ``position_m`` (CG position error), ``yaw_deg``, ``roll_deg``,
    ``speed_mps`` (each (n_starts, n_horizons), NaN where the prediction or the drive ended)."""

    t0_s: np.ndarray
    horizons_s: tuple
    position_m: np.ndarray
    yaw_deg: np.ndarray
    roll_deg: np.ndarray
    speed_mps: np.ndarray

    def summary(self, mask: np.ndarray | None = None) -> dict[str, dict[str, float]]:
        """RMS over the starts (optionally a subset) per horizon: {"0.5": {...}, ...}."""
        sel = np.ones(len(self.t0_s), bool) if mask is None else np.asarray(mask, bool)
        out = {}
        for j, h in enumerate(self.horizons_s):
            d = {}
            for name in ("position_m", "yaw_deg", "roll_deg", "speed_mps"):
                a = getattr(self, name)[sel, j]
                a = a[np.isfinite(a)]
                d[name] = float(np.sqrt(np.mean(a * a))) if len(a) else math.nan
            out[f"{h:g}"] = d
        return out


def simulation_errors(table: DriveTable, vehicle: Vehicle, effects: EffectSet | Sequence = (), *,
                      every_s: float = 0.5, horizons_s: Sequence[float] = HORIZONS_S,
                      starts_s: Sequence[float] | None = None, step_s: float = 0.01,
                      vehicle_at=None, effects_at=None) -> SimErrors:
    """Input-driven predictions from the estimate (module docstring).

    ``vehicle_at(t0_s)`` / ``effects_at(t0_s)``: optional callables giving the model to use for
    a prediction starting at t0 (the workbench passes parameters fitted only on data before t0)."""
    effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
    c = table.columns
    hmax = max(horizons_s)
    t = table.t_s
    if starts_s is None:
        starts_s = np.arange(t[0], t[-1] - hmax + 1e-9, every_s)
    starts = np.asarray(starts_s, dtype=float)
    nh = len(horizons_s)
    out = {k: np.full((len(starts), nh), np.nan) for k in ("position_m", "yaw_deg", "roll_deg", "speed_mps")}
    cfg = PredictorConfig(horizon_s=hmax, step_s=step_s, stop_at_point_of_no_return=False)
    cache: dict = {}
    need = ["steer_wheel_angle_rad", *[f"wheel_torque_nm_{i}" for i in range(1, 5)]]
    speed = np.hypot(c["vel_g_mps_e"], c["vel_g_mps_n"])
    for s_i, t0 in enumerate(starts):
        k0 = int(np.searchsorted(t, t0 - 1e-9))
        if k0 >= len(t) or speed[k0] < MIN_SPEED_MPS:
            continue
        init = _initial_state(table, k0)
        if init is None:
            continue
        k1 = int(np.searchsorted(t, t[k0] + hmax + 1e-9))
        sl = slice(k0, min(k1 + 1, len(t)))
        inp = np.column_stack([c[n][sl] for n in need])
        if not np.all(np.isfinite(inp)):
            continue
        traj = InputTrajectory(t[sl] - t[k0], inp[:, 0], inp[:, 1:5])
        veh = vehicle_at(t[k0]) if vehicle_at else vehicle
        eff = effects_at(t[k0]) if effects_at else effects
        key = (id(veh), id(eff))
        if key not in cache:
            cache.clear()
            cache[key] = Predictor(veh, cfg, EffectSet(EffectSet(eff).dynamics))
        res = cache[key].predict(init, traj)
        for j, h in enumerate(horizons_s):
            kt = int(np.searchsorted(t, t[k0] + h - 1e-9))
            ip = int(round(h / step_s))
            if kt >= len(t) or ip >= len(res.t_s):
                continue
            pe = res.pos_g_m[ip]
            pt = np.array([c["pos_g_m_e"][kt], c["pos_g_m_n"][kt], c["pos_g_m_u"][kt]])
            out["position_m"][s_i, j] = float(np.linalg.norm(pe - pt))
            yaw_t = c["yaw_g_rad"][kt]
            out["yaw_deg"][s_i, j] = math.degrees(_wrap(res.euler_g_rad[ip, 2] - yaw_t))
            out["roll_deg"][s_i, j] = math.degrees(res.euler_g_rad[ip, 0] - c["roll_g_rad"][kt])
            out["speed_mps"][s_i, j] = float(np.linalg.norm(res.vel_b_mps[ip])) - float(speed[kt])
    return SimErrors(starts, tuple(horizons_s), **out)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _initial_state(table: DriveTable, k: int) -> PredictorInitialState | None:
    c = table.columns
    try:
        susp = tuple(c[f"susp_deflection_m_{i}"][k] for i in range(1, 5))
        rate = tuple(c[f"susp_deflection_rate_mps_{i}"][k] for i in range(1, 5))
        if not all(math.isfinite(v) for v in susp):
            susp = rate = None
        elif not all(math.isfinite(v) for v in rate):
            rate = None
        return PredictorInitialState(
            t_ns=table.t0_ns + int(round(table.t_s[k] * 1e9)),
            pos_g_m=(c["pos_g_m_e"][k], c["pos_g_m_n"][k], c["pos_g_m_u"][k]),
            vel_g_mps=(c["vel_g_mps_e"][k], c["vel_g_mps_n"][k], c["vel_g_mps_u"][k]),
            euler_g_rad=(c["roll_g_rad"][k], c["pitch_g_rad"][k], c["yaw_g_rad"][k]),
            road_bank_rad=_fin(c["road_bank_rad"][k]), road_grade_rad=_fin(c["road_grade_rad"][k]),
            rate_b_radps=tuple(c[f"rate_b_radps_{a}"][k] for a in "xyz"),
            wheel_speed_radps=tuple(c[f"wheel_speed_radps_{i}"][k] for i in range(1, 5)),
            susp_deflection_m=susp, susp_deflection_rate_mps=rate)
    except ValueError:
        return None
