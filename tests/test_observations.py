"""Observation models of eq 9: analytic Jacobians against central differences (tolerance
1e-6), each h at the truth of the synthetic manoeuvre reproduces the measurement built from
noise-free sensors (1e-9) (measurement covariances: ``test_measurements``)."""

import math

import numpy as np
import pytest

from vdps_hil.experiments import synthetic as syn
from vdps_hil.estimation.measurements import suspension_measurement, y2_gps_measurement
from vdps_hil.estimation.observations import ObsKind, make_models, rear_axle_ground_point, wheel_positions
from vdps_hil.estimation.states import N_EXT, AugStates
from vdps_hil.model.params import load_vehicle

VEH = load_vehicle("sedan-model")
GEO = VEH.geometry
LEVER = VEH.mounting.gnss_lever_arm_m


def _aux(kind, rng):
    if kind == ObsKind.GNSS_VEL:
        return rng.normal(size=3) * 0.3
    if kind == ObsKind.Y2_GPS:  # theta_v given (paper), or None: from eq 4 of the state
        return float(rng.normal() * 0.02) if rng.uniform() < 0.5 else None
    return None


@pytest.mark.parametrize("kind", list(ObsKind))
def test_jacobians_against_finite_differences(kind, rng):
    model = make_models(LEVER)[kind]
    for _ in range(20):
        x = rng.normal(size=12) * np.array([300, 300, 20, 25, 25, 2, .3, .3, 3, .1, .1, 3])
        aux = _aux(kind, rng)
        H = model.jacobian(x, aux)
        assert H.shape == (model.dim, 12)
        h = 1e-6
        num = np.empty_like(H)
        for i in range(12):
            d = np.zeros(12)
            d[i] = h
            num[:, i] = model.residual(model.h(x + d, aux), model.h(x - d, aux)) / (2 * h)
        np.testing.assert_allclose(H, num, atol=1e-6, rtol=1e-6)


def test_models_at_truth_match_noise_free_measurements():
    m = syn.Maneuver(duration_s=5.0)
    t = np.linspace(0.5, 5.0, 10)
    tr = syn.truth(m, t)
    models = make_models(LEVER)
    defl = syn.deflections(tr, GEO)
    for k in range(t.size):
        x = tr.x_full[k]
        sm = suspension_measurement(defl[k], GEO.l_f_m, GEO.l_r_m, GEO.track_half_front_m, GEO.track_half_rear_m, 1e-3)
        np.testing.assert_allclose(models[ObsKind.Y1_SUS].h(x), sm.y1, atol=1e-12)
        assert abs(sm.theta_v_rad - tr.vehicle_angles[k, 1]) < 1e-12
        assert abs(sm.phi_v_rad - tr.vehicle_angles[k, 0]) < 1e-12
        # y2^sus plane form: the CG height above the plane through the origin (plane offset 0)
        assert abs(models[ObsKind.Y2_SUS_PLANE].h(x)[0] - sm.z_r_m) < 1e-9
        assert abs(models[ObsKind.Y2_SUS_RATE].h(x)[0] - tr.heave_rate_mps[k]) < 1e-9
        z, _ = y2_gps_measurement(x[7], x[8], 0.01, 0.01)
        np.testing.assert_allclose(models[ObsKind.Y2_GPS].h(x, tr.vehicle_angles[k, 1]), z, atol=1e-12)
        # without aux, theta_v comes from eq 4 of the state: the same value here
        np.testing.assert_allclose(models[ObsKind.Y2_GPS].h(x, None), z, atol=1e-12)
        np.testing.assert_allclose(models[ObsKind.GNSS_ATT].h(x), x[6:9], atol=0)


def test_gnss_position_lever_arm_points_forward():
    """Heading north (psi = 90 deg) with the antenna 0.3 m ahead and 0.85 m above the CG: the
    antenna is 0.3 m north and 0.85 m up."""
    x = np.zeros(12)
    x[8] = math.pi / 2
    np.testing.assert_allclose(make_models(LEVER)[ObsKind.GNSS_POS].h(x), [0.0, 0.30, 0.85], atol=1e-12)


