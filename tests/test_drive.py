"""Tests of sim.drive: a simulated drive decoded with the foundation decoders gives back the truth
within the wire quantisation, the noise matches the profile, every NMEA sentence passes
pynmeagps, nothing in /raw/ names an effect or a fault, seeds reproduce the bytes, rollover
events reach /truth/events and the summary."""

from __future__ import annotations

import base64
import dataclasses as dc
import io
import json
import math

import numpy as np
import pytest
from pynmeagps import NMEAReader, VALCKSUM

from vdps_hil.codecs.can_dbc import load_dbc
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.framing import LineFramer, transmission_time_ns
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.model.effects import REGISTRY as EFFECTS, EffectConfigError
from vdps_hil.model.frames import dcm_global_to_vehicle
from vdps_hil.record import schemas as S
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive, DriveError
from vdps_hil.sim.faults import REGISTRY as FAULTS
from vdps_hil.sim.profiles import load_profile
from vdps_hil.sim.scenarios import load_scenario, parse_scenario
from vdps_hil.sim.sensors import GEOID_SEPARATION_M

MS = 1_000_000
DBC = load_dbc()
PROFILE = load_profile("table1-susp1k")
STRAIGHT = parse_scenario('name = "straight"\nduration_s = 60.0\n[initial]\nspeed_mps = 20.0\n')
ROLLOVER = parse_scenario('name = "tip"\nvehicle = "suv-truth"\nduration_s = 3.0\n'
                          'stop_at_point_of_no_return = true\n[initial]\nspeed_mps = 30.0\n'
                          '[inputs]\nsteer_wheel_angle_rad = { type = "step", t_s = 0.5, after = 4.0 }\n')


def run(drive: Drive) -> tuple[RecordingReader, object]:
    buf = io.BytesIO()
    summary = drive.run(buf)
    buf.seek(0)
    return RecordingReader(buf), summary


def decode(r: RecordingReader) -> dict:
    """Every /raw/ topic through the foundation decoders."""
    can_dec, imu_dec = VdpsCanDecoder(), ImuDecoder()
    framer, nmea_dec = LineFramer(115200), NmeaDecoder()
    out = {"can": {}, "imu": [], "gnss": [], "lines": [], "can_t": []}
    for _, msg in r.iter_raw_can():
        for s in can_dec.decode_message(msg):
            out["can"].setdefault(s.kind, []).append(s)
            out["can_t"].append(s.t_ns)
    for dev, t, data in r.iter_raw_serial():
        if dev == "imu":
            out["imu"] += imu_dec.feed(t, data)
        else:
            for tl, line in framer.feed(t, data):
                out["lines"].append(line)
                out["gnss"] += nmea_dec.feed_line(tl, line)
    out["imu"] += imu_dec.flush()
    out["decoders"] = (can_dec, imu_dec, framer, nmea_dec)
    return out


def truth_table(r: RecordingReader) -> dict[int, dict]:
    return {t: doc["values"] for _, t, doc in r.iter_messages(["/truth/state"])}


@pytest.fixture(scope="module")
def zero_noise_drive():
    r, summary = run(Drive("paper", profile=PROFILE.zero_noise(), seed=3, duration_s=2.0))
    return r, summary, decode(r), truth_table(r)


