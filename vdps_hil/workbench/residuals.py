"""Model against measurement: the residual of every equation of eq 13 on the usable rows of a
drive table (the innovations: ``innovations``; the simulation error: ``simulation_errors``).

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
time within the estimator's own sigma (``ranking.context``), so an effect is judged only on what the
estimator's errors cannot explain.

Noise per equation (``sigma``): the robust spread of the residual above 3 Hz, scaled to the
table's bandwidth (the residual of an unmodelled effect is slow; the sensor noise is not).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from scipy.signal import butter, filtfilt

from vdps_hil.model.core import Inputs, Model
from vdps_hil.model.core_kernel import N_DIAG
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import EQUATIONS as DYNAMIC_EQUATIONS
from vdps_hil.model.effects.base import ImuKinematics
from vdps_hil.model.effects.steering import steer_corrected, steering_effects
from vdps_hil.model.params import Vehicle
from vdps_hil.prediction.predictor import Predictor, PredictorConfig, PredictorInitialState

from .dataset import DriveTable
from .row_kernel import NUISANCE_STEP_MPS, residual_rows
from .row_model import LazyRowQuantities, RowModel, RowQuantities

__all__ = ["EQUATIONS", "DYNAMIC_EQUATIONS", "KINEMATIC_EQUATIONS", "EQUATION_LABELS", "EQUATION_UNITS",
           "EquationResiduals", "compute_residuals", "RowStates", "row_states", "parameter_columns",
           "MIN_SPEED_MPS", "effect_quantities", "usable_rows", "TORQUE_COLUMNS", "imu_kinematics", "finite_or_zero"]

KINEMATIC_EQUATIONS: tuple[str, ...] = tuple(f"wheel_speed_{i}" for i in range(1, 5))
EQUATIONS: tuple[str, ...] = tuple(DYNAMIC_EQUATIONS) + KINEMATIC_EQUATIONS
EQUATION_LABELS = {"long": "longitudinal force", "lat": "lateral force", "vert": "vertical force",
                   "roll": "roll moment", "pitch": "pitch moment", "yaw": "yaw moment",
                   **{f"wheel_{i}": f"wheel {i} spin" for i in range(1, 5)},
                   **{f"wheel_speed_{i}": f"wheel {i} speed" for i in range(1, 5)}}
EQUATION_UNITS = {"long": "N", "lat": "N", "vert": "N", "roll": "N m", "pitch": "N m", "yaw": "N m",
                  **{f"wheel_{i}": "N m" for i in range(1, 5)}, **{f"wheel_speed_{i}": "m/s" for i in range(1, 5)}}
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
    has_torque: bool = True

    def arrays(self, keep: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(X (n, 16), U (n, 9), ENV (n, 6)) of ``row_kernel.residual_rows``: the states, the
        inputs (steering wheel angle, drive and brake torques) and the road normal with the wind;
        kept for the next call when ``keep`` (the ranking evaluates the same rows many times)."""
        a = self.__dict__.get("_arrays")
        if a is None and not keep:
            return self._make_arrays()
        if a is None:
            a = self.__dict__["_arrays"] = self._make_arrays()
        return a

    def _make_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = len(self.x)
        X = np.array(self.x, dtype=float).reshape(n, -1)
        U = np.array([(u.steer_wheel_angle_rad, *u.wheel_torque_nm, *u.brake_torque_nm) for u in self.u],
                     dtype=float).reshape(n, 9)
        E = np.array([(*e.normal_g, *e.wind_enu_mps) for e in self.env], dtype=float).reshape(n, 6)
        return X, U, E


def row_states(table: DriveTable, vehicle: Vehicle) -> RowStates:
    """The reduced model's state at every usable row (``Predictor.core_state``: pose and heave
    from the suspension when it is measured, eq 5)."""
    pred = Predictor(vehicle, PredictorConfig(horizon_s=0.02, step_s=0.01))
    c = table.columns
    has_torque = table.has(*TORQUE_COLUMNS)
    ok = usable_rows(table)
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
            road_bank_rad=finite_or_zero(c["road_bank_rad"][k]), road_grade_rad=finite_or_zero(c["road_grade_rad"][k]),
            rate_b_radps=(c["rate_b_radps_x"][k], c["rate_b_radps_y"][k], c["rate_b_radps_z"][k]),
            wheel_speed_radps=tuple(c[f"wheel_speed_radps_{i}"][k] for i in range(1, 5)),
            susp_deflection_m=susp, susp_deflection_rate_mps=rate)
        x0, env, _ = pred.core_state(init)
        xs.append(x0)
        envs.append(env)
        torque = tuple(c[f"wheel_torque_nm_{i}"][k] for i in range(1, 5)) if has_torque else (0.0,) * 4
        us.append(Inputs(c["steer_wheel_angle_rad"][k], torque))
    return RowStates(idx, xs, us, envs, meas, has_susp, has_torque=has_torque)


