"""Tire effects: linear law (eq 15), Magic Formula (pure slip against the textbook formula,
saturation at peak friction, combined slip, load sensitivity), load-dependent cornering
stiffness, low-pressure tire."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.model.core import Inputs, Model
from vdps_hil.model.effects import (EffectConfigError, EffectSet, LinearTire, LoadDependentCorneringStiffness,
                                    LowPressureTire, MagicFormulaTire, make_effect)
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.simulator import Simulator

SEDAN = load_vehicle("sedan-truth")
MF = MagicFormulaTire(**SEDAN.effects["magic_formula_tire"])
FZ0, CK, CA = 4300.0, 80000.0, 60000.0


def textbook_mf(s, stiffness, c, e, d):
    """F = D sin(C atan(B s - E (B s - atan(B s)))), B = stiffness / (C D)."""
    b = stiffness / (c * d)
    return d * math.sin(c * math.atan(b * s - e * (b * s - math.atan(b * s))))


def test_linear_tire_is_eq15_and_zero_off_the_ground():
    t = LinearTire()
    assert t.tire_forces(4000.0, FZ0, 0.01, -0.02, CK, CA) == (CK * 0.01, CA * -0.02)
    assert t.tire_forces(0.0, FZ0, 0.01, -0.02, CK, CA) == (0.0, 0.0)


@pytest.mark.parametrize("fz", [1500.0, 4300.0, 7000.0])
def test_mf_pure_slip_equals_textbook_magic_formula(fz):
    mu = MF.peak_friction * (1 + MF.load_sensitivity * (fz / FZ0 - 1))
    for alpha in (-0.3, -0.05, 0.001, 0.02, 0.1, 0.5):
        fa, fb = MF.tire_forces(fz, FZ0, 0.0, alpha, CK, CA)
        assert fa == 0.0
        assert fb == pytest.approx(textbook_mf(alpha, CA, MF.shape_lateral, MF.curvature_lateral, mu * fz), rel=1e-12)
    for kappa in (-0.8, -0.05, 0.003, 0.1, 1.0):
        fa, fb = MF.tire_forces(fz, FZ0, kappa, 0.0, CK, CA)
        assert fa == pytest.approx(textbook_mf(kappa, CK, MF.shape_longitudinal, MF.curvature_longitudinal, mu * fz), rel=1e-12)


def test_mf_small_slip_equals_linear_tire():
    fa, fb = MF.tire_forces(FZ0, FZ0, 1e-5, 2e-5, CK, CA)
    assert fa == pytest.approx(CK * 1e-5, rel=1e-6) and fb == pytest.approx(CA * 2e-5, rel=1e-6)


@pytest.mark.parametrize("fz", [1000.0, 4300.0, 8000.0])
def test_mf_lateral_force_saturates_at_peak_friction(fz):
    """max over alpha of F_b equals mu(F_z) F_z within 0.1 %, and is never exceeded."""
    d = MF.peak_force(fz, FZ0)
    assert d == pytest.approx(MF.peak_friction * (1 + MF.load_sensitivity * (fz / FZ0 - 1)) * fz)
    fb = [MF.tire_forces(fz, FZ0, 0.0, a * 1e-4, CK, CA)[1] for a in range(0, 6000)]
    assert max(fb) == pytest.approx(d, rel=1e-3)
    assert max(fb) <= d * (1 + 1e-12)
    # beyond the peak it falls (sliding) but stays above sin(C pi/2) D
    assert fb[-1] < max(fb) and fb[-1] > 0.85 * d


@settings(max_examples=200, deadline=None)
@given(kappa=st.floats(-1.0, 1.0), alpha=st.floats(-0.7, 0.7), fz=st.floats(100.0, 10000.0))
def test_mf_combined_slip_stays_inside_friction_circle(kappa, alpha, fz):
    fa, fb = MF.tire_forces(fz, FZ0, kappa, alpha, CK, CA)
    assert math.hypot(fa, fb) <= MF.peak_force(fz, FZ0) * (1 + 1e-9)
    # forces oppose the slip velocity direction of eq 15 (same signs as the linear law)
    assert fa * kappa >= 0.0 and fb * alpha >= 0.0


def test_mf_combined_slip_reduces_lateral_force():
    _, fb_pure = MF.tire_forces(FZ0, FZ0, 0.0, 0.05, CK, CA)
    _, fb_comb = MF.tire_forces(FZ0, FZ0, 0.1, 0.05, CK, CA)
    assert fb_comb < 0.8 * fb_pure


def test_mf_rejects_bad_parameters():
    with pytest.raises(EffectConfigError, match="shape_lateral"):
        MagicFormulaTire(shape_lateral=0.5)
    with pytest.raises(EffectConfigError, match="unknown parameter"):
        MagicFormulaTire(peak=1.0)


def test_vehicle_lateral_force_saturates_with_magic_formula():
    """Ramp steer at 20 m/s on the sedan with MF tires: every tire's lateral force stays below
    mu(F_z) F_z, some tire reaches > 99 % of its friction limit, and the lateral
    acceleration tops out near mu g (0.8-1.0 g: load transfer and load sensitivity)."""
    sim = Simulator(SEDAN, inputs=lambda t, x: Inputs(0.25 * t, (150.0,) * 4), effects=EffectSet([MF]),
                    initial_speed_mps=20.0)
    sim.run(6.0)
    best = 0.0
    for s in sim.truth:
        for i in range(1, 5):
            fz = s[f"normal_load_n_{i}"]
            d = MF.peak_force(fz, sim.model.static_load_n[i - 1]) if fz > 0 else 0.0
            f = math.hypot(s[f"tire_force_long_n_{i}"], s[f"tire_force_lat_n_{i}"])
            assert f <= d * (1 + 1e-9) + 1e-9
            if d > 0:
                best = max(best, f / d)
    assert best > 0.99
    ay_max = max(abs(s["accel_b_mps2_y"]) for s in sim.truth)
    assert 0.75 * 9.81 < ay_max < 1.0 * 9.81


def test_load_dependent_stiffness_law_and_regressors():
    e = LoadDependentCorneringStiffness()
    assert e.cornering_stiffness_factor(0, FZ0, FZ0) == 1.0
    assert e.cornering_stiffness_factor(0, 0.0, FZ0) == pytest.approx(0.0, abs=1e-12)  # a - b = 1 - ... -> 0
    d = 0.5
    assert e.cornering_stiffness_factor(0, FZ0 * 1.5, FZ0) == pytest.approx(1 + 0.6 * d - 0.4 * d * d)
    # degressive: lateral load transfer +-dF lowers the axle sum
    assert e.cornering_stiffness_factor(0, 1.4 * FZ0, FZ0) + e.cornering_stiffness_factor(0, 0.6 * FZ0, FZ0) < 2.0
    # regressors reproduce the lateral force change
    q = {}
    for i, (fz, alpha, x) in enumerate([(5000, 0.02, 1.2), (3600, 0.02, 1.2), (4000, 0.015, -1.5), (3000, 0.015, -1.5)], start=1):
        q.update({f"normal_load_n_{i}": fz, f"static_load_n_{i}": FZ0, f"slip_angle_rad_{i}": alpha,
                  f"cornering_stiffness_nprad_{i}": CA, f"corner_x_m_{i}": x})
    r = e.regressors(q)
    dfy = sum(CA * q[f"slip_angle_rad_{i}"] * (e.cornering_stiffness_factor(0, q[f"normal_load_n_{i}"], FZ0) - 1)
              for i in range(1, 5))
    assert r["lat"]["load_slope"] * 0.6 + r["lat"]["load_degression"] * 0.4 == pytest.approx(dfy, rel=1e-12)


def test_load_sensitivity_lowers_steady_state_lateral_gain():
    """Quantitative vehicle check in a steady turn (about 3.5 m/s^2): every tire's lateral force
    equals C0 * factor(F_z) * alpha on the simulated state (1e-9 relative), and the yaw rate
    falls by more than 1 % (the front axle, with the stiffer springs, takes more of the lateral
    load transfer and loses more stiffness: more understeer)."""
    eff0 = EffectSet([LinearTire()])
    eff1 = EffectSet([LinearTire(), LoadDependentCorneringStiffness()])
    out = []
    for eff in (eff0, eff1):
        sim = Simulator(SEDAN, inputs=lambda t, x: Inputs(0.13, (120.0,) * 4), effects=eff,
                        initial_speed_mps=20.0, record_truth=False)
        sim.step_to(6.0)
        out.append(sim.snapshot())
    s0, s1 = out
    # with the law, each tire's lateral force = C0 alpha factor: check on the simulated state
    e = LoadDependentCorneringStiffness()
    m = Model(SEDAN)
    for i in range(1, 5):
        fz = s1[f"normal_load_n_{i}"]
        fac = e.cornering_stiffness_factor(i - 1, fz, m.static_load_n[i - 1])
        assert s1[f"tire_force_lat_n_{i}"] == pytest.approx(m.c_alpha[i - 1] * fac * s1[f"slip_angle_rad_{i}"], rel=1e-9)
    # and the car turns differently (front axle stiffness falls more: less yaw rate)
    assert s1["rate_b_radps_z"] < 0.99 * s0["rate_b_radps_z"]


def test_low_pressure_wheel_speed_ratio_equals_radius_ratio():
    """Straight free rolling at 25 m/s (rolling resistance on so every wheel carries the same
    small force): omega_low / omega_nominal = r_nom / r_low within 0.1 %."""
    lp = LowPressureTire(wheel=3, radius_reduction=0.015)
    sim = Simulator(SEDAN, inputs=Inputs(), effects=EffectSet([lp, make_effect("rolling_resistance")]),
                    initial_speed_mps=25.0, record_truth=False)
    sim.step_to(3.0)
    s = sim.snapshot()
    ratio = s["wheel_speed_radps_3"] / s["wheel_speed_radps_4"]
    assert ratio == pytest.approx(1.0 / (1.0 - 0.015), rel=1e-3)
    assert s["rolling_radius_m_3"] == pytest.approx(0.31 * 0.985)
    with pytest.raises(EffectConfigError):
        LowPressureTire(wheel=5)
    assert lp.regressors({"rolling_radius_nominal_m": 0.31, "wheel_speed_radps_3": 80.0}) == \
        {"wheel_speed_3": {"radius_reduction": -0.31 * 80.0}}


def test_two_tire_models_are_rejected():
    with pytest.raises(EffectConfigError, match="mutually exclusive"):
        EffectSet([LinearTire(), make_effect("magic_formula_tire")])
