"""Where the inertia problem's I_z gets its error: the budget of eq 23's yaw row on a drive with
truth (issue 17; TRUTH: studies only, ``tools/yaw_budget.py`` runs it).

Eq 23's third row with I_x, I_y at the identified values::

    I_z wd_z = M_z + (I_x - I_y) w_x w_y = b_z,    M_z = sum_i (x_i F_y,i - y_i F_x,i) + M_z,u

(``identification.forces``: F_x,i = F_a,i cos d_i - F_b,i sin d_i, F_y,i = F_a,i sin d_i +
F_b,i cos d_i, eq 15 F_a = C_lambda lambda, F_b = C_alpha,axle / 2 alpha; M_z,u the unsprung
masses' term.) Over the rows the inertia problem uses (speed and excitation gates of
``configs/identification/default.toml`` ``[inertia]``), each b_z is fitted against the truth's
yaw acceleration by least squares, I_z = sum wd_z b_z / sum wd_z^2:

* ``iz_truth_forces``: b_z with the truth's tire forces and wheel angles (the model's moment
  law with the truth's forces: equals the truth figure when eq 23's yaw balance holds);
* ``iz_model``: the identifier's b_z (``forces.moments_from_inputs``: estimated slip angles and
  slip ratios, the identified stiffnesses); ``iz_model_est_accel`` the same against the
  estimated wd_z (what the RLS sees, unweighted);
* ``shares``: iz_model - iz_truth_forces split into the least-squares projections of its
  parts on wd_z (kg m^2; their sum plus ``other`` is the difference): per axle the lateral
  force's slip error C_alpha / 2 (alpha_est - alpha_true) at the truth's lever, in two parts,
  **slip_est** (alpha_est - alpha_kin: the estimation, alpha_kin = delta - atan2(v + x_i r +
  c_r p (h_cg - r_w), u - y_i r) the model's wheel kinematics, ``forces.slip_angles_rad``, with
  the truth's velocity, yaw and roll rates and wheel angle) and **slip_kin** (alpha_kin -
  alpha_true: what the truth's slip angle has beyond the model's wheel kinematics, e.g.
  CommonRoad's axle roll rate), and its
  **law** error (C_alpha / 2 alpha_true - F_b,true: what a linear tire cannot follow), and the
  **longitudinal** forces' error (C_lambda lambda - F_a,true at the truth's lever, the track
  width's y_i F_x,i among it);
* ``sensitivity``: dI_z / dC_alpha,f and dI_z / dC_alpha,r as % of I_z per % of C_alpha: the
  eq 15 moments' projection on wd_z (what a stiffness error moves I_z by).

Truth snapshots are linearly interpolated to each input's time (the chain's estimates fall
between the 100 Hz snapshots). Keys of a snapshot: ``sim.simulator``'s docstring.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.identification.forces import moments_from_inputs, slip_angles_rad

__all__ = ["yaw_budget"]

_WHEELS = (1, 2, 3, 4)


def _truth_series(truth) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    keys = ["angular_accel_b_radps2_z", "vel_b_mps_x", "vel_b_mps_y", "rate_b_radps_z", "rate_b_radps_x"] + [f"{k}_{i}" for k in ("tire_force_long_n", "tire_force_lat_n",
                                                                 "slip_angle_rad", "road_wheel_angle_rad")
                                           for i in _WHEELS]
    t = np.array([s["t_ns"] for s in truth], dtype=float)
    return t, {k: np.array([s[k] for s in truth], dtype=float) for k in keys}


def _rows(truth, inputs, vehicle, params, config, t_end_s: float) -> list[dict]:
    """Per used input: the estimated and truth quantities of the yaw row (module docstring)."""
    t_tr, tr = _truth_series(truth)
    gate = config.inertia.excitation_min[2]
    rows = []
    for inp in inputs:
        t = float(inp.t_ns)
        if t / 1e9 > t_end_s or not (t_tr[0] <= t <= t_tr[-1]) or abs(inp.xd_a_mps) < config.min_speed_mps:
            continue
        wx, wy, _ = inp.omega_radps
        dz = inp.omega_dot_radps2[2]
        if not (math.isfinite(dz) and math.isfinite(wx * wy)) or max(abs(dz), abs(wx * wy)) < gate:
            continue
        at = {k: float(np.interp(t, t_tr, v)) for k, v in tr.items()}
        al = slip_angles_rad(vehicle, inp)
        if not np.all(np.isfinite(al)):
            continue
        b_z = moments_from_inputs(vehicle, params, inp, config.moment_form)[2] + (
            params.inertia_x_kgm2 - params.inertia_y_kgm2) * wx * wy
        rows.append({"inp": inp, "al": al, "b_z": float(b_z), "dz_true": at["angular_accel_b_radps2_z"],
                     "fa": np.array([at[f"tire_force_long_n_{i}"] for i in _WHEELS]),
                     "fb": np.array([at[f"tire_force_lat_n_{i}"] for i in _WHEELS]),
                     "al_true": np.array([at[f"slip_angle_rad_{i}"] for i in _WHEELS]),
                     "v_true": (at["vel_b_mps_x"], at["vel_b_mps_y"], at["rate_b_radps_z"], at["rate_b_radps_x"]),
                     "d_true": np.array([at[f"road_wheel_angle_rad_{i}"] for i in _WHEELS])})
    return rows


def _parts(row, vehicle, params) -> dict[str, float]:
    """The yaw moment's error parts of one row [N m] and its truth-force moment (module docstring)."""
    xy = np.array(vehicle.geometry.corner_xy_m())
    inp, d = row["inp"], row["d_true"]
    lat = xy[:, 0] * np.cos(d) + xy[:, 1] * np.sin(d)  # M_z per unit F_b,i
    lon = xy[:, 0] * np.sin(d) - xy[:, 1] * np.cos(d)  # M_z per unit F_a,i
    c_b = np.array([params.cornering_stiffness_front_nprad] * 2 + [params.cornering_stiffness_rear_nprad] * 2) / 2.0
    u, v, r, p = row["v_true"]
    roll = vehicle.chassis.wheel_roll_coupling * p * (vehicle.geometry.h_cg_m - vehicle.tire.rolling_radius_m)
    al_kin = d - np.arctan2(v + xy[:, 0] * r + roll, u - xy[:, 1] * r)  # the model's wheel kinematics, truth motion
    slip_est, slip_kin = lat * c_b * (row["al"] - al_kin), lat * c_b * (al_kin - row["al_true"])
    law = lat * (c_b * row["al_true"] - row["fb"])
    f_a = np.array(params.tracking_stiffness_n) * np.asarray(inp.slip_ratio, dtype=float)
    de = np.asarray(inp.wheel_angle_rad, dtype=float)  # the model's own levers: its b_z less its tire moment
    lat_e, lon_e = xy[:, 0] * np.cos(de) + xy[:, 1] * np.sin(de), xy[:, 0] * np.sin(de) - xy[:, 1] * np.cos(de)
    model_no_tires = row["b_z"] - float(np.sum(lat_e * c_b * row["al"] + lon_e * f_a))
    return {"slip_est_front": slip_est[0] + slip_est[1], "slip_est_rear": slip_est[2] + slip_est[3],
            "slip_kin_front": slip_kin[0] + slip_kin[1], "slip_kin_rear": slip_kin[2] + slip_kin[3],
            "law_front": law[0] + law[1],
            "law_rear": law[2] + law[3], "longitudinal": float(np.sum(lon * (f_a - row["fa"]))),
            "b_z_truth_forces": model_no_tires + float(np.sum(lat * row["fb"] + lon * row["fa"])),
            "dm_dcf_nm": float(np.sum((lat * row["al"])[:2])) / 2.0,
            "dm_dcr_nm": float(np.sum((lat * row["al"])[2:])) / 2.0}