TORQUE_COLUMNS = tuple(f"wheel_torque_nm_{i}" for i in range(1, 5))
NEEDED_COLUMNS = ("specific_force_b_mps2_x", "specific_force_b_mps2_y", "specific_force_b_mps2_z",
                  "rate_b_radps_x", "rate_b_radps_y", "rate_b_radps_z", "steer_wheel_angle_rad",
                  *[f"wheel_speed_radps_{i}" for i in range(1, 5)], *TORQUE_COLUMNS,
                  *[f"vel_g_mps_{a}" for a in "enu"], "roll_g_rad", "pitch_g_rad", "yaw_g_rad")
"""Signals a usable row needs (the wheel torques only when the drive has them at all: without
them the equations that need them are not evaluated, ``compute_residuals``)."""
TORQUE_EQUATIONS = (0, *range(6, 14))
"""Equations (``EQUATIONS`` index) that need the wheel torques: long, wheel_i, wheel_speed_i."""


def usable_rows(table: DriveTable) -> np.ndarray:
    """Rows moving at >= ``MIN_SPEED_MPS`` with every needed signal finite (``NEEDED_COLUMNS``;
    the wheel torques only when the drive has them)."""
    c = table.columns
    has_torque = table.has(*TORQUE_COLUMNS)
    ok = np.ones(len(table), bool)
    for n in NEEDED_COLUMNS:
        if n in TORQUE_COLUMNS and not has_torque:
            continue
        ok &= np.isfinite(c[n]) if n in c else False
    return ok & (np.hypot(c["vel_g_mps_e"], c["vel_g_mps_n"]) >= MIN_SPEED_MPS)