def test_zero_noise_drive_decodes_to_the_truth_within_the_wire_resolution(zero_noise_drive):
    r, summary, d, truth = zero_noise_drive
    can_dec, imu_dec, framer, nmea_dec = d["decoders"]
    assert can_dec.total_rejected == 0
    assert all(c["lost_frames"] == 0 for k, c in can_dec.counters.items() if k != "bus")
    assert imu_dec.counters["rejected"] == 0 and imu_dec.counters["seq_gaps"] == 0
    assert nmea_dec.counters["rejected"] == 0 and framer.pending_bytes == 0
    # 2 s: 2001 samples of each 1 kHz sensor, 201 of the 100 Hz ones, 11 GNSS epochs
    assert {k: len(v) for k, v in d["can"].items()} == {
        "wheel_speed": 4002, "suspension": 2001, "wheel_torque": 201, "steer": 201}
    assert len(d["imu"]) == 2001 and len(d["gnss"]) == 33
    res = {f: s.resolution for _, spec in DBC.messages.items() for f, s in zip(spec.field_names, spec.values)}
    checked = 0
    for kind, samples in d["can"].items():
        for s in samples:
            t_meas = s.t_ns // MS * MS  # frames arrive 87..600 us after their sampling instant
            assert 80_000 <= s.t_ns - t_meas <= 600_000
            if t_meas not in truth:
                continue
            for f, v in s.fields.items():
                if f != "seq_counter":
                    assert abs(v - truth[t_meas][f]) <= res[f] / 2 + 1e-9, (kind, f)
                    checked += 1
    assert checked > 2000
    for s in d["imu"]:
        k = int(s.fields["seq_counter"])
        if k * MS in truth:
            tv = truth[k * MS]  # IMU at the CG, axes aligned (sedan mounting): f = f_cg, w = w_b
            for a in "xyz":
                assert s.fields[f"specific_force_mps2_{a}"] == \
                    pytest.approx(tv[f"specific_force_b_mps2_{a}"], rel=1e-6, abs=1e-6)
                assert s.fields[f"angular_rate_radps_{a}"] == pytest.approx(tv[f"rate_b_radps_{a}"], rel=1e-6, abs=1e-9)
    assert json.loads(r.metadata()["truth.drive"]["duration_s"]) == 2.0
    r_ant = np.array(load_scenario("paper").vehicle.mounting.gnss_lever_arm_m)
    epoch_t = None
    for s in d["gnss"]:
        tv = None
        if s.kind == "gnss_pos":
            epoch_t = round(s.t_ns / 200e6) * 200 * MS  # the epoch of this line (no latency)
            tv = truth[epoch_t]
            c = dcm_global_to_vehicle(tv["roll_g_rad"], tv["pitch_g_rad"], tv["yaw_g_rad"])
            p = np.array([tv["pos_e_m"], tv["pos_n_m"], tv["pos_u_m"]]) + c.T @ r_ant
            lat, lon, h = DEFAULT_ORIGIN.to_geodetic(p)
            assert s.fields["gnss_lat_deg"] == pytest.approx(lat, abs=0.5e-6 / 60 + 1e-12)
            assert s.fields["gnss_lon_deg"] == pytest.approx(lon, abs=0.5e-6 / 60 + 1e-12)
            assert s.fields["gnss_alt_m"] + GEOID_SEPARATION_M == pytest.approx(h, abs=0.5e-3 + 1e-9)
        elif s.kind == "gnss_att":
            tv = truth[epoch_t]
            for f, g in (("gnss_pitch_rad", "pitch_g_rad"), ("gnss_roll_rad", "roll_g_rad")):
                assert s.fields[f] == pytest.approx(tv[g], abs=math.radians(0.005) + 1e-12)
            assert math.remainder(s.fields["gnss_yaw_rad"] - tv["yaw_g_rad"], 2 * math.pi) == \
                pytest.approx(0, abs=math.radians(0.005) + 1e-12)
        else:
            tv = truth[epoch_t]
            # antenna 0.85 m above the CG: v_ant = v + w x r, printed to 0.001 kn
            assert s.fields["gnss_speed_mps"] == pytest.approx(tv["speed_mps"], abs=0.05)


def test_every_nmea_sentence_passes_pynmeagps_checksum_validation(zero_noise_drive):
    _, _, d, _ = zero_noise_drive
    assert len(d["lines"]) == 33
    for line in d["lines"]:
        NMEAReader.parse(line + b"\r\n", validate=VALCKSUM)  # raises on a bad checksum


def test_serial_timing_follows_the_devices(zero_noise_drive):
    r, _, d, _ = zero_noise_drive
    imu_dec = d["decoders"][1]
    assert imu_dec.last_packet.sample_time_fine == 2000 * 10  # device time of packet 2000
    chunks = list(r.iter_raw_serial("imu"))
    assert len(chunks) == 401  # one read per 5 ms window that received bytes
    for dev, t, data in chunks:
        assert len(data) % 47 == 0 and data[:2] == b"\xfa\xff"
        k_last = int.from_bytes(data[-40:-38], "big")  # PacketCounter of the chunk's last packet
        assert t == k_last * MS + transmission_time_ns(47, 921600)  # its last byte's arrival
    assert r.serial_config("imu") == (921600, "xsens-mtdata2")
    assert r.serial_config("gnss") == (115200, "nmea")


