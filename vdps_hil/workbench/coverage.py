"""What a drive can show: the signals it lacks and what that prevents, why rows are unusable, and
whether enough of it is usable to judge the slow effects.

* Missing signals (:func:`missing_signals`): a signal group absent over the whole drive switches
  off the equations that need it (``residuals.compute_residuals``: the suspension -> vert, roll,
  pitch; the wheel torques -> long, wheel_i, wheel_speed_i) and the effects judged there.
* Unusable rows (:func:`unusable_reason`): when fewer than ``MIN_ROWS`` rows are usable, the one
  line names the signal missing on most rows, or standstill.
* Too little drive (:func:`coverage_messages`): usable time below ``MIN_JUDGE_S`` (e.g. a brake
  test whose car stands still after 4 s) is said, with what the drive would need.
"""

from __future__ import annotations

import numpy as np

from vdps_hil.estimation.sensorsets import not_used_note

from .dataset import DriveTable
from .residuals import MIN_SPEED_MPS, NEEDED_COLUMNS, TORQUE_COLUMNS, usable_rows

__all__ = ["MIN_ROWS", "MIN_JUDGE_S", "EFFECT_NEEDS", "missing_signals", "unusable_reason", "coverage_messages"]

MIN_ROWS = 50
"""Fewer usable rows than this: no ranking (one-line error naming why)."""
MIN_JUDGE_S = 10.0
"""Less usable drive than this [s]: said as too short for the slow effects."""

_GROUPS = (
    ("wheel torques", TORQUE_COLUMNS,
     "the longitudinal balance and the wheel-spin and wheel-speed rows are not evaluated: aerodynamic drag, "
     "rolling resistance, an under-inflated tire and the slip stiffnesses cannot be judged; the input-driven "
     "simulation does not run"),
    ("suspension deflections", tuple(f"susp_deflection_m_{i}" for i in range(1, 5)),
     "the vertical, roll and pitch balances are not evaluated (no suspension forces, eq 14): the roll and "
     "pitch inertias are held at the model file's values"),
    ("wheel speeds", tuple(f"wheel_speed_radps_{i}" for i in range(1, 5)), "no row is usable (the model's state needs them)"),
    ("steering angle", ("steer_wheel_angle_rad",), "no row is usable (the model's input)"),
)

EFFECT_NEEDS = {
    "aero_drag": "speed varied over a wide range (a coast-down from >= 25 m/s) with the wheel torques recorded",
    "rolling_resistance": "a coast-down or steady driving with the wheel torques recorded",
    "magic_formula_tire": "lateral acceleration toward the tire limit (a circle ramped beyond 5 m/s^2)",
    "load_dependent_cornering_stiffness": "large load transfer while cornering (a circle or slalom beyond 4 m/s^2)",
    "low_pressure_tire": "steady rolling at speed with all four wheel speeds and the wheel torques",
    "crosswind": "sustained driving at speed, ideally in both directions",
    "steering_compliance": "cornering at several lateral accelerations",
    "imu_bias": "GNSS position and velocity over a drive with turns and speed changes",
    "imu_lever_arm": "yaw and roll accelerations (a slalom or lane change)",
    "steering_offset": "driving at speed with the steering angle recorded: 2 s straight and half a turn",
}
"""What a drive needs to excite each built-in effect (the ``not excited`` words)."""


def not_ranked_lines(not_ranked: dict[str, str]) -> list[str]:
    """One line per effect the ranking left out because the drive cannot tell it apart from others
    (``candidates.drive_candidates``: name -> why, in words)."""
    return [f"not ranked on this drive: {name} ({why}): vdps diagnose --add {name} fits it"
            for name, why in sorted(not_ranked.items())]


def missing_signals(table: DriveTable) -> list[str]:
    """One line per signal group the drive lacks entirely: what is missing and what it prevents."""
    out = []
    for label, cols, prevents in _GROUPS:
        if not table.has(*cols):
            out.append(f"missing signals: {label} ({', '.join(cols)}): {prevents}")
    sensors = table.sensors
    if sensors.get("imu_substituted"):
        out.append(f"missing signals: IMU axes ({', '.join(sensors['imu_substituted'])}; an ESC cluster): "
                   "substituted as the estimator does (f_z = g, roll and pitch rates 0); the vertical, roll "
                   "and pitch balances are not evaluated")
    unused = not_used_note(sensors.get("not_used"), sensors.get("kind_map"))
    if unused:  # a sensor in the recording its sensor set does not name (sensorsets.KindMap)
        out.append(unused)
    return out


def unusable_reason(table: DriveTable) -> str:
    """Why (almost) no row is usable, in one line."""
    c = table.columns
    n = len(table)
    moving = np.hypot(c["vel_g_mps_e"], c["vel_g_mps_n"]) >= MIN_SPEED_MPS if n else np.zeros(0, bool)
    lacking = []
    for name in NEEDED_COLUMNS:
        if name in TORQUE_COLUMNS and not table.has(*TORQUE_COLUMNS):
            continue
        fin = np.isfinite(c[name]) if name in c else np.zeros(n, bool)
        miss = int(np.sum(moving & ~fin))
        if miss:
            lacking.append((miss, name))
    head = (f"too few usable rows: {int(usable_rows(table).sum())} of {n}, at least {MIN_ROWS} needed (a row needs "
            f">= {MIN_SPEED_MPS:g} m/s and every model signal)")
    if not moving.any():
        return head + f": the car never moves faster than {MIN_SPEED_MPS:g} m/s on this drive"
    lacking.sort(reverse=True)
    if lacking:
        names = ", ".join(nm for _, nm in lacking[:4]) + (", ..." if len(lacking) > 4 else "")
        return head + f": missing on the moving rows: {names}"
    if moving.all():  # every row usable, and still too few: the drive itself is short
        return head + (f": the drive is too short, {n} rows of {table.period_s:g} s ({n * table.period_s:.1f} s) "
                       "after the estimator settled")
    return head + f": only {int(moving.sum())} rows are moving"


def coverage_messages(table: DriveTable, used_index: np.ndarray) -> list[str]:
    """The missing signals and, when the usable drive is short, that it is too short to judge."""
    out = missing_signals(table)
    dt = table.period_s
    usable_s = len(used_index) * dt
    if usable_s < MIN_JUDGE_S:
        out.append(f"too little drive to judge: only {usable_s:.1f} s of the {table.duration_s:.1f} s are usable "
                   f"(moving faster than {MIN_SPEED_MPS:g} m/s with every signal); slow effects (drag, rolling "
                   f"resistance, crosswind, a tire's radius) need >= {MIN_JUDGE_S:g} s of driving -- "
                   "a 'no missing effect' here means 'not judged'")
    return out
