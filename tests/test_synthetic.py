"""Synthetic trajectories are physically consistent: noise-free IMU integrates to the truth,
absolute angles obey eq 4, deflections map back through eq 5, Table-1 rates and noise levels,
and samples use catalogue fields only."""

import math

import numpy as np

from vdps_hil.bus.samples import check_fields
from vdps_hil.estimation import kinematics as K
from vdps_hil.experiments import synthetic as syn
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.model import frames as fr
from vdps_hil.model.params import load_vehicle

VEH = load_vehicle("sedan-model")
MAN = syn.Maneuver(duration_s=10.0)


def test_noise_free_imu_integrates_to_the_truth():
    """1 kHz samples carrying the interval mean, integrated with ``kinematics.step``: after 10 s
    position error < 1 mm, velocity < 0.1 mm/s, angles < 1e-7 rad."""
    dt = 1e-3
    t = np.arange(1, 10001) * dt
    imu = syn.truth(MAN, t - 0.5 * dt)
    tr = syn.truth(MAN, t)
    x = syn.truth(MAN, np.array([0.0])).x_full[0]
    for k in range(t.size):
        x = K.step(x, imu.specific_force_b[k], imu.omega_b[k], dt)
    e = x - tr.x_full[-1]
    e[8] = (e[8] + math.pi) % (2 * math.pi) - math.pi
    assert np.abs(e[0:3]).max() < 1e-3 and np.abs(e[3:6]).max() < 1e-4 and np.abs(e[6:9]).max() < 1e-7


def test_truth_angles_obey_eq4_and_deflections_eq5():
    tr = syn.truth(MAN, np.linspace(0, 10, 21))
    for k in range(0, 21, 4):
        pv, tv, sv = tr.vehicle_angles[k]
        g = fr.compose_absolute(pv, tv, sv, MAN.bank_rad, MAN.grade_rad)
        d = tr.x_full[k, 6:9] - np.array(g)
        d[2] = (d[2] + math.pi) % (2 * math.pi) - math.pi
        assert np.abs(d).max() < 1e-12
    h = syn.deflections(tr, VEH.geometry)
    geo = VEH.geometry
    for k in range(21):
        z_r, th, ph = fr.suspension_to_road_attitude(h[k], geo.l_f_m, geo.l_r_m, geo.track_half_front_m,
                                                     geo.track_half_rear_m)
        assert abs(z_r - tr.heave_m[k]) < 1e-12
        assert abs(th - tr.vehicle_angles[k, 1]) < 1e-12 and abs(ph - tr.vehicle_angles[k, 0]) < 1e-12


def test_table1_rates_noise_and_outage():
    data = syn.make_sensor_data(MAN, VEH, seed=0, gnss_outage_s=(4.0, 6.0))
    assert data.t_imu_ns.size == 10000 and data.t_tacho_ns.size == 10000
    assert data.t_susp_ns.size == 10
    assert data.t_gnss_ns.size == 50 - 10  # 5 Hz, 2 s outage
    assert not ((data.t_gnss_ns >= 4e9) & (data.t_gnss_ns < 6e9)).any()
    t = data.t_imu_ns / 1e9 - 0.5e-3
    tr = syn.truth(MAN, t)
    assert abs((data.specific_force - tr.specific_force_b).std() / 0.02 - 1) < 0.05
    assert abs((data.angular_rate - tr.omega_b).std() / math.radians(0.08) - 1) < 0.05
    assert np.all(np.diff(data.t_imu_ns) == 1_000_000)


def test_samples_use_catalogue_fields_in_time_order():
    data = syn.make_sensor_data(syn.Maneuver(duration_s=2.0), VEH, seed=0)
    for variant in ({}, {"imu_fields": "esc3", "gnss": "single_antenna", "suspension": False}):
        samples = syn.to_samples(data, DEFAULT_ORIGIN, **variant)
        assert all(s1.t_ns <= s2.t_ns for s1, s2 in zip(samples, samples[1:]))
        for s in samples:
            check_fields(s.fields)
        kinds = {s.kind for s in samples}
        assert ("gnss_att" in kinds) == (not variant)
        assert ("suspension" in kinds) == (not variant)
    gp = next(s for s in samples if s.kind == "gnss_pos")
    enu = DEFAULT_ORIGIN.to_enu(gp.fields["gnss_lat_deg"], gp.fields["gnss_lon_deg"], gp.fields["gnss_alt_m"])
    np.testing.assert_allclose(enu, data.gnss_pos_enu[0], atol=1e-6)
