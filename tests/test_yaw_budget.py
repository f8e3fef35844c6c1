"""``experiments.yaw_budget``: the I_z budget of eq 23's yaw row on synthetic rows whose yaw
moment is known (eq 15 forces on rigid wheel kinematics balancing I_z wd_z exactly; no steer, no
roll or pitch rate, no acceleration in the inputs: the unsprung and cross terms vanish)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from vdps_hil.experiments.yaw_budget import yaw_budget
from vdps_hil.identification.config import load_ident_config
from vdps_hil.identification.inputs import IdentInputs
from vdps_hil.model.params import load_vehicle

IZ_TRUE_KGM2 = 2700.0
C_F_NPRAD, C_R_NPRAD = 120000.0, 170000.0


def _drive(slip_error_per_accel=0.0, n=400, dt_s=0.01, truth_extra_per_rate=0.0):
    """(truth, inputs): a rigid-kinematics drive at 20 m/s with yaw rate r = 0.2 sin(2 pi t) rad/s
    and v = l_r r (the rear slip zero), no steer; the truth's slip angles are the wheels' rigid
    kinematics, its forces eq 15's (C_alpha,axle / 2 alpha), and its wd_z = M_z / I_z, so eq 23's
    yaw balance holds exactly. The estimated front slip is the truth's plus
    ``slip_error_per_accel`` x wd_z. ``truth_extra_per_rate``: the truth's front slip has this
    x r beyond the kinematics (as CommonRoad's axle roll rate term), the estimate has not."""
    veh = load_vehicle("sedan-model")
    xy = np.array(veh.geometry.corner_xy_m())
    c_b = np.array([C_F_NPRAD, C_F_NPRAD, C_R_NPRAD, C_R_NPRAD]) / 2.0
    u = 20.0
    truth, inputs = [], []
    for k in range(n):
        t_ns = int(round(k * dt_s * 1e9))
        r = 0.2 * math.sin(2 * math.pi * k * dt_s)
        v = veh.geometry.l_r_m * r
        al_kin = -np.arctan2(v + xy[:, 0] * r, u - xy[:, 1] * r)
        al_true = al_kin + np.array([1.0, 1.0, 0.0, 0.0]) * truth_extra_per_rate * r
        f_b = c_b * al_true
        wdz = float(np.sum(xy[:, 0] * f_b)) / IZ_TRUE_KGM2
        snap = {"t_ns": t_ns, "angular_accel_b_radps2_z": wdz, "vel_b_mps_x": u, "vel_b_mps_y": v,
                "rate_b_radps_z": r, "rate_b_radps_x": 0.0}
        for i in range(4):
            snap[f"tire_force_long_n_{i + 1}"] = 0.0
            snap[f"tire_force_lat_n_{i + 1}"] = float(f_b[i])
            snap[f"slip_angle_rad_{i + 1}"] = float(al_true[i])
            snap[f"road_wheel_angle_rad_{i + 1}"] = 0.0
        truth.append(snap)
        e = slip_error_per_accel * wdz
        al_est = (al_kin[0] + e, al_kin[1] + e, al_kin[2], al_kin[3])
        inputs.append(IdentInputs(
            t_ns=t_ns, xdd_a_mps2=0.0, ydd_a_mps2=0.0, zdd_a_mps2=9.80665, xd_a_mps=u, yd_a_mps=0.0,
            psi_v_dot_radps=0.0, gravity_aux_mps2=(0.0, 0.0, -9.80665), omega_radps=(0.0, 0.0, 0.0),
            omega_dot_radps2=(0.0, 0.0, wdz), susp_deflection_m=(0.0,) * 4, susp_rate_mps=(0.0,) * 4,
            wheel_speed_radps=(64.5,) * 4, wheel_accel_radps2=(0.0,) * 4, wheel_torque_nm=(0.0,) * 4,
            slip_ratio=(0.0,) * 4, slip_angle_rad=al_est, wheel_angle_rad=(0.0,) * 4))
    return veh, truth, inputs


def _params(veh, c_f=C_F_NPRAD, c_r=C_R_NPRAD):
    return dataclasses.replace(veh.params, cornering_stiffness_front_nprad=c_f, cornering_stiffness_rear_nprad=c_r,
                               inertia_x_kgm2=550.0, inertia_y_kgm2=2400.0)


def test_exact_model_gives_the_truth_and_no_shares():
    veh, truth, inputs = _drive()
    b = yaw_budget(truth, inputs, veh, _params(veh), load_ident_config())
    assert b["iz_truth_forces"] == pytest.approx(IZ_TRUE_KGM2, rel=1e-9)
    assert b["iz_model"] == pytest.approx(IZ_TRUE_KGM2, rel=1e-9)
    assert b["iz_model_est_accel"] == pytest.approx(IZ_TRUE_KGM2, rel=1e-9)
    assert all(abs(v) < 1e-6 for v in b["shares"].values()) and abs(b["other"]) < 1e-6


def test_gate_leaves_out_rows_below_the_excitation():
    veh, truth, inputs = _drive()
    b = yaw_budget(truth, inputs, veh, _params(veh), load_ident_config())
    wdz = np.array([i.omega_dot_radps2[2] for i in inputs])
    assert b["rows"] == int(np.count_nonzero(np.abs(wdz) >= 0.05))


def test_stiffness_error_is_the_tire_law_share_and_the_sensitivity():
    """C_alpha,f 10 % high: the front's moment M_f grows 10 %, so I_z by 0.1 x its projection
    (the law share), and dI_z/dC_alpha,f is that projection over I_z (the rear carries no force)."""
    veh, truth, inputs = _drive()
    b0 = yaw_budget(truth, inputs, veh, _params(veh), load_ident_config())
    b = yaw_budget(truth, inputs, veh, _params(veh, c_f=1.1 * C_F_NPRAD), load_ident_config())
    m_f = b0["sensitivity"]["front"] * b0["iz_model"]  # projection of the front moment on wd_z
    assert m_f == pytest.approx(IZ_TRUE_KGM2, rel=1e-9)  # the rear slip is zero: all of M_z is the front's
    assert b["iz_model"] == pytest.approx(1.1 * IZ_TRUE_KGM2, rel=1e-9)
    assert b["shares"]["law_front"] == pytest.approx(0.1 * IZ_TRUE_KGM2, rel=1e-9)
    assert abs(b["shares"]["slip_est_front"]) < 1e-6 and abs(b["other"]) < 1e-6
    assert abs(b0["sensitivity"]["rear"]) < 1e-12


def test_slip_error_in_phase_with_the_yaw_acceleration_is_the_slip_share():
    """alpha_est = alpha_true + e wd_z at the front: M_z gains l_f C_alpha,f e wd_z, so I_z by
    l_f C_alpha,f e, all of it the estimate's share (the truth's slip is rigid kinematics)."""
    e = 2e-4  # rad per rad/s^2
    veh, truth, inputs = _drive(slip_error_per_accel=e)
    b = yaw_budget(truth, inputs, veh, _params(veh), load_ident_config())
    expected = veh.geometry.l_f_m * C_F_NPRAD * e
    assert b["shares"]["slip_est_front"] == pytest.approx(expected, rel=1e-9)
    assert abs(b["shares"]["slip_kin_front"]) < 1e-6
    assert b["iz_model"] - b["iz_truth_forces"] == pytest.approx(expected, rel=1e-9)
    assert abs(b["shares"]["law_front"]) < 1e-6


def test_truth_is_interpolated_between_snapshots():
    """Inputs halfway between 10 ms snapshots of a linear ramp of wd_z: the interpolated truth
    equals the estimate, so the fit against either is the same."""
    veh, truth, inputs = _drive(n=200)
    ramp = [dict(s, angular_accel_b_radps2_z=0.5 + s["t_ns"] / 1e9) for s in truth]
    mid = [dataclasses.replace(i, t_ns=i.t_ns + 5_000_000,
                               omega_dot_radps2=(0.0, 0.0, 0.5 + (i.t_ns + 5_000_000) / 1e9)) for i in inputs[:-1]]
    b = yaw_budget(ramp, mid, veh, _params(veh), load_ident_config())
    assert b["rows"] == len(mid)
    assert b["iz_model"] == pytest.approx(b["iz_model_est_accel"], rel=1e-12)


def test_truth_slip_beyond_the_kinematics_is_the_kinematic_share():
    """The truth's front slip has k r more than the rigid kinematics the estimate follows: the
    whole I_z difference is the front's kinematic share, none the estimate's or the law's."""
    veh, truth, inputs = _drive(truth_extra_per_rate=0.01)
    b = yaw_budget(truth, inputs, veh, _params(veh), load_ident_config())
    s = b["shares"]
    assert abs(s["slip_est_front"]) < 1e-6 and abs(s["law_front"]) < 1e-6
    assert abs(s["slip_kin_front"]) > 1.0
    assert b["iz_model"] - b["iz_truth_forces"] == pytest.approx(s["slip_kin_front"], rel=1e-9)