def yaw_budget(truth, inputs, vehicle, params, config, t_end_s: float = math.inf) -> dict:
    """The I_z budget of one drive (module docstring): ``truth`` the snapshots, ``inputs`` the
    identifier's ``IdentInputs``, ``vehicle`` the *model* file, ``params`` the identified values
    (those at ``t_end_s``), ``config`` the ``IdentConfig``. Returns rows, the three I_z fits
    [kg m^2], ``shares`` [kg m^2], ``other`` [kg m^2] and ``sensitivity`` [% per %]."""
    rows = _rows(truth, inputs, vehicle, params, config, t_end_s)
    if not rows:
        return {"rows": 0}
    parts = [_parts(r, vehicle, params) for r in rows]
    dz = np.array([r["dz_true"] for r in rows])
    dz_est = np.array([r["inp"].omega_dot_radps2[2] for r in rows])
    fit = lambda y, x=dz: float(np.dot(x, y) / np.dot(x, x))  # noqa: E731
    col = lambda k: np.array([p[k] for p in parts])  # noqa: E731
    b_z = np.array([r["b_z"] for r in rows])
    iz_truth, iz_model = fit(col("b_z_truth_forces")), fit(b_z)
    shares = {k: fit(col(k)) for k in ("slip_est_front", "slip_est_rear", "slip_kin_front", "slip_kin_rear",
                                       "law_front", "law_rear", "longitudinal")}
    sens = {"front": fit(col("dm_dcf_nm")) * params.cornering_stiffness_front_nprad / iz_model,
            "rear": fit(col("dm_dcr_nm")) * params.cornering_stiffness_rear_nprad / iz_model}
    return {"rows": len(rows), "iz_truth_forces": iz_truth, "iz_model": iz_model,
            "iz_model_est_accel": fit(b_z, dz_est), "shares": shares,
            "other": iz_model - iz_truth - sum(shares.values()), "sensitivity": sens}
