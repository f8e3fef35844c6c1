"""vdps_hil.realcars without the real data: sensor-set files (one-line errors), the sensor set a
signal map provides, the standstill gyro calibration, the NMEA and MTi writers against the
project's own decoders (property tests), outage windows and GNSS-denied filtering, dead
reckoning, the steady-state steering fit on a known bicycle, the publisher's mounting
conversion, lag estimators and time scales."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil import realcars as rc
from vdps_hil.adapters.signalmap import load_signalmap
from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.estimation.ekf_config import SensorSet
from vdps_hil.model.frames import dcm_gv
from vdps_hil.model.params import load_vehicle


# ------------------------------------------------------------------------------ sensor sets
def test_sensor_set_files_load_and_build_pipeline_configs():
    for name in ("rav4-can-ublox", "rtklib-car", "table1"):
        ss = rc.load_sensorset(name)
        cfg = ss.pipeline_config()
        assert cfg.ekf.sensors == ss.sensors
    rtk = rc.load_sensorset("rtklib-car")
    assert rtk.latencies.imu_s == 0.125 and rtk.ekf["use_gnss_velocity"] is False
    assert math.isclose(rtk.ekf["gyro_noise_radps"], math.radians(1.0))  # _degps keys converted
    assert isinstance(rtk.calibration_nodes()[0], rc.ZeroRateCalibration)
    assert rc.load_sensorset("rav4-can-ublox").kind_map == {"esc_imu": "imu"}
    assert rc.load_sensorset("table1").calibration_nodes() == []


@pytest.mark.parametrize("text, fragment", [
    ("[sensors]\nimu = \"9axis\"\n", "[sensors]"),
    ("[ekf]\nwarp = 1.0\n", "unknown key 'warp'"),
    ("[ekf]\naccel_noise_mps2 = \"big\"\n", "expected a finite number"),
    ("[ekf]\nuse_gnss_velocity = 1\n", "expected true or false"),
    ("[calibration]\nzero_rate = \"yes\"\n", "expected true or false"),
    ("[calibration]\nmin_still_s = -1.0\n", "must be positive"),
    ("[pipeline]\npredict_period_s = 0.0\n", "positive"),
    ("[kind_map]\nesc_imu = 3\n", "[kind_map]"),
    ("hello = [\n", "malformed TOML"),
    ("extra = 1\n", "unknown key 'extra'"),
])
def test_bad_sensor_set_files_are_one_line_errors(text, fragment):
    with pytest.raises(rc.SensorSetError) as e:
        rc.parse_sensorset(text, "x.toml")
    assert fragment in str(e.value) and "\n" not in str(e.value)


def test_sensor_set_from_what_a_signal_map_provides():
    sm = load_signalmap("toyota_rav4_2017")
    fields = {}
    for rule in sm.bus("pt").messages.values():
        fields.setdefault(rule.kind, set()).update(r.field for r in rule.rules)
    ss, km = rc.infer_sensor_set(fields)
    assert ss == SensorSet(imu="esc3", gnss="none", suspension=False, wheel_speeds=True) and km == {"esc_imu": "imu"}
    fields["gnss_pos"] = {"gnss_lat_deg", "gnss_lon_deg", "gnss_alt_m"}
    assert rc.infer_sensor_set(fields)[0].gnss == "single_antenna"
    fields["gnss_att"] = {"gnss_yaw_rad"}
    assert rc.infer_sensor_set(fields)[0].gnss == "multi_antenna"
    six = {f"specific_force_mps2_{a}" for a in "xyz"} | {f"angular_rate_radps_{a}" for a in "xyz"}
    assert rc.infer_sensor_set({"imu": six})[0].imu == "6axis"
    with pytest.raises(rc.SensorSetError):
        rc.infer_sensor_set({"wheel_speed": {"wheel_speed_radps_1"}})


# ------------------------------------------------------------------------------ calibration
def _imu(t, w):
    return Sample(int(round(t * 1e9)), "imu", "imu", {"angular_rate_radps_x": w[0], "angular_rate_radps_y": w[1],
                                                     "angular_rate_radps_z": w[2], "specific_force_mps2_x": 0.0})


def _vel(t, v):
    return Sample(int(round(t * 1e9)), "gnss", "gnss_vel", {"gnss_speed_mps": v})


def test_zero_rate_calibration_learns_at_standstill_and_is_causal(rng):
    bias = np.array([0.01, -0.02, 0.003])
    cal = rc.ZeroRateCalibration(speed_still_mps=0.1, min_still_s=2.0)
    out, raw = [], []
    for k in range(1200):  # 12 s at 100 Hz: still for 1.5 s (too short), moving, still for 6 s, moving
        t = k * 0.01
        moving = t < 3.0 or 4.5 <= t < 5.0 or t >= 11.0
        if k % 25 == 0:
            out.append(cal.process(_vel(t, 5.0 if moving else 0.0)))
        s = _imu(t, bias + rng.normal(0.0, 0.005, 3) + (0.2 if moving else 0.0))
        raw.append(s)
        out.append(cal.process(s))
    imu = [s for s in out if s.kind == "imu"]
    changed = np.array([o.fields != r.fields for o, r in zip(imu, raw)])
    t_imu = np.array([s.t_ns for s in raw]) / 1e9
    assert not changed[t_imu < 7.0].any() and changed[t_imu >= 7.0].all()  # stop from 5.0 s qualifies at 7.0 s
    assert cal.counters["stops"] == 1
    assert np.allclose(cal.bias_radps, bias, atol=5e-4)
    late = np.array([[s.fields[f"angular_rate_radps_{a}"] for a in "xyz"] for s in imu if s.t_ns > 11.5e9])
    assert np.allclose(late.mean(axis=0), 0.2, atol=2e-3)  # bias removed from the moving part
    early = np.array([s.fields["angular_rate_radps_z"] for s in imu if s.t_ns < 3e9])
    assert abs(early.mean() - (0.2 + bias[2])) < 2e-3  # samples before the stop are untouched


# ------------------------------------------------------------------------------ writers
@settings(max_examples=60, deadline=None)
@given(lat=st.floats(-89.0, 89.0), lon=st.floats(-179.9, 179.9), h=st.floats(-100.0, 5000.0),
       speed=st.floats(0.0, 80.0), course=st.floats(-math.pi, math.pi - 1e-6), q=st.sampled_from([1, 2, 4, 5]),
       t=st.floats(0.0, 1e5), utc=st.floats(1.5e9, 1.8e9))
def test_nmea_fix_lines_round_trip(lat, lon, h, speed, course, q, t, utc):
    fx = rc.GnssFixes(np.array([t]), np.array([utc]), np.array([lat]), np.array([lon]), np.array([h]),
                      np.array([speed]), np.array([course]), np.array([float(q)]), np.array([12.0]),
                      np.array([np.nan]), np.array([np.nan]))
    dec = NmeaDecoder()
    from vdps_hil.adapters.nmea_adapter import parse_time_prefix
    got = []
    for line in rc.nmea_fix_lines(fx, 0.0):
        ts, rest = parse_time_prefix(line)
        assert ts == round(t * 1e6) * 1000
        got += dec.feed_line(ts, rest)
    assert dec.counters["rejected"] == 0 and [s.kind for s in got] == ["gnss_pos", "gnss_vel"]
    p, v = got[0].fields, got[1].fields
    assert abs(p["gnss_lat_deg"] - lat) <= 1e-6 / 60 and abs(p["gnss_lon_deg"] - lon) <= 1e-6 / 60
    assert abs(p["gnss_alt_m"] + p["gnss_geoid_sep_m"] - h) <= 5e-4 + 1e-9
    assert p["gnss_fix_quality"] == q
    assert abs(v["gnss_speed_mps"] - speed) <= 0.0005 * 1852 / 3600 + 1e-9
    assert abs(rc.wrap_pi(v["gnss_course_rad"] - course)) <= math.radians(0.0005) + 1e-9


@settings(max_examples=40, deadline=None)
@given(gaps=st.lists(st.floats(0.0005, 0.02), min_size=1, max_size=60), baud=st.sampled_from([57600, 115200]))
def test_mti_capture_puts_each_packet_at_its_stamp(gaps, baud):
    t = 0.05 + np.cumsum(gaps)
    n = t.shape[0]
    f = np.tile([0.1, -0.2, 9.8], (n, 1)) + np.arange(n)[:, None] * 1e-3
    imu = rc.ImuSeries(t, f, np.zeros((n, 3)), "flu")
    data, stats = rc.mti_capture(imu, 0.0, baud)
    dec = ImuDecoder(baud=baud)
    from vdps_hil.codecs.framing import transmission_time_ns
    out = []
    for k in range(0, len(data), 4096):  # the file adapter's chunks, stamped by wire time
        chunk = data[k:k + 4096]
        out += dec.feed(transmission_time_ns(k + len(chunk), baud), chunk)
    out += dec.flush()
    assert len(out) == n and dec.counters["rejected"] == 0
    got = np.array([s.t_ns for s in out]) / 1e9
    byte = 10.0 / baud
    late = got - t
    assert np.all(late >= -byte) and (stats.delayed > 0 or np.all(late <= byte))
    assert np.allclose([s.fields["specific_force_mps2_x"] for s in out], f[:, 0], atol=1e-6)
    with pytest.raises(ValueError):
        rc.mti_capture(rc.ImuSeries(t + 500.0, f, np.zeros((n, 3)), "flu"), 0.0, baud)


# ------------------------------------------------------------------------------ runs and metrics
def test_gnss_denied_and_outage_windows():
    wins = rc.outage_windows(100.0, 200.0, 30.0, (5.0, 10.0), first_offset_s=0.0)
    assert wins == [(100.0, 105.0), (130.0, 140.0), (160.0, 165.0)]  # (190, 200) would not end before 200
    drop = rc.gnss_denied(wins)
    assert drop(Sample(int(101e9), "gnss", "gnss_pos")) and not drop(Sample(int(105e9), "gnss", "gnss_pos"))
    assert not drop(Sample(int(101e9), "imu", "imu")) and drop(Sample(int(139.9e9), "gnss", "gnss_vel"))


def test_dead_reckoning_on_a_circle_and_constant_velocity():
    t = np.linspace(0.0, 10.0, 2001)
    w = 0.1
    tt, sp, crs, p = rc.dead_reckoning(t, np.full_like(t, 10.0), np.full_like(t, w), np.zeros(2), 0.0, 0.0, 10.0)
    exact = np.array([100.0 * math.sin(w * 10.0), 100.0 * (1.0 - math.cos(w * 10.0))])
    assert np.allclose(p[-1], exact, atol=1e-3) and math.isclose(crs[-1], 1.0, abs_tol=1e-9)
    assert np.allclose(rc.constant_velocity([1.0, 2.0, 0.0], [3.0, 0.0, 0.0], 5.0, [7.0]), [[7.0, 2.0, 0.0]])


def test_steer_response_fit_recovers_a_known_bicycle(rng):
    L, sr, k, off = 2.65, 15.0, 0.004, math.radians(0.3)
    t = np.arange(0.0, 120.0, 0.05)
    u = 10.0 + 8.0 * np.sin(2 * math.pi * t / 120.0) ** 2
    sw = math.radians(20.0) * np.sin(2 * math.pi * t / 7.0) + off
    r = u * (sw - off) / (sr * (L + k * u * u))
    bias = math.radians(0.3)
    fit = rc.steer_response_fit(t, u, sw + rng.normal(0.0, 1e-4, t.shape), r + bias, r + rng.normal(0.0, 1e-4, t.shape),
                                wheelbase_m=L, understeer0=k, prior_steer_ratio=16.0)
    print(f"\nknown bicycle s_R {sr}, x 1, offset 0.3 deg -> {fit.steer_ratio:.2f} +- {fit.steer_ratio_sigma:.2f}, "
          f"{fit.stiffness_factor:.3f} +- {fit.stiffness_factor_sigma:.3f}, {fit.angle_offset_deg:.3f} deg")
    assert abs(fit.steer_ratio - sr) < max(3 * fit.steer_ratio_sigma, 0.05)
    assert abs(fit.stiffness_factor - 1.0) < max(3 * fit.stiffness_factor_sigma, 0.01)
    assert abs(fit.angle_offset_deg - 0.3) < max(3 * fit.angle_offset_sigma_deg, 0.005)
    assert math.isclose(fit.yaw_rate_bias_degps, 0.3, abs_tol=0.01)
    assert all(fit.observable().values())
    # one speed only: s_R L and s_R K_us are no longer separable
    fit2 = rc.steer_response_fit(t, np.full_like(t, 15.0), sw, 15.0 * (sw - off) / (sr * (L + k * 225.0)),
                                 15.0 * (sw - off) / (sr * (L + k * 225.0)), wheelbase_m=L, understeer0=k,
                                 prior_steer_ratio=16.0)
    assert not fit2.observable()["understeer_x_steer_ratio"]
    assert any(e.names[:2] == ("steer_ratio_x_wheelbase", "understeer_x_steer_ratio") for e in fit2.explanations)


# ------------------------------------------------------------------------------ mounting, lags, time
def test_publisher_mounting_matches_the_vehicle_file_and_groves():
    veh = load_vehicle("rtklib-car-model", "model")
    rpy = rc.publisher_mounting_rpy((180.0, 0.0, 180.0), (0.0, -6.79, 5.35))
    assert np.allclose(rpy, veh.mounting.imu_rotation_rpy_rad, atol=1e-9)
    e = np.radians([180.0, -6.79, 185.35])
    f_imu = np.array([1.15, 0.30, 9.86])  # the drive's standstill mean [m/s^2]
    f_frd = rc.groves_ctm(*e) @ f_imu  # the publisher's own transform
    f_flu = dcm_gv(*rpy).T @ f_imu  # what the pipeline does with the model file
    assert np.allclose(f_flu, f_frd * np.array([1.0, -1.0, -1.0]), atol=1e-12)
    assert abs(f_flu[0]) < 0.05 and f_flu[2] > 9.8  # level forward axis once the misalignment is applied
    assert np.allclose(rc.publisher_mounting_rpy((180.0, 0.0, 180.0)), (0.0, 0.0, -math.pi), atol=1e-12)
    assert veh.mounting.imu_lever_arm_m == (0.0, 0.0, 0.65) and veh.mounting.gnss_lever_arm_m == (0.0, 0.05, 0.65)


def test_lag_estimators_and_time_scales():
    t = np.arange(0.0, 60.0, 0.25)
    p = np.column_stack([np.cumsum(np.full_like(t, 2.5)) + 10 * np.sin(t / 5), 20 * np.cos(t / 7), np.zeros_like(t)])
    v_true = np.column_stack([np.gradient(p[:, 0], t), np.gradient(p[:, 1], t), np.zeros_like(t)])
    late = np.column_stack([np.interp(t - 0.1, t, v_true[:, k]) for k in range(3)])
    from vdps_hil.geodesy import DEFAULT_ORIGIN
    assert math.isclose(rc.velocity_lag(rc.Reference(t, DEFAULT_ORIGIN, p, late)), 0.1, abs_tol=0.011)
    x = np.sin(t)
    assert math.isclose(rc.estimate_lag(t, np.sin(t - 0.15), t, x, np.arange(0, 0.3, 0.01)), 0.15, abs_tol=1e-9)
    assert rc.gpst_minus_utc_s(1.75e9) == 18 and rc.gpst_minus_utc_s(1.2e9) == 14
    assert rc.gpst_to_unix(rc.unix_to_gpst(1.75e9)) == 1.75e9