def finite_or_zero(v: float) -> float:
    return float(v) if math.isfinite(v) else 0.0


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
    or None, ``quantities`` per row (named quantities for the effects' regressors; a
    :class:`~vdps_hil.workbench.row_model.RowQuantities`, a dict per row on access)."""

    t_s: np.ndarray
    index: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    nuisance: np.ndarray | None
    quantities: RowQuantities | LazyRowQuantities | list
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
                      with_quantities: bool = True, compiled: bool = True) -> EquationResiduals:
    """The residuals of every equation (module docstring) for a model = model vehicle (with its
    identified parameters) + effects (dynamics effects act in the core; measurement effects are
    taken out of the measured specific force). All rows in one compiled call when the model's
    core is compiled (``row_kernel``, bit for bit the per-row path); ``compiled=False`` takes
    the per-row path (``RowModel.residual``, the reference)."""
    effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
    st = states if states is not None else row_states(table, vehicle)
    st = _remove_steering_effects(st, effects)
    rm = RowModel(vehicle, effects)
    n = len(st.index)
    vals = np.full((n, 14), np.nan)
    nuis = np.zeros((n, 14, 6)) if with_nuisance else None
    lat = np.zeros((n, 14, 4)) if with_nuisance else None
    quants = RowQuantities()
    meas = st.meas.copy()
    meas = _remove_measurement_effects(table, st, effects, meas)
    ws = np.zeros((n, 8))
    packed = rm.packed() if compiled and n else None
    if packed is not None:
        meas = np.ascontiguousarray(meas)
        keep = states is not None  # rows the caller evaluates again (the ranking's)
        _compiled_rows(rm, packed, st, meas, vals, ws, nuis, lat, None, keep)
        if with_quantities:  # made when a candidate's regressors first read them
            quants = LazyRowQuantities(lambda: _compiled_quantities(rm, packed, st, meas, keep))
    else:
        _python_rows(rm, st, meas, vals, ws, nuis, lat, quants if with_quantities else None)
    avail = np.ones(14, bool)
    if not st.has_susp or table.sensors.get("imu_substituted"):
        # vert, roll, pitch need the suspension forces (eq 14), and f_z, p, q measured (an ESC
        # cluster's are substitutes: streams.ESC_SUBSTITUTES)
        avail[2:5] = False
        vals[:, 2:5] = np.nan
    if not st.has_torque:
        # no wheel torques: the longitudinal balance and the wheel rows are not evaluated, and the
        # longitudinal tire forces are not free per row (their only evidence, the spin balance, is gone)
        avail[list(TORQUE_EQUATIONS)] = False
        vals[:, list(TORQUE_EQUATIONS)] = np.nan
        if nuis is not None:
            nuis[:, :, 2:6] = 0.0
    bad = ~np.all(np.isfinite(vals[:, avail]), axis=1)
    vals[bad] = np.nan
    sigma = _noise_sigma(vals, table.period_s) if with_nuisance else np.full(14, np.nan)
    return EquationResiduals(table.t_s[st.index], st.index, vals, sigma, nuis, quants, avail, vehicle, effects, st,
                             ws, meas, lat)


def _python_rows(rm: RowModel, st: RowStates, meas, vals, ws, nuis, lat, quants) -> None:
    """The reference path: ``RowModel.residual`` row by row, twice more per row for the velocity
    nuisance (forward differences of ``row_kernel.NUISANCE_STEP_MPS``)."""
    meas_rows = meas.tolist()
    h = NUISANCE_STEP_MPS
    for j in range(len(st.index)):
        x, u, env = st.x[j], st.u[j], st.env[j]
        r, named = rm.residual(x, u, env, meas_rows[j], want_named=quants is not None, want_slip=nuis is not None)
        vals[j] = r
        ws[j] = rm.last_ws
        r = np.array(r)
        if quants is not None:
            quants.append(effect_quantities(rm.model, named, x))
        if nuis is not None:
            slip = rm.last_slip_cols
            for c, slot in enumerate((6, 7)):
                xp = list(x)
                xp[slot] += h
                nuis[j, :, c] = (np.array(rm.residual(xp, u, env, meas_rows[j])[0]) - r) / h
            nuis[j, :, 2:6] = slip[:, 0:4]
            lat[j] = slip[:, 4:8]


def _compiled_rows(rm: RowModel, packed: tuple, st: RowStates, meas: np.ndarray, vals, ws, nuis, lat, quants,
                   keep: bool, chunk: int = 4096) -> None:
    """All rows through ``row_kernel.residual_rows`` in chunks (its per-row outputs, the core's
    diagnostics among them, are held for one chunk at a time); the named quantities from the
    kernel's diagnostics (``Model.evaluate_from``, as the per-row path's ``Model._named``)."""
    X, U, ENV = st.arrays(keep)
    n = len(X)
    with_nuis = nuis is not None
    m = min(chunk, n)
    XD, DG = np.empty((m, X.shape[1])), np.empty((m, N_DIAG))
    NU, SL = (np.empty((m, 14, 2)), np.empty((m, 14, 8))) if with_nuis else (np.empty((0, 14, 2)), np.empty((0, 14, 8)))
    for j0 in range(0, n, chunk):
        j1 = min(n, j0 + chunk)
        k = j1 - j0
        residual_rows(X[j0:j1], U[j0:j1], ENV[j0:j1], meas[j0:j1], *packed, with_nuis, XD[:k], DG[:k], vals[j0:j1],
                      ws[j0:j1], NU[:k] if with_nuis else NU, SL[:k] if with_nuis else SL)
        if with_nuis:
            nuis[j0:j1, :, 0:2] = NU[:k]
            nuis[j0:j1, :, 2:6] = SL[:k, :, 0:4]
            lat[j0:j1] = SL[:k, :, 4:8]
        if quants is not None:
            xds = XD[:k].tolist()
            for i in range(k):
                x = st.x[j0 + i]
                named = rm.model.evaluate_from(x, xds[i], DG[i], st.env[j0 + i])[1]
                quants.append(effect_quantities(rm.model, named, x))


def _compiled_quantities(rm: RowModel, packed: tuple, st: RowStates, meas: np.ndarray, keep: bool) -> RowQuantities:
    """The named quantities of every row, made when first read: the kernel runs once more
    (without the nuisance) for its per-chunk diagnostics, which costs less than holding 99
    values a row until a candidate reads them."""
    n = len(st.index)
    q = RowQuantities()
    _compiled_rows(rm, packed, st, meas, np.empty((n, 14)), np.empty((n, 8)), None, None, q, keep)
    return q


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
        kin = imu_kinematics(c, k)
        fields = {f"specific_force_mps2_{a}": meas[j, q] for q, a in enumerate("xyz")}
        for e in ms:
            app = e.apply(fields, kin)
            for q, a in enumerate("xyz"):
                out[j, q] -= app[f"specific_force_mps2_{a}"] - fields[f"specific_force_mps2_{a}"]
    return out


def _remove_steering_effects(st: RowStates, effects: EffectSet) -> RowStates:
    """The rows' inputs with the model's steering-sensor effects (``steering_offset``) taken out
    of the steering wheel angle (``effects.steering.steer_corrected``); ``st`` itself when the
    model has none (its kept arrays stay)."""
    ms = steering_effects(effects.measurement)
    if not ms:
        return st
    us = [replace(u, steer_wheel_angle_rad=steer_corrected(u.steer_wheel_angle_rad, ms)) for u in st.u]
    return RowStates(st.index, st.x, us, st.env, st.meas, st.has_susp, st.has_torque)


def imu_kinematics(c, k) -> ImuKinematics:
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
