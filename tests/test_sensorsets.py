"""vdps_hil.estimation.sensorsets: sensor-set files (one-line errors), the sensor set a signal map
provides, the standstill gyro calibration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vdps_hil.adapters.signalmap import load_signalmap
from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.ekf_config import SensorSet
from vdps_hil.estimation.sensorsets import (KindMap, SensorSetError, ZeroRateCalibration, infer_sensor_set,
                                            load_sensorset, not_used_note, parse_sensorset)


# ------------------------------------------------------------------------------ sensor sets
def test_sensor_set_files_load_and_build_pipeline_configs():
    for name in ("rav4-can-ublox", "rtklib-car", "table1"):
        ss = load_sensorset(name)
        cfg = ss.pipeline_config()
        assert cfg.ekf.sensors == ss.sensors
    rtk = load_sensorset("rtklib-car")
    assert rtk.latencies.imu_s == 0.125 and rtk.ekf["use_gnss_velocity"] is False
    assert math.isclose(rtk.ekf["gyro_noise_radps"], math.radians(1.0))  # _degps keys converted
    assert isinstance(rtk.calibration_nodes()[0], ZeroRateCalibration)
    assert load_sensorset("rav4-can-ublox").kind_map == {"esc_imu": "imu"}
    assert load_sensorset("table1").calibration_nodes() == []


@pytest.mark.parametrize("text, fragment", [
    ("[sensors]\nimu = \"9axis\"\n", "[sensors]"),
    ("[sensors]\nsuspension = nan\n", "suspension must be true or false"),  # was an internal error
    ("[ekf]\naccel_noise_mps2 = 1e300\n", "magnitude at most 1e+06"),  # overflowed in the filter
    ("[latencies]\ngnss_s = 1e300\n", "magnitude at most 1e+06"),
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
    with pytest.raises(SensorSetError) as e:
        parse_sensorset(text, "x.toml")
    assert fragment in str(e.value) and "\n" not in str(e.value)


def test_sensor_set_from_what_a_signal_map_provides():
    sm = load_signalmap("toyota_rav4_2017")
    fields = {}
    for rule in sm.bus("pt").messages.values():
        fields.setdefault(rule.kind, set()).update(r.field for r in rule.rules)
    ss, km = infer_sensor_set(fields)
    assert ss == SensorSet(imu="esc3", gnss="none", suspension=False, wheel_speeds=True) and km == {"esc_imu": "imu"}
    fields["gnss_pos"] = {"gnss_lat_deg", "gnss_lon_deg", "gnss_alt_m"}
    assert infer_sensor_set(fields)[0].gnss == "single_antenna"
    fields["gnss_att"] = {"gnss_yaw_rad"}
    assert infer_sensor_set(fields)[0].gnss == "multi_antenna"
    six = {f"specific_force_mps2_{a}" for a in "xyz"} | {f"angular_rate_radps_{a}" for a in "xyz"}
    assert infer_sensor_set({"imu": six})[0].imu == "6axis"
    with pytest.raises(SensorSetError):
        infer_sensor_set({"wheel_speed": {"wheel_speed_radps_1"}})


# ------------------------------------------------------------------------------ calibration
def _imu(t, w):
    return Sample(int(round(t * 1e9)), "imu", "imu", {"angular_rate_radps_x": w[0], "angular_rate_radps_y": w[1],
                                                     "angular_rate_radps_z": w[2], "specific_force_mps2_x": 0.0})


def _vel(t, v):
    return Sample(int(round(t * 1e9)), "gnss", "gnss_vel", {"gnss_speed_mps": v})


def test_zero_rate_calibration_learns_at_standstill_and_is_causal(rng):
    bias = np.array([0.01, -0.02, 0.003])
    cal = ZeroRateCalibration(speed_still_mps=0.1, min_still_s=2.0)
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


def test_kind_map_renames_leaves_out_what_it_feeds_from_elsewhere_and_counts_it():
    """``KindMap``: ``esc_imu`` -> ``imu`` renames the ESC's samples; another source's ``imu``
    samples (a phone IMU the set does not name) are left out and counted per source/kind; kinds the
    map neither renames nor feeds pass as they are (the same object)."""
    km = KindMap({"esc_imu": "imu"})
    esc = Sample(1_000, "can.pt", "esc_imu", {"angular_rate_radps_z": 0.1}, 5, True)
    phone = Sample(2_000, "imu", "imu", {"angular_rate_radps_z": 0.2})
    gnss = Sample(3_000, "gnss", "gnss_pos", {"gnss_lat_deg": 1.0})
    out = km(esc)
    assert (out.kind, out.source, out.t_ns, out.fields, out.wall_time_ns, out.valid) == \
        ("imu", "can.pt", 1_000, esc.fields, 5, True)
    assert km(phone) is None and km(phone) is None
    assert km(gnss) is gnss
    assert km.dropped == {"imu/imu": 2}
    assert not_used_note(km.dropped, km.map) == "not used: imu/imu (2 samples): the sensor set feeds imu from esc_imu"
    empty = KindMap({})
    assert not empty and empty(phone) is phone and not_used_note(empty.dropped, empty.map) is None
    swap = KindMap({"a": "b", "b": "a"})  # a kind both renamed and fed is renamed, never left out
    assert swap(Sample(0, "s", "b", {})).kind == "a" and swap.dropped == {}


def test_kind_map_joins_an_altitude_sent_in_a_frame_of_its_own():
    """``join_altitude`` (the CANedge's GNSS: kinds ``gnss_pos`` without an altitude and
    ``gnss_alt``): each fix gets the newest altitude and its sigma when it is at most 2 s old; the
    altitude samples are taken in; a fix that carries its own altitude, or comes without a recent
    one, passes unchanged; the map then renames as before."""
    km = KindMap({}, join_altitude=True)
    assert km  # on, although it renames nothing
    pos = lambda t, **f: Sample(t, "can.gnss", "gnss_pos", {"gnss_lat_deg": 47.0, "gnss_lon_deg": 8.0, **f})
    assert km(pos(0)).fields.get("gnss_alt_m") is None  # no altitude yet
    assert km(Sample(1_000_000_000, "can.gnss", "gnss_alt", {"gnss_alt_m": 412.5, "gnss_pos_sigma_v_m": 1.5})) is None
    got = km(pos(1_000_000_000))
    assert got.kind == "gnss_pos" and got.fields["gnss_alt_m"] == 412.5 and got.fields["gnss_pos_sigma_v_m"] == 1.5
    assert got.fields["gnss_lat_deg"] == 47.0
    own = pos(2_000_000_000, gnss_alt_m=400.0)
    assert km(own) is own
    assert km(pos(3_500_000_000)).fields.get("gnss_alt_m") is None  # 2.5 s old: not joined
    assert km.joined == 1 and km.dropped == {}
    off = KindMap({})
    alt = Sample(0, "can.gnss", "gnss_alt", {"gnss_alt_m": 1.0})
    assert not off and off(alt) is alt
