"""Tests of sim.faults: parsing and one-line errors, each fault's hook, and each fault in a short
simulated drive decoded with the foundation decoders (it does what its docstring says)."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest

from vdps_hil.codecs.can_dbc import load_dbc
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.framing import LineFramer
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.faults import (REGISTRY, FaultError, FaultSet, GnssOutage, parse_fault)
from vdps_hil.sim.profiles import load_profile
from vdps_hil.sim.scenarios import parse_scenario

MS = 1_000_000
S_ = 1_000_000_000
DBC = load_dbc()
PROFILE = load_profile("table1-susp1k")
STRAIGHT = parse_scenario('name = "straight"\nduration_s = 3.0\n[initial]\nspeed_mps = 20.0\n')


# ------------------------------------------------------------------------------------ parsing
def test_parse_defaults_params_tables_and_spec_round_trip():
    f = parse_fault("gnss_outage")
    assert isinstance(f, GnssOutage) and f.params == {"t_s": 5.0, "duration_s": 5.0, "reacquire_s": 1.0}
    g = parse_fault("gyro_spike:t_s=2.5, axis=x ,amplitude_degps=-50")
    assert (g.t_s, g.axis, g.amplitude_degps) == (2.5, "x", -50.0)
    assert parse_fault(g.spec()).params == g.params
    h = parse_fault({"name": "dropped_frames", "fraction": 0.2, "message": "VDPS_Suspension"})
    assert h.fraction == 0.2 and math.isinf(h.duration_s)
    assert parse_fault("serial_disconnect:duration_s=inf").end_ns > 10**18
    assert set(REGISTRY) == {"gnss_outage", "gyro_spike", "frozen_can_signal", "dropped_frames",
                             "serial_disconnect", "clock_jump"}


@pytest.mark.parametrize("spec", [
    "nope", "", "gnss_outage:t_s", "gnss_outage:x=1", "gnss_outage:t_s=a", "gnss_outage:t_s=-1",
    "gnss_outage:t_s=1,t_s=2", "gyro_spike:axis=w", "dropped_frames:fraction=2",
    "serial_disconnect:device=can", "clock_jump:device=x", {"fraction": 0.1}, 42,
    "gnss_outage:t_s=nan"])
def test_bad_fault_specs_are_one_line_errors(spec):
    with pytest.raises(FaultError) as e:
        parse_fault(spec)
    assert "\n" not in str(e.value) and str(e.value)


def test_faults_checked_against_the_dbc():
    with pytest.raises(FaultError, match="signal 'speed'"):
        FaultSet(["frozen_can_signal:signal=speed"], dbc=DBC)
    with pytest.raises(FaultError, match="unknown message"):
        FaultSet(["dropped_frames:message=VDPS_Nothing"], dbc=DBC)
    with pytest.raises(FaultError, match="unknown message"):  # the warning is not a sensor frame
        FaultSet(["dropped_frames:message=VDPS_Warning"], dbc=DBC)


# ------------------------------------------------------------------------------------ hooks
def test_hooks_act_only_in_their_windows():
    t = np.arange(0, 10 * S_, 100 * MS)
    fs = FaultSet(["gnss_outage:t_s=2,duration_s=3,reacquire_s=1",
                   "serial_disconnect:device=gnss,t_s=1,duration_s=0.5",
                   "clock_jump:device=can,t_s=4,jump_s=-0.25", "clock_jump:device=can,t_s=6,jump_s=1"])
    states = [fs.gnss_fix_state(int(x)) for x in t]
    assert states[19:21] == ["ok", "lost"] and states[49:51] == ["lost", "reacquiring"]
    assert states[59:61] == ["reacquiring", "ok"]
    keep = fs.serial_keep_fn("gnss")(t)
    assert np.flatnonzero(~keep).tolist() == list(range(10, 15))
    assert fs.serial_keep_fn("imu") is None
    off = fs.clock_offset_ns("can", t)
    assert off[39] == 0 and off[40] == -250 * MS and off[60] == 750 * MS
    assert fs.clock_offset_ns("imu", t) is None


def test_frozen_signal_holds_its_last_value_across_blocks():
    fs = FaultSet(["frozen_can_signal:signal=wheel_speed_radps_2,t_s=0.005,duration_s=0.004"], dbc=DBC)
    fields = ("wheel_speed_radps_1", "wheel_speed_radps_2")
    values = np.arange(20, dtype=float).reshape(10, 2)
    t = np.arange(10) * MS
    a, b = values[:6].copy(), values[6:].copy()
    fs.can_values("VDPS_WheelSpeedFront", fields, t[:6], a)
    fs.can_values("VDPS_WheelSpeedFront", fields, t[6:], b)
    got = np.vstack((a, b))
    assert got[:, 0].tolist() == values[:, 0].tolist()
    assert got[:, 1].tolist() == [1, 3, 5, 7, 9, 9, 9, 9, 9, 19]


def test_dropped_frames_are_seeded_per_fault():
    t = np.arange(20_000) * MS
    a = FaultSet(["dropped_frames:fraction=0.1"], seed=1).can_keep("VDPS_SteerAngle", t)
    b = FaultSet(["dropped_frames:fraction=0.1"], seed=1).can_keep("VDPS_SteerAngle", t)
    c = FaultSet(["gyro_spike", "dropped_frames:fraction=0.1"], seed=1).can_keep("VDPS_SteerAngle", t)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)  # a fault's stream is tied to its position in the list
    # binomial: 2000 expected, sd 42
    assert abs((~a).sum() - 2000) < 200
    only = FaultSet(["dropped_frames:fraction=1,message=VDPS_Suspension,t_s=0.01,duration_s=0.005"], seed=1)
    assert only.can_keep("VDPS_SteerAngle", t) is None
    assert np.flatnonzero(~only.can_keep("VDPS_Suspension", t[:100])).tolist() == list(range(10, 15))


# ------------------------------------------------------------------------------------ drives
def drive(faults, profile=PROFILE, duration_s=3.0):
    buf = io.BytesIO()
    summary = Drive(STRAIGHT, profile=profile, seed=4, faults=faults, duration_s=duration_s).run(buf)
    buf.seek(0)
    r = RecordingReader(buf)
    out = {"summary": summary, "reader": r, "can": {}, "imu": [], "gnss": [], "chunks": {}}
    can = VdpsCanDecoder()
    for _, msg in r.iter_raw_can():
        for s in can.decode_message(msg):
            out["can"].setdefault(s.kind, []).append(s)
    imu, framer, nmea = ImuDecoder(), LineFramer(115200), NmeaDecoder()
    for dev, t, data in r.iter_raw_serial():
        out["chunks"].setdefault(dev, []).append(t)
        if dev == "imu":
            out["imu"] += imu.feed(t, data)
        else:
            for tl, line in framer.feed(t, data):
                out["gnss"] += [(tl, line, s) for s in nmea.feed_line(tl, line)]
    out["imu"] += imu.flush()
    out["decoders"] = {"can": can, "imu": imu, "nmea": nmea}
    return out


def test_gnss_outage_in_a_drive():
    d = drive(["gnss_outage:t_s=1.0,duration_s=0.8,reacquire_s=0.6"], duration_s=3.0)
    by_epoch = {}
    for tl, line, s in d["gnss"]:
        by_epoch.setdefault(round(tl / (200 * MS)) * 200 * MS, []).append(s)
    assert len(by_epoch) == 16
    for t, samples in by_epoch.items():
        kinds = [s.kind for s in samples]
        q = samples[0].fields["gnss_fix_quality"]
        if 1.0 * S_ <= t < 1.8 * S_:
            assert kinds == ["gnss_pos", "gnss_vel"] and q == 0 and not samples[0].valid
            assert "gnss_lat_deg" not in samples[0].fields and "gnss_speed_mps" not in samples[1].fields
        else:
            assert kinds == ["gnss_pos", "gnss_vel", "gnss_att"] and samples[0].valid
            assert q == (1 if 1.8 * S_ <= t < 2.4 * S_ else 4)
    assert d["decoders"]["nmea"].counters["rejected"] == 0


def test_gyro_spike_in_a_drive():
    d = drive(["gyro_spike:t_s=1.5,duration_s=0.004,axis=x,amplitude_degps=300"], profile=PROFILE.zero_noise(),
              duration_s=2.0)
    w = {int(s.fields["seq_counter"]): s.fields["angular_rate_radps_x"] for s in d["imu"]}
    base = np.median([w[k] for k in range(1400, 1500)])
    spiked = [k for k, v in w.items() if abs(v - base) > math.radians(100)]
    assert spiked == [1500, 1501, 1502, 1503]
    assert w[1500] - base == pytest.approx(math.radians(300), rel=1e-3)


def test_frozen_can_signal_in_a_drive():
    d = drive(["frozen_can_signal:signal=wheel_speed_radps_1,t_s=1.0,duration_s=1.0"], duration_s=2.5)
    front = d["can"]["wheel_speed"][0::2]
    assert all("wheel_speed_radps_1" in s.fields for s in front)
    v1 = np.array([s.fields["wheel_speed_radps_1"] for s in front])
    v2 = np.array([s.fields["wheel_speed_radps_2"] for s in front])
    win = slice(1000, 2000)  # frames sampled at 1.000 .. 1.999 s
    assert np.all(v1[win] == v1[999]) and np.std(v1[:999]) > 0.02 and np.std(v1[2000:]) > 0.02
    assert np.std(v2[win]) > 0.02  # the other wheel keeps its noise
    c = d["decoders"]["can"].counters["VDPS_WheelSpeedFront"]
    assert c["lost_frames"] == 0 and c["counter_repeat"] == 0  # the counter cannot reveal it


def test_dropped_frames_in_a_drive():
    d = drive(["dropped_frames:fraction=0.2,message=VDPS_Suspension"], duration_s=2.0)
    c = d["decoders"]["can"].counters
    lost = 2001 - c["VDPS_Suspension"]["accepted"]
    assert abs(lost - 400) < 4 * math.sqrt(2001 * 0.2 * 0.8)
    # the decoder finds them by the counters (except losses at the very end)
    assert lost - 5 <= c["VDPS_Suspension"]["lost_frames"] <= lost
    assert c["VDPS_WheelSpeedFront"]["lost_frames"] == 0 and c["VDPS_WheelSpeedFront"]["accepted"] == 2001


def test_serial_disconnect_in_a_drive():
    d = drive(["serial_disconnect:device=imu,t_s=1.0,duration_s=0.5"], duration_s=2.5)
    chunks = np.array(d["chunks"]["imu"])
    assert not np.any((chunks >= 1.0 * S_) & (chunks < 1.5 * S_))
    assert np.any(chunks >= 1.5 * S_) and np.any(chunks < 1.0 * S_)
    ks = [int(s.fields["seq_counter"]) for s in d["imu"]]
    missing = sorted(set(range(2501)) - set(ks))
    # packets whose bytes started before 1.0 s or ended after 1.5 s are cut, the rest never sent
    assert missing[0] in (999, 1000) and missing[-1] in (1499, 1500) and len(missing) in (500, 501, 502)
    assert d["decoders"]["imu"].counters["seq_gaps"] == len(missing)
    assert len(d["gnss"]) == 39  # the other device is untouched


def test_clock_jumps_in_a_drive():
    d = drive(["clock_jump:device=imu,t_s=1.0,jump_s=0.25", "clock_jump:device=can,t_s=1.5,jump_s=-0.5"],
              profile=PROFILE.zero_noise(), duration_s=2.0)
    imu = d["decoders"]["imu"]
    assert imu.last_packet.sample_time_fine == (2000 + 250) * 10  # 100 us ticks
    steer_t = [s.t_ns for s in d["can"]["steer"]]
    back = [i for i in range(1, len(steer_t)) if steer_t[i] < steer_t[i - 1]]
    assert len(back) == 1 and steer_t[back[0] - 1] - steer_t[back[0]] == pytest.approx(0.5 * S_ - 10 * MS, abs=MS)
    assert d["summary"].time_backwards.get("/raw/can/vdps", 0) >= 1
