"""Residuals of eq 13: consistent with the physics core (an effect's regressors are the change
of the residual it causes), nuisance directions, parameter columns, noise per equation."""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.experiments.workbench_study import cached_drive
from vdps_hil.model.effects import EffectSet, make_effect
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import residuals as R
from vdps_hil.workbench.dataset import load_drive

VEH = load_vehicle("sedan-model")
TRUE = VEH.with_params(**load_vehicle("sedan-truth").params.as_dict())  # tests only: a correct model


@pytest.fixture(scope="module")
def drive(drive_cache):
    path = cached_drive(drive_cache, "step-steer", (), seed=5)
    tab = load_drive(path, VEH)
    st = R.row_states(tab, TRUE)
    res = R.compute_residuals(tab, TRUE, EffectSet(), states=st)
    return tab, st, res


def _contribution(tab, st, res, effect):
    with_e = R.compute_residuals(tab, TRUE, EffectSet([effect]), states=st, with_nuisance=False,
                                 with_quantities=False)
    return res.values - with_e.values


@pytest.mark.parametrize("name, params, rel", [
    ("aero_drag", {"cda_m2": 0.7}, 1e-6),
    ("rolling_resistance", {"coefficient": 0.012}, 0.02),
    ("low_pressure_tire", {"wheel": 3.0, "radius_reduction": 0.015}, 0.02),
    ("steering_compliance", {"compliance_radpn": 2e-7}, 0.05),
    ("load_dependent_cornering_stiffness", {"load_slope": 0.3, "load_degression": 0.2}, 0.1),
])
def test_regressors_are_the_residual_change_the_effect_causes(drive, name, params, rel):
    """r(model) - r(model + effect) = sum_p regressor_p theta_p on every equation the regressor
    names (the sign convention the ranking relies on). Tolerances: exact for drag, first order
    for the others (rolling resistance saturates at standstill, compliance and the load law are
    linearised)."""
    tab, st, res = drive
    eff = make_effect(name, **params)
    contrib = _contribution(tab, st, res, eff)
    pred = np.zeros_like(contrib)
    for j, q in enumerate(res.quantities):
        for eq, d in eff.regressors(q).items():
            k = R.EQUATIONS.index(eq)
            pred[j, k] += sum(v * eff.params[p] for p, v in d.items())
    eqs = [R.EQUATIONS.index(eq) for eq in eff.regressors(res.quantities[len(res.quantities) // 2])]
    # stacked over the equations the regressor names, each in units of its noise
    a, b = pred[:, eqs] / res.sigma[eqs], contrib[:, eqs] / res.sigma[eqs]
    assert np.linalg.norm(b) > 0
    assert np.linalg.norm(a - b) <= rel * np.linalg.norm(b), np.linalg.norm(a - b) / np.linalg.norm(b)


def test_measurement_effect_moves_the_force_balance_by_m_times_the_bias(drive):
    tab, st, res = drive
    eff = make_effect("imu_bias", accel_bias_x_mps2=0.05, accel_bias_y_mps2=-0.03, accel_bias_z_mps2=0.0)
    contrib = _contribution(tab, st, res, eff)
    m = TRUE.params.mass_kg
    assert np.allclose(contrib[:, 0], m * 0.05, rtol=1e-9)
    assert np.allclose(contrib[:, 1], -m * 0.03, rtol=1e-9)
    assert np.allclose(contrib[:, 3:], 0.0)


def test_a_steering_offset_moves_lateral_and_yaw_by_the_front_axle_force_it_adds(drive):
    """The model steers by the reading less the offset: r(model) - r(model + offset) is the front
    axle's lateral force change C_f offset / i_s on the lateral balance and l_f times it on the yaw
    balance (linear tire, small angles: within 2 %), and on the longitudinal and vertical balance
    only its projections through the road-wheel angle and the body's roll (within 5 % of it;
    measured 2.6 % and 2.3 % at most on this step steer)."""
    tab, st, res = drive
    off = 0.03
    contrib = _contribution(tab, st, res, make_effect("steering_offset", offset_rad=off))
    g = TRUE.geometry
    dfy = -TRUE.params.cornering_stiffness_front_nprad * off / g.steer_ratio
    lat, yaw = R.EQUATIONS.index("lat"), R.EQUATIONS.index("yaw")
    assert np.linalg.norm(contrib[:, lat] - dfy) <= 0.02 * abs(dfy) * np.sqrt(len(contrib))
    assert np.linalg.norm(contrib[:, yaw] - g.l_f_m * dfy) <= 0.02 * abs(g.l_f_m * dfy) * np.sqrt(len(contrib))
    others = [R.EQUATIONS.index(e) for e in ("long", "vert")]
    assert np.all(np.abs(contrib[:, others]) <= 0.05 * abs(dfy))
    # the same offset in the opposite direction undoes it exactly (an offset, not a gain)
    back = _contribution(tab, st, res, make_effect("steering_offset", offset_rad=-off))
    assert np.allclose(back[:, [lat, yaw]], -contrib[:, [lat, yaw]], rtol=0.02, atol=1e-9 * abs(dfy))


def test_residual_with_the_true_parameters_is_small_after_the_nuisance(drive):
    """Whitened residual with the estimator-error directions projected out: noise level (the
    truth simulator has unsprung masses and tire compliance the reduced model lacks, so not 1)."""
    tab, st, res = drive
    av = res.available & np.isfinite(res.sigma)
    y = res.values[:, av] / res.sigma[av]
    j = res.nuisance[:, av, :] / res.sigma[av][None, :, None]
    out = []
    for k in range(len(y)):
        q, rr = np.linalg.qr(j[k])
        out.append(y[k] - q @ (q.T @ y[k]))
    rms = np.sqrt(np.mean(np.square(out), axis=0))
    raw = np.sqrt(np.mean(np.square(y), axis=0))
    assert np.all(rms < 4.0), rms
    assert np.median(raw / rms) > 3.0  # the nuisance explains most of the raw residual


def test_parameter_columns_match_finite_differences(drive):
    tab, st, res = drive
    for p in ("mass_kg", "inertia_z_kgm2", "cornering_stiffness_front_nprad", "tracking_stiffness_2_n"):
        a = R.parameter_columns(res, p, tab)
        v = getattr(TRUE.params, p)
        h = 1e-4 * v
        r1 = R.compute_residuals(tab, TRUE.with_params(**{p: v + h}), EffectSet(), states=st,
                                 with_nuisance=False, with_quantities=False)
        fd = np.nan_to_num((res.values - r1.values) / h)
        if p.startswith("tracking_stiffness"):
            # the analytic column is the wheel-speed row; the rest of the change lies along the
            # row-wise longitudinal tire-force nuisance (the slip stiffness only scales F_a)
            ws = slice(10, 14)
            err = np.linalg.norm(a[:, ws] - fd[:, ws]) / np.linalg.norm(fd[:, ws])
            rest = fd.copy()
            rest[:, ws] = 0.0
            jn = res.nuisance[:, :, 2:]
            left = [rest[k] - jn[k] @ np.linalg.lstsq(jn[k], rest[k], rcond=None)[0] for k in range(len(rest))]
            assert np.linalg.norm(left) < 0.03 * np.linalg.norm(rest)
        else:
            err = np.linalg.norm(a - fd) / max(np.linalg.norm(fd), 1e-12)
        if p.startswith("cornering_stiffness"):
            # equation by equation: a whole-matrix norm let the lateral row, right, hide roll and
            # yaw rows 3-4 % off (the unsprung masses' arm left out; CommonRoad set 1, 2026-12-07)
            for k in range(a.shape[1]):
                scale = max(np.linalg.norm(fd[:, k]), 1e-9 * np.linalg.norm(fd))
                assert np.linalg.norm(a[:, k] - fd[:, k]) < 0.01 * scale, (p, R.EQUATIONS[k])
        assert err < 0.03, (p, err)


def test_noise_sigma_is_the_sensor_noise(drive):
    _, _, res = drive
    s = dict(zip(R.EQUATIONS, res.sigma))
    m = TRUE.params.mass_kg
    assert 0.5 * m * 0.002 < s["long"] < 3.0 * m * 0.004  # IMU 0.02 m/s^2 at 1 kHz through 10 Hz
    assert 0.0 < s["wheel_speed_1"] < 0.01


def test_without_wheel_torques_only_the_equations_that_need_them_are_dropped(drive):
    """A partial sensor set (the RAV4: no wheel torques): the same rows stay usable, the
    longitudinal, wheel-spin and wheel-speed rows are not evaluated, the lateral and yaw
    balances still are (and unchanged where the torques do not enter: a step steer at
    constant speed has small drive torques), and the slip nuisance is off."""
    import dataclasses

    tab, st, res = drive
    cols = dict(tab.columns)
    for i in range(1, 5):
        cols[f"wheel_torque_nm_{i}"] = np.full(len(tab), np.nan)
    part = dataclasses.replace(tab, columns=cols)
    st2 = R.row_states(part, TRUE)
    assert not st2.has_torque and len(st2.index) == len(st.index)
    r2 = R.compute_residuals(part, TRUE, EffectSet(), states=st2)
    names = list(R.EQUATIONS)
    gone = ["long", *[f"wheel_{i}" for i in range(1, 5)], *[f"wheel_speed_{i}" for i in range(1, 5)]]
    for eq in gone:
        assert not r2.available[names.index(eq)]
    for eq in ("lat", "yaw"):
        k = names.index(eq)
        assert r2.available[k] and np.isfinite(r2.values[:, k]).mean() > 0.9
    assert np.all(r2.nuisance[:, :, 2:6] == 0.0)


def test_all_rows_compiled_equal_the_per_row_path_with_their_quantities(drive):
    """``compute_residuals`` on the compiled rows (``row_kernel``) gives the per-row reference's
    values, nuisance, slip columns, wheel-speed parts, noise and named quantities bit for bit, on
    the drive and with the Magic Formula tire and aero drag; the quantities are made when first
    read."""
    tab, st, _ = drive
    effects = EffectSet([make_effect("magic_formula_tire"), make_effect("aero_drag", cda_m2=0.7)])
    a = R.compute_residuals(tab, TRUE, effects, states=st, compiled=False)
    b = R.compute_residuals(tab, TRUE, effects, states=st)
    assert type(b.quantities).__name__ == "LazyRowQuantities" and b.quantities._q is None
    for x, y in ((a.values, b.values), (a.nuisance, b.nuisance), (a.lateral_unit, b.lateral_unit),
                 (a.ws_parts, b.ws_parts), (a.sigma, b.sigma)):
        assert np.array_equal(x, y, equal_nan=True)
    assert len(b.quantities) == len(a.quantities) == len(st.index) > 100
    assert list(b.quantities) == list(a.quantities)