def test_noise_statistics_match_the_profile_over_a_60_s_drive():
    r, summary = run(Drive(STRAIGHT, profile=PROFILE, seed=21))
    truth = truth_table(r)
    d = decode(r)
    assert summary.duration_s == 60.0
    t_keys = np.array(sorted(truth))
    # IMU: residuals at the 100 Hz truth instants (6001 per axis: rel. SE of sigma 0.9 %)
    imu = {int(s.fields["seq_counter"]) * MS: s.fields for s in d["imu"]}
    assert len(d["imu"]) == 60001
    res_f, res_w = [], []
    for t in t_keys.tolist():
        k = t // MS % 65536 * MS
        s, tv = imu[k], truth[t]
        res_f.append([s[f"specific_force_mps2_{a}"] - tv[f"specific_force_b_mps2_{a}"] for a in "xyz"])
        res_w.append([s[f"angular_rate_radps_{a}"] - tv[f"rate_b_radps_{a}"] for a in "xyz"])
    np.testing.assert_allclose(np.std(res_f, axis=0), PROFILE.imu.accel_sigma_mps2, rtol=0.05)
    np.testing.assert_allclose(np.std(res_w, axis=0), PROFILE.imu.gyro_sigma_radps, rtol=0.05)
    # chassis sensors: the decoded value minus the truth at its sampling instant
    for kind, stem, sigma in (("wheel_speed", "wheel_speed_radps", PROFILE.tachometer.sigma_radps),
                              ("suspension", "susp_deflection_m", PROFILE.suspension.sigma_m)):
        res = {}
        for s in d["can"][kind]:
            t = s.t_ns // MS * MS
            if t in truth:
                for f, v in s.fields.items():
                    if f.startswith(stem):
                        res.setdefault(f, []).append(v - truth[t][f])
        assert len(res) == 4 and all(len(v) == 6001 for v in res.values())
        np.testing.assert_allclose([np.std(v) for v in res.values()], sigma, rtol=0.05)
    # GNSS at 5 Hz: only 301 epochs, so sigma's relative standard error is 4.1 % (2.9 % pooled
    # over E/N or roll/pitch): tolerances of about 4 standard errors (12 %, vertical 15 %)
    pos = [s.fields for s in d["gnss"] if s.kind == "gnss_pos"]
    att = [s.fields for s in d["gnss"] if s.kind == "gnss_att"]
    assert len(pos) == len(att) == 301
    tvs = [truth[k * 200 * MS] for k in range(301)]
    att_res = np.array([[a["gnss_roll_rad"] - tv["roll_g_rad"], a["gnss_pitch_rad"] - tv["pitch_g_rad"]]
                        for a, tv in zip(att, tvs)])
    assert np.std(att_res) == pytest.approx(PROFILE.gnss.attitude_sigma_rad, rel=0.12)
    r_ant = np.array(STRAIGHT.vehicle.mounting.gnss_lever_arm_m)
    enu = np.array([DEFAULT_ORIGIN.to_enu(p["gnss_lat_deg"], p["gnss_lon_deg"], p["gnss_alt_m"] + GEOID_SEPARATION_M)
                    - (np.array([tv["pos_e_m"], tv["pos_n_m"], tv["pos_u_m"]])
                       + dcm_global_to_vehicle(tv["roll_g_rad"], tv["pitch_g_rad"], tv["yaw_g_rad"]).T @ r_ant)
                    for p, tv in zip(pos, tvs)])
    assert np.std(enu[:, :2]) == pytest.approx(PROFILE.gnss.pos_sigma_h_m, rel=0.12)
    assert np.std(enu[:, 2]) == pytest.approx(PROFILE.gnss.pos_sigma_v_m, rel=0.15)


def _raw_bytes(r: RecordingReader) -> list[bytes]:
    out = []
    for rec in r.iter_records(prefixes=(S.RAW_PREFIX,)):
        out.append(rec.data)
        doc = json.loads(rec.data)
        if "data_b64" in doc:
            out.append(base64.b64decode(doc["data_b64"]))
    return out


ALL_FAULTS = ["gnss_outage:t_s=0.5,duration_s=0.5", "gyro_spike:t_s=0.3",
              "frozen_can_signal:t_s=0.4,duration_s=0.5", "dropped_frames:fraction=0.05",
              "serial_disconnect:device=gnss,t_s=1.2,duration_s=0.2",
              "clock_jump:device=imu,t_s=1.0,jump_s=0.5"]