def test_gnss_velocity_speed_course():
    x = np.zeros(12)
    x[3:5] = (3.0, 4.0)
    y = make_models((0, 0, 0))[ObsKind.GNSS_VEL].h(x)
    np.testing.assert_allclose(y, [5.0, math.atan2(4, 3)], atol=1e-12)


def test_yaw_residual_wraps():
    model = make_models()[ObsKind.GNSS_ATT]
    r = model.residual(np.array([0.0, 0.0, math.pi - 0.01]), np.array([0.0, 0.0, -math.pi + 0.01]))
    assert abs(r[2] + 0.02) < 1e-12


# ---------------------------------------------------------------------------------------------
# real-car rows: wheel speed and the non-holonomic constraint
WHEELS = wheel_positions(GEO, VEH.tire.rolling_radius_m)


def _x_ext(rng):
    x = np.zeros(N_EXT)
    x[:12] = rng.normal(size=12) * np.array([300, 300, 20, 25, 25, 2, .3, .3, 3, .1, .1, 3])
    x[12:] = rng.normal(size=7) * 0.02
    return x


@pytest.mark.parametrize("kind", [ObsKind.WHEEL_SPEED, ObsKind.NHC])
def test_real_car_rows_jacobians_on_the_extended_vector(kind, rng):
    """Both rows with body rates, steering and uneven weights, on the N_EXT vector (the wheel
    speed depends on k_w): analytic Jacobian against central differences (1e-6)."""
    model = make_models(LEVER, WHEELS, rear_axle_ground_point(GEO))[kind]
    for _ in range(20):
        x = _x_ext(rng)
        w = tuple(rng.normal(size=3) * 0.3)
        aux = (w, (0.1, 0.08, 0.0, 0.0), (0.4, 0.1, 0.3, 0.2)) if kind == ObsKind.WHEEL_SPEED else w
        H = model.jacobian(x, aux)
        num = np.zeros_like(H)
        for i in range(H.shape[1]):
            d = np.zeros(N_EXT)
            d[i] = 1e-6
            num[:, i] = (model.h(x + d, aux) - model.h(x - d, aux)) / 2e-6
        np.testing.assert_allclose(H, num, atol=1e-6, rtol=1e-6)
        assert H.shape[1] == (N_EXT if kind == ObsKind.WHEEL_SPEED else 12)


def test_wheel_speed_and_nhc_physics():
    """Level car heading north-east at 20 m/s turning left at 0.3 rad/s: the left wheels roll
    slower than the right ones by w_z * track, their mean is the CG speed; a steered front pair
    sees cos(d) of it; k_w scales. The rear axle moves sideways by -w_z l_r (NHC) and not
    vertically."""
    models = make_models(LEVER, WHEELS, rear_axle_ground_point(GEO))
    ws, nhc = models[ObsKind.WHEEL_SPEED], models[ObsKind.NHC]
    psi, u, r = 0.8, 20.0, 0.3
    x = np.zeros(N_EXT)
    x[3:5] = u * math.cos(psi), u * math.sin(psi)
    x[8] = psi
    w = (0.0, 0.0, r)
    left = ws.h(x, (w, (0.0,) * 4, (0.0, 0.0, 0.0, 1.0)))[0]  # RL
    right = ws.h(x, (w, (0.0,) * 4, (0.0, 0.0, 1.0, 0.0)))[0]  # RR
    assert right - left == pytest.approx(r * 2 * GEO.track_half_rear_m, abs=1e-9)
    assert ws.h(x, (w, (0.0,) * 4, (0.25,) * 4))[0] == pytest.approx(u, abs=1e-9)
    assert ws.h(x)[0] == pytest.approx(u, abs=1e-9)
    d = 0.2  # steered front wheels, no yaw rate: the car's x velocity along each wheel's heading
    assert ws.h(x, ((0.0, 0.0, 0.0), (d, d, 0.0, 0.0), (0.5, 0.5, 0.0, 0.0)))[0] == pytest.approx(u * math.cos(d))
    x[AugStates.WHEEL_SCALE] = -0.01
    assert ws.h(x)[0] == pytest.approx(0.99 * u)
    np.testing.assert_allclose(nhc.h(x, w), [-r * GEO.l_r_m, 0.0], atol=1e-9)
    np.testing.assert_allclose(nhc.h(x, None), [0.0, 0.0], atol=1e-9)
