"""``experiments.yaw_budget``: the I_z budget of eq 23's yaw row on synthetic rows whose yaw
moment is known (a front-axle force balancing I_z wd_z exactly; no steer, no roll or pitch rate,
no acceleration: the unsprung and cross terms vanish)."""

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


def _drive(slip_error_per_accel=0.0, n=400, dt_s=0.01):
    """(truth, inputs): wd_z = 1.5 sin(2 pi t) rad/s^2 and the front slip angle whose eq 15 force
    gives M_z = I_z wd_z (both front wheels at x = l_f, rear slip 0); the estimated front slip is
    the truth's plus ``slip_error_per_accel`` x wd_z."""
    veh = load_vehicle("sedan-model")
    l_f = veh.geometry.l_f_m
    truth, inputs = [], []
    for k in range(n):
        t_ns = int(round(k * dt_s * 1e9))
        wdz = 1.5 * math.sin(2 * math.pi * k * dt_s)
        al_f = IZ_TRUE_KGM2 * wdz / (l_f * C_F_NPRAD)  # 2 wheels x C_f/2 x alpha x l_f
        al_true = (al_f, al_f, 0.0, 0.0)
        snap = {"t_ns": t_ns, "angular_accel_b_radps2_z": wdz}
        for i in range(4):
            snap[f"tire_force_long_n_{i + 1}"] = 0.0
            snap[f"tire_force_lat_n_{i + 1}"] = (C_F_NPRAD if i < 2 else C_R_NPRAD) / 2.0 * al_true[i]
            snap[f"slip_angle_rad_{i + 1}"] = al_true[i]
            snap[f"road_wheel_angle_rad_{i + 1}"] = 0.0
        truth.append(snap)
        e = slip_error_per_accel * wdz
        inputs.append(IdentInputs(
            t_ns=t_ns, xdd_a_mps2=0.0, ydd_a_mps2=0.0, zdd_a_mps2=9.80665, xd_a_mps=20.0, yd_a_mps=0.0,
            psi_v_dot_radps=0.0, gravity_aux_mps2=(0.0, 0.0, -9.80665), omega_radps=(0.0, 0.0, 0.0),
            omega_dot_radps2=(0.0, 0.0, wdz), susp_deflection_m=(0.0,) * 4, susp_rate_mps=(0.0,) * 4,
            wheel_speed_radps=(64.5,) * 4, wheel_accel_radps2=(0.0,) * 4, wheel_torque_nm=(0.0,) * 4,
            slip_ratio=(0.0,) * 4, slip_angle_rad=(al_f + e, al_f + e, 0.0, 0.0), wheel_angle_rad=(0.0,) * 4))
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
    """C_alpha,f 10 % high: every moment is the front's, so I_z comes out 10 % high, all of it in
    the front law share, and dI_z/dC_alpha,f = 1 % per % (the rear carries no force)."""
    veh, truth, inputs = _drive()
    b = yaw_budget(truth, inputs, veh, _params(veh, c_f=1.1 * C_F_NPRAD), load_ident_config())
    assert b["iz_model"] == pytest.approx(1.1 * IZ_TRUE_KGM2, rel=1e-9)
    assert b["shares"]["law_front"] == pytest.approx(0.1 * IZ_TRUE_KGM2, rel=1e-9)
    assert abs(b["shares"]["slip_front"]) < 1e-6 and abs(b["other"]) < 1e-6
    assert b["sensitivity"]["front"] == pytest.approx(1.0, rel=1e-9)
    assert abs(b["sensitivity"]["rear"]) < 1e-12


def test_slip_error_in_phase_with_the_yaw_acceleration_is_the_slip_share():
    """alpha_est = alpha_true + e wd_z at the front: M_z gains l_f C_alpha,f e wd_z, so I_z by
    l_f C_alpha,f e, all of it in the front slip share."""
    e = 2e-4  # rad per rad/s^2
    veh, truth, inputs = _drive(slip_error_per_accel=e)
    b = yaw_budget(truth, inputs, veh, _params(veh), load_ident_config())
    expected = veh.geometry.l_f_m * C_F_NPRAD * e
    assert b["shares"]["slip_front"] == pytest.approx(expected, rel=1e-9)
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