def test_raw_topics_carry_no_effect_fault_or_truth():
    drive = Drive("paper", seed=5, duration_s=1.5, effects=["imu_bias", "imu_lever_arm", "aero_drag"],
                  faults=ALL_FAULTS)
    r, summary = run(drive)
    names = set(EFFECTS) | set(FAULTS) | {"magic_formula", "tire", "truth", "fault", "effect", "paper"}
    blobs = _raw_bytes(r)
    assert len(blobs) > 4000
    for b in blobs:
        low = b.lower()
        for n in names:
            assert n.encode() not in low
    for topic in r.topics():
        if topic.startswith(S.RAW_PREFIX):
            md = r.channel_metadata(topic)
            assert set(md) <= {"bus", "device", "baud", "format"}
            assert not any(n in v for v in md.values() for n in names)
    # raw documents hold only the schema's keys
    for rec in r.iter_records(prefixes=(S.RAW_PREFIX,)):
        doc = json.loads(rec.data)
        schema = S.SCHEMAS[S.RAW_SERIAL if "data_b64" in doc else S.RAW_CAN]
        assert set(doc) <= set(schema["properties"])
    rec_md = json.dumps(r.metadata()["vdps.recording"])
    assert not any(n in rec_md for n in names)
    # what was injected is kept for the truth side only
    td = r.metadata()["truth.drive"]
    assert {e["name"] for e in json.loads(td["effects"])} == \
        {"magic_formula_tire", "imu_bias", "imu_lever_arm", "aero_drag"}
    assert [f["name"] for f in json.loads(td["faults"])] == [s.split(":")[0] for s in ALL_FAULTS]
    events = [doc["values"] for _, _, doc in r.iter_messages(["/truth/events"])]
    assert {e["fault"] for e in events if e["kind"] == "fault_start"} == {s.split(":")[0] for s in ALL_FAULTS}
    assert summary.faults and summary.effects[0] == "magic_formula_tire"


def test_seeds_reproduce_the_raw_bytes():
    def raw(seed):
        r, _ = run(Drive("paper", seed=seed, duration_s=0.6, faults=["dropped_frames:fraction=0.1"]))
        return ([(rec.topic, rec.t_ns, rec.data) for rec in r.iter_records(prefixes=(S.RAW_PREFIX,))],
                [rec.data for rec in r.iter_records(["/truth/state"])])
    a, b, c = raw(9), raw(9), raw(10)
    assert a == b
    assert a[0] != c[0] and a[1] == c[1]  # the seed moves the sensors, never the truth


def test_rollover_events_reach_the_truth_topic_and_the_summary():
    r, summary = run(Drive(ROLLOVER, profile="table1", seed=1))
    kinds = [e["kind"] for e in summary.rollover_events]
    assert kinds == ["tip_up", "point_of_no_return"]
    assert summary.stop_reason == "point_of_no_return" and summary.duration_s < 3.0
    events = [doc["values"] for _, _, doc in r.iter_messages(["/truth/events"])]
    assert [e["kind"] for e in events] == kinds
    doc = summary.to_json()
    assert doc["max_abs_roll_rel_road_rad"] > events[1]["tip_angle_rad"]
    assert doc["messages"]["/truth/state"] == round(summary.duration_s * 100) + 1
    json.dumps(doc)  # serialisable


def test_scenario_faults_come_first_and_bad_configs_are_one_line():
    sc = dc.replace(STRAIGHT, raw={**STRAIGHT.raw, "faults": ["gyro_spike", {"name": "gnss_outage", "t_s": 1.0}]})
    d = Drive(sc, faults=["clock_jump"])
    assert [f.name for f in d.faults] == ["gyro_spike", "gnss_outage", "clock_jump"]
    for kw in ({"duration_s": 0.0}, {"duration_s": 86400.001}, {"effects": ["imu_bias:x"]}, {"effects": ["imu_bias:accel_bias_x_mps2=a"]},
               {"read_period_s": 0.0}):
        with pytest.raises(DriveError) as e:
            Drive(STRAIGHT, **kw)
        assert "\n" not in str(e.value)
    # a truth outside an effect's physical range (drag thrusting the car, a 1e5 m/s^2 bias; a drag
    # area of 1e9 m^2 was an internal error: non-finite state at 0.002 s)
    for spec, name in (("aero_drag:cda_m2=-5", "cda_m2"), ("aero_drag:cda_m2=1e9", "cda_m2"),
                       ("imu_bias:accel_bias_x_mps2=1e5", "accel_bias_x_mps2")):
        with pytest.raises(EffectConfigError, match=f"{name} = .* is outside its physical range") as e:
            Drive(STRAIGHT, effects=[spec])
        assert "\n" not in str(e.value)
