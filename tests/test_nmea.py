"""Tests of codecs.nmea: round trips of every sentence kind (checked also by pynmeagps, an
independent parser), the golden real OxTS file, the attitude sign table, and fuzzing."""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pynmeagps import NMEAReader, VALCKSUM

from vdps_hil.bus.samples import FIELDS
from vdps_hil.codecs.framing import LineFramer, transmission_time_ns
from vdps_hil.codecs.nmea import (
    ATTITUDE_LAYOUTS, KNOT_MPS, PRINT_DECIMALS, REJECT_REASONS, NmeaDecoder, ParsedSentence,
    Reject, format_attitude, format_gga, format_hdt, format_rmc, format_ths, format_vtg,
    nmea_checksum, parse_sentence,
)
from vdps_hil.conventions import ATTITUDE_SIGN, AttitudeSign, heading_to_yaw

OXTS = "gpsd_oxts_rst39/rst39.nmea"

times = st.floats(0.0, 86399.99)
yaws = st.floats(-math.pi, math.pi - 1e-9)
lats = st.floats(-89.9, 89.9)
lons = st.floats(-179.9, 179.9)


def angle_tol_rad(decimals: int) -> float:
    """Half a unit of the last printed digit of an angle in degrees, in radians (+ float eps)."""
    return math.radians(0.5 * 10.0 ** -decimals) + 1e-12


def wrapdiff(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2.0 * math.pi) - math.pi)


def ok(line) -> ParsedSentence:
    r = parse_sentence(line)
    assert isinstance(r, ParsedSentence), r
    assert line.endswith(b"\r\n")
    for name in r.fields:
        assert name in FIELDS
    return r


def independent(line):
    """pynmeagps decodes the sentence, validating the checksum."""
    return NMEAReader.parse(line, validate=VALCKSUM)


def time_close(a: float, b: float, decimals: int) -> bool:
    d = abs(a - b) % 86400.0
    return min(d, 86400.0 - d) <= 0.5 * 10.0 ** -decimals + 1e-6


# ---------------------------------------------------------------------------------------------
# Round trips, with pynmeagps as the independent parser
# ---------------------------------------------------------------------------------------------

@settings(max_examples=150, deadline=None, derandomize=True)
@given(t=times, lat=lats, lon=lons, alt=st.floats(-400.0, 9000.0), q=st.integers(1, 6),
       sats=st.integers(0, 40), hdop=st.floats(0.0, 50.0),
       geoid=st.one_of(st.none(), st.floats(-100.0, 100.0)))
def test_gga_round_trip(t, lat, lon, alt, q, sats, hdop, geoid):
    line = format_gga(t, lat, lon, alt, fix_quality=q, num_sats=sats, hdop=hdop, geoid_sep_m=geoid)
    r = ok(line)
    d = PRINT_DECIMALS["GGA"]
    f = r.fields
    assert r.sentence == "GGA" and r.sample_kind == "gnss_pos" and r.valid
    tol_deg = 0.5 * 10.0 ** -d["lat_min"] / 60.0 + 1e-12
    assert abs(f["gnss_lat_deg"] - lat) <= tol_deg
    assert abs(f["gnss_lon_deg"] - lon) <= tol_deg
    assert abs(f["gnss_alt_m"] - alt) <= 0.5e-3 + 1e-9
    assert abs(f["gnss_hdop"] - hdop) <= 0.05 + 1e-9
    assert f["gnss_num_sats"] == sats and f["gnss_fix_quality"] == q
    assert (geoid is None) == ("gnss_geoid_sep_m" not in f)
    if geoid is not None:
        assert abs(f["gnss_geoid_sep_m"] - geoid) <= 0.5e-3 + 1e-9
    assert time_close(r.utc_time_s, t, d["time"])
    m = independent(line)
    assert f["gnss_lat_deg"] == pytest.approx(m.lat, abs=1e-9)
    assert f["gnss_lon_deg"] == pytest.approx(m.lon, abs=1e-9)
    assert f["gnss_alt_m"] == pytest.approx(m.alt, abs=1e-9)
    assert f["gnss_hdop"] == pytest.approx(m.HDOP, abs=1e-9)
    assert (f["gnss_num_sats"], f["gnss_fix_quality"]) == (m.numSV, m.quality)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(t=times, lat=lats, lon=lons, v=st.floats(0.0, 80.0), course=yaws,
       day=st.dates(dt.date(2000, 1, 1), dt.date(2068, 12, 31)))  # ddmmyy: 2-digit year
def test_rmc_round_trip(t, lat, lon, v, course, day):
    line = format_rmc(t, lat, lon, v, course, date=day)
    r = ok(line)
    f = r.fields
    assert r.sentence == "RMC" and r.sample_kind == "gnss_vel" and r.valid
    assert abs(f["gnss_speed_mps"] - v) <= 0.5e-3 * KNOT_MPS + 1e-9
    assert wrapdiff(f["gnss_course_rad"], course) <= angle_tol_rad(PRINT_DECIMALS["RMC"]["course"])
    assert abs(r.extras["lat_deg"] - lat) <= 0.5e-6 / 60.0 + 1e-12
    m = independent(line)
    assert m.status == "A" and m.date == day
    assert f["gnss_speed_mps"] == pytest.approx(m.spd * KNOT_MPS, abs=1e-9)
    assert wrapdiff(f["gnss_course_rad"], heading_to_yaw(m.cog)) <= 1e-12


@settings(max_examples=100, deadline=None, derandomize=True)
@given(v=st.floats(0.0, 80.0), course=yaws)
def test_vtg_round_trip(v, course):
    line = format_vtg(course, v)
    r = ok(line)
    assert r.sentence == "VTG" and r.sample_kind == "gnss_vel"
    assert abs(r.fields["gnss_speed_mps"] - v) <= 0.5e-3 * KNOT_MPS + 1e-9
    assert wrapdiff(r.fields["gnss_course_rad"], course) <= angle_tol_rad(3)
    m = independent(line)
    assert r.fields["gnss_speed_mps"] == pytest.approx(m.sogn * KNOT_MPS, abs=1e-9)
    assert m.sogk == pytest.approx(v * 3.6, abs=0.5e-3 + 1e-9)
    assert wrapdiff(r.fields["gnss_course_rad"], heading_to_yaw(m.cogt)) <= 1e-12


@settings(max_examples=100, deadline=None, derandomize=True)
@given(yaw=yaws)
def test_hdt_and_ths_round_trip(yaw):
    for line, key in ((format_hdt(yaw), "headingT"), (format_ths(yaw), "headt")):
        r = ok(line)
        assert r.sample_kind == "gnss_att" and r.has_roll is False and r.valid
        assert wrapdiff(r.fields["gnss_yaw_rad"], yaw) <= angle_tol_rad(2)
        m = independent(line)
        assert wrapdiff(r.fields["gnss_yaw_rad"], heading_to_yaw(getattr(m, key))) <= 1e-12


# pynmeagps attribute names of each attitude layout: (heading, pitch, roll)
PYNMEA_KEYS = {"PASHR": ("trueHdg", "pitch", "roll"), "PASHR,HPR": ("trueHdg", "pitch", "roll"),
               "HPR": ("heading", "pitch", "roll"), "PTNL,AVR": ("yaw", "tilt", "roll")}

# (layout, generated slots, decoder baseline): every slot combination a receiver prints
ATT_CASES = [("PASHR", "pr", "along"),
             ("PASHR,HPR", "p", "along"), ("PASHR,HPR", "r", "across"), ("PASHR,HPR", "pr", "both"),
             ("HPR", "p", "along"), ("HPR", "r", "across"), ("HPR", "pr", "both"),
             ("PTNL,AVR", "p", "along"), ("PTNL,AVR", "r", "along")]


@pytest.mark.parametrize("layout,slots,baseline", ATT_CASES)
@settings(max_examples=60, deadline=None, derandomize=True)
@given(t=times, yaw=yaws, pitch=st.floats(-1.5, 1.5), roll=st.floats(-1.5, 1.5),
       sig=st.tuples(*[st.floats(0.0, 0.2)] * 3))
def test_attitude_round_trip(layout, slots, baseline, t, yaw, pitch, roll, sig):
    line = format_attitude(layout, utc_time_s=t, yaw_rad=yaw,
                           pitch_rad=pitch if "p" in slots else None,
                           roll_rad=roll if "r" in slots else None,
                           yaw_sigma_rad=sig[0], pitch_sigma_rad=sig[1], roll_sigma_rad=sig[2])
    r = parse_sentence(line, dual_antenna_baseline=baseline)
    assert isinstance(r, ParsedSentence), r
    d = PRINT_DECIMALS[layout]
    f = r.fields
    assert r.sentence == layout and r.sample_kind == "gnss_att" and r.valid
    assert r.has_roll == ("r" in slots)
    assert ("gnss_pitch_rad" in f) == ("p" in slots)
    assert wrapdiff(f["gnss_yaw_rad"], yaw) <= angle_tol_rad(d["heading"])
    if "p" in slots:
        assert abs(f["gnss_pitch_rad"] - pitch) <= angle_tol_rad(d["pitch"])
    if "r" in slots:
        assert abs(f["gnss_roll_rad"] - roll) <= angle_tol_rad(d["roll"])
    assert time_close(r.utc_time_s, t, d["time"])
    if layout == "PASHR":
        names = ("gnss_yaw_sigma_rad", "gnss_pitch_sigma_rad", "gnss_roll_sigma_rad")
        for name, s in zip(names, sig):
            assert abs(f[name] - s) <= angle_tol_rad(d["sigma"])
    # the independent parser reads the same printed numbers; our conventions then map them
    m = independent(line)
    kh, kp, kr = PYNMEA_KEYS[layout]
    sgn = ATTITUDE_SIGN[layout]
    assert wrapdiff(f["gnss_yaw_rad"], heading_to_yaw(getattr(m, kh) % 360.0)) <= 1e-12
    if "p" in slots:
        want = sgn.pitch_to_paper * math.radians(getattr(m, kp))
        assert f["gnss_pitch_rad"] == pytest.approx(want, abs=1e-12)
    if "r" in slots:
        want = sgn.roll_to_paper * math.radians(getattr(m, kr))
        assert f["gnss_roll_rad"] == pytest.approx(want, abs=1e-12)
    if layout == "PASHR":
        assert f["gnss_roll_sigma_rad"] == pytest.approx(math.radians(m.rollAcc), abs=1e-12)
        assert f["gnss_yaw_sigma_rad"] == pytest.approx(math.radians(m.hdgAcc), abs=1e-12)


def test_dual_antenna_baseline_selects_the_measured_slot():
    # one baseline along the car: the roll slot (even if printed) is not a measurement
    line = format_attitude("HPR", utc_time_s=1.0, yaw_rad=0.1, pitch_rad=0.05, roll_rad=0.02)
    along = parse_sentence(line)
    assert "gnss_roll_rad" not in along.fields and along.has_roll is False
    across = parse_sentence(line, dual_antenna_baseline="across")
    assert "gnss_pitch_rad" not in across.fields and across.has_roll is True
    both = parse_sentence(line, dual_antenna_baseline="both")
    assert {"gnss_pitch_rad", "gnss_roll_rad"} <= set(both.fields)


def test_sign_override_flips_the_printed_pitch():
    line = format_attitude("HPR", utc_time_s=1.0, yaw_rad=0.1, pitch_rad=0.05)
    flipped = AttitudeSign("HPR", -1.0, 1.0, False, "test: receiver configured nose-down")
    dec = NmeaDecoder("gnss", sign_overrides={"HPR": flipped})
    s = dec.feed_line(0, line)[0]
    assert s.fields["gnss_pitch_rad"] == pytest.approx(-0.05, abs=angle_tol_rad(2))
    with pytest.raises(ValueError):
        NmeaDecoder("gnss", sign_overrides={"XYZ": flipped})


def test_receiver_invalid_flags_give_invalid_samples():
    dec = NmeaDecoder("gnss")
    no_fix = b"$GPGGA,123519.00,,,,,0,00,99.9,,,,,,*"
    no_fix += b"%02X\r\n" % nmea_checksum(no_fix[1:-1])
    s = dec.feed_line(1, no_fix)
    assert len(s) == 1 and s[0].valid is False and s[0].fields["gnss_fix_quality"] == 0.0
    s = dec.feed_line(2, format_rmc(1.0, 1.0, 2.0, 3.0, 0.1, status="V"))
    assert s[0].valid is False
    s = dec.feed_line(3, format_ths(0.3, mode="V"))
    assert s[0].valid is False
    assert dec.counters["invalid_samples"] == 3


def test_missing_checksum_rejected_unless_lenient():
    line = b"$GPHDT,25.50,T\r\n"
    assert parse_sentence(line) == Reject("missing_checksum", "no '*hh'")
    r = parse_sentence(line, lenient_checksum=True)
    assert isinstance(r, ParsedSentence)
    assert r.fields["gnss_yaw_rad"] == pytest.approx(heading_to_yaw(25.5))
    # a present but wrong checksum is rejected even when lenient
    assert parse_sentence(b"$GPHDT,25.50,T*00", lenient_checksum=True).reason == "bad_checksum"


@pytest.mark.parametrize("line,reason", [
    (b"", "empty"),
    (b"   \r\n", "empty"),
    (b"\xff\xfe$GPHDT,1,T*00\x80", "not_ascii"),
    ("$GPHDT,25.50,T*37\u00e9", "not_ascii"),
    (b"hello world", "no_start"),
    (b"$GPHDT,25.50,T*3", "malformed_checksum"),
    (b"$GPHDT,25.50,T*3G", "malformed_checksum"),
    (b"$GPHDT,25.50,T*37*37", "malformed_checksum"),
    (b"$GPHDT,25.50,T*38", "bad_checksum"),
    (b"$GPZDA,204133.000,19,02,2014,,*5C", "unsupported"),
    (b"$PASHR,POS,0*00", "bad_checksum"),
])
def test_rejects_by_reason(line, reason):
    r = parse_sentence(line)
    assert isinstance(r, Reject) and r.reason == reason, r


def _with_cs(body: str) -> bytes:
    return f"${body}*{nmea_checksum(body):02X}\r\n".encode()


@pytest.mark.parametrize("body,reason", [
    ("GPHDT", "truncated"),
    ("GPGGA,1,2,N", "truncated"),
    ("GPHDT,,T", "empty_field"),
    ("PASHR,204132.000,,T,+00.39,-00.79,-00.84,0.151,0.075,0.555,1,0", "empty_field"),
    ("GPHDT,abc,T", "bad_field"),
    ("GPHDT,1_0,T", "bad_field"),
    ("GPHDT,nan,T", "bad_field"),
    ("GPHDT,400.0,T", "bad_field"),
    ("GPGGA,250000,4205.7,N,08802.0,W,1,08,1.0,221.9,M,,,,", "bad_field"),
    ("GPGGA,204132.10,4265.7,N,08802.0,W,1,08,1.0,221.9,M,,,,", "bad_field"),
    ("GPRMC,204132.00,X,4205.7,N,08802.0,W,9.4,21.4,190214,,,D", "bad_field"),
    ("PTNL,AVR,212405.20,+52.1531,Yaw,-0.0806,Roll,,,12.575,3,1.4,16", "bad_field"),
    ("PASHR,ATT,1,2,3", "unsupported"),
    ("GPGSV,3,1,11", "unsupported"),
])
def test_structural_rejects(body, reason):
    r = parse_sentence(_with_cs(body))
    assert isinstance(r, Reject) and r.reason == reason, r


def test_garbage_before_dollar_is_skipped_and_counted():
    line = format_hdt(0.7)
    dec = NmeaDecoder("gnss")
    out = dec.feed_line(5, b"\x00\xff#junk" + line)
    assert len(out) == 1
    assert out[0].fields["gnss_yaw_rad"] == pytest.approx(0.7, abs=angle_tol_rad(2))
    assert dec.counters["garbage_prefix"] == 1


def test_generated_sentences_have_receiver_precision():
    # printed like the real receivers: the OxTS file's own figures, Unicore/ComNav, Trimble
    assert format_attitude("PASHR", utc_time_s=74492.0, yaw_rad=heading_to_yaw(10.51),
                           pitch_rad=math.radians(-0.79), roll_rad=math.radians(0.39),
                           roll_sigma_rad=math.radians(0.151), pitch_sigma_rad=math.radians(0.075),
                           yaw_sigma_rad=math.radians(0.555), heave_m=-0.84, quality=1,
                           ins_status=0) == \
        b"$PASHR,204132.000,010.51,T,+00.39,-00.79,-00.84,0.151,0.075,0.555,1,0*03\r\n"
    assert format_hdt(heading_to_yaw(25.5)) == b"$GPHDT,25.50,T*37\r\n"
    gga = format_gga(74492.1, 42.0 + 5.733715 / 60.0, -(88.0 + 2.040978 / 60.0), 221.921,
                     fix_quality=2, num_sats=8, hdop=1.0, diff_age_s=3.0, diff_station=138)
    assert gga.startswith(
        b"$GPGGA,204132.10,4205.733715,N,08802.040978,W,2,08,1.0,221.921,M,,,3.0,0138*")


def test_heading_never_prints_360():
    line = format_hdt(heading_to_yaw(359.999))
    assert line.startswith(b"$GPHDT,0.00,T*")


# ---------------------------------------------------------------------------------------------
# Golden: the real OxTS file
# ---------------------------------------------------------------------------------------------

def _oxts_lines(real_data):
    return (real_data / OXTS).read_bytes().splitlines()


def test_oxts_every_pashr_decodes_to_the_printed_numbers(real_data):
    lines = _oxts_lines(real_data)
    pashr = [ln for ln in lines if ln.startswith(b"$PASHR")]
    assert len(pashr) == 100
    sgn = ATTITUDE_SIGN["PASHR"]
    for ln in pashr:
        r = parse_sentence(ln)
        assert isinstance(r, ParsedSentence) and r.sentence == "PASHR" and r.has_roll
        # the printed numbers, read by splitting the text (no parser involved)
        f = ln.split(b"*")[0].decode().split(",")
        heading, roll, pitch = float(f[2]), float(f[4]), float(f[5])
        acc_r, acc_p, acc_h = float(f[7]), float(f[8]), float(f[9])
        assert r.fields["gnss_yaw_rad"] == pytest.approx(math.radians(90.0 - heading), abs=1e-12)
        assert r.fields["gnss_roll_rad"] == sgn.roll_to_paper * math.radians(roll)
        assert r.fields["gnss_pitch_rad"] == sgn.pitch_to_paper * math.radians(pitch)
        assert r.fields["gnss_roll_sigma_rad"] == math.radians(acc_r)
        assert r.fields["gnss_pitch_sigma_rad"] == math.radians(acc_p)
        assert r.fields["gnss_yaw_sigma_rad"] == math.radians(acc_h)
        assert r.extras["heave_m"] == float(f[6])
        # pynmeagps reads the same values
        m = independent(ln)
        assert (m.trueHdg, m.roll, m.pitch) == (heading, roll, pitch)
        assert (m.rollAcc, m.pitchAcc, m.hdgAcc) == (acc_r, acc_p, acc_h)
        assert r.utc_time_s == pytest.approx(
            m.utctime.hour * 3600 + m.utctime.minute * 60 + m.utctime.second
            + m.utctime.microsecond * 1e-6, abs=1e-9)


def test_oxts_gga_rmc_hdt_match_pynmeagps(real_data):
    n = {"GGA": 0, "RMC": 0, "HDT": 0}
    for ln in _oxts_lines(real_data):
        r = parse_sentence(ln)
        if not isinstance(r, ParsedSentence) or r.sentence not in n:
            continue
        n[r.sentence] += 1
        m = independent(ln)
        if r.sentence == "GGA":
            assert r.fields["gnss_lat_deg"] == pytest.approx(m.lat, abs=1e-9)
            assert r.fields["gnss_lon_deg"] == pytest.approx(m.lon, abs=1e-9)
            assert r.fields["gnss_alt_m"] == m.alt
            assert (r.fields["gnss_fix_quality"], r.fields["gnss_num_sats"]) == (m.quality, m.numSV)
            assert "gnss_geoid_sep_m" not in r.fields  # printed empty in this file
        elif r.sentence == "RMC":
            assert r.fields["gnss_speed_mps"] == pytest.approx(m.spd * KNOT_MPS, abs=1e-12)
            assert r.fields["gnss_course_rad"] == pytest.approx(heading_to_yaw(m.cog), abs=1e-12)
        else:
            assert r.fields["gnss_yaw_rad"] == pytest.approx(heading_to_yaw(m.headingT), abs=1e-12)
    assert n == {"GGA": 40, "RMC": 4, "HDT": 4}


def test_oxts_through_framer_and_decoder(real_data, rng):
    raw = (real_data / OXTS).read_bytes()
    cuts = np.sort(rng.choice(len(raw), size=60, replace=False))
    framer, dec = LineFramer(115200), NmeaDecoder("gnss")
    samples = []
    for a, b in zip([0, *cuts], [*cuts, len(raw)]):
        # each read returns when its last byte has arrived (continuous sending at 115200 baud)
        for t_line, line in framer.feed(transmission_time_ns(int(b), 115200), raw[a:b]):
            samples += dec.feed_line(t_line, line)
    c = dec.counters
    assert c["sentence_PASHR"] == 100 and c["sentence_GGA"] == 40
    assert c["sentence_RMC"] == 4 and c["sentence_HDT"] == 4
    assert c["unsupported"] == 4          # the four $GPZDA
    assert c["reject_no_start"] == 6      # the six '#' comment lines of the gpsd test file
    assert c["rejected"] == 6 and c["reject_internal_error"] == 0
    kinds = [s.kind for s in samples]
    assert kinds.count("gnss_att") == 104 and kinds.count("gnss_pos") == 40
    assert all(s.valid for s in samples)
    assert all(b.t_ns > a.t_ns for a, b in zip(samples, samples[1:]))
    # each line's time is the arrival of its own line end (+-1 ns of rounding), whatever the
    # chunking
    decoded_ends, start = [], 0
    for i, byte in enumerate(raw):
        if byte == 0x0A:
            if raw[start:i].startswith((b"$PASHR", b"$GPGGA", b"$GPRMC", b"$GPHDT")):
                decoded_ends.append(i)
            start = i + 1
    expected = [transmission_time_ns(e + 1, 115200) for e in decoded_ends]
    assert len(expected) == len(samples)
    assert max(abs(s.t_ns - e) for s, e in zip(samples, expected)) <= 1


def test_oxts_roll_sign_agrees_with_the_turn(real_data):
    # Cross-check of the PASHR roll sign on real data: the car turns right (yaw rate < 0) and the
    # body rolls out of the turn (left side down, phi < 0), harder when the turn is tighter, so
    # the paper roll must rise and fall with the paper yaw rate.
    rows = [parse_sentence(ln) for ln in _oxts_lines(real_data) if ln.startswith(b"$PASHR")]
    t = np.array([r.utc_time_s for r in rows])
    yaw = np.unwrap([r.fields["gnss_yaw_rad"] for r in rows])
    roll = np.array([r.fields["gnss_roll_rad"] for r in rows])
    r_yaw = np.gradient(yaw, t)
    assert np.all(r_yaw < 0.0)
    assert np.corrcoef(r_yaw, roll)[0, 1] > 0.5


def test_attitude_sign_table_covers_every_layout():
    assert set(ATTITUDE_SIGN) == set(ATTITUDE_LAYOUTS)
    for key, s in ATTITUDE_SIGN.items():
        assert s.sentence == key
        assert s.pitch_to_paper in (-1.0, 1.0) and s.roll_to_paper in (-1.0, 1.0)
        assert len(s.source) > 80
    assert ATTITUDE_SIGN["PASHR"].has_roll is True
    assert not any(ATTITUDE_SIGN[k].has_roll for k in ("PASHR,HPR", "HPR", "PTNL,AVR"))


# ---------------------------------------------------------------------------------------------
# Fuzz: garbage and mutated sentences interleaved with valid ones
# ---------------------------------------------------------------------------------------------

def _valid_sentences(rng, n):
    out = []
    for k in range(n):
        t = float(rng.uniform(0, 86399))
        yaw = float(rng.uniform(-math.pi, math.pi))
        p, r = (float(x) for x in rng.uniform(-0.3, 0.3, 2))
        kind = k % 9
        if kind == 0:
            lat, lon = float(rng.uniform(-80, 80)), float(rng.uniform(-170, 170))
            out.append(format_gga(t, lat, lon, float(rng.uniform(0, 3000)),
                                  geoid_sep_m=float(rng.uniform(-50, 50))))
        elif kind == 1:
            out.append(format_rmc(t, 10.0, 20.0, float(rng.uniform(0, 40)), yaw))
        elif kind == 2:
            out.append(format_vtg(yaw, float(rng.uniform(0, 40))))
        elif kind == 3:
            out.append(format_hdt(yaw))
        elif kind == 4:
            out.append(format_ths(yaw))
        else:
            layout = ATTITUDE_LAYOUTS[kind - 5]
            out.append(format_attitude(layout, utc_time_s=t, yaw_rad=yaw, pitch_rad=p,
                                       roll_rad=r if layout == "PASHR" else None,
                                       yaw_sigma_rad=0.01, pitch_sigma_rad=0.01,
                                       roll_sigma_rad=0.01))
    return out


def _mutate(rng, line: bytes) -> bytes:
    """A corruption an 8-bit XOR checksum always detects: substitute, delete or truncate."""
    text = line.rstrip(b"\r\n")
    star = text.index(b"*")
    op = rng.integers(3)
    if op == 0:  # substitute one body character by a different printable one (not $ or !)
        i = int(rng.integers(1, star))
        choices = [c for c in range(0x20, 0x7F) if c not in (text[i], 0x24, 0x21)]
        new = text[:i] + bytes([choices[int(rng.integers(len(choices)))]]) + text[i + 1:]
    elif op == 1:  # delete one body character
        i = int(rng.integers(1, star))
        new = text[:i] + text[i + 1:]
    else:  # cut short anywhere before the end
        new = text[:int(rng.integers(1, len(text)))]
    return new + b"\r\n"


def test_fuzz_line_level(rng):
    valid = _valid_sentences(rng, 300)
    items = [("valid", s) for s in valid]
    items += [("bad", _mutate(rng, valid[int(rng.integers(len(valid)))])) for _ in range(600)]
    items += [("bad", rng.bytes(int(rng.integers(0, 120)))) for _ in range(300)]
    items += [("prefixed", rng.bytes(int(rng.integers(1, 40))).replace(b"$", b"").replace(b"!", b"")
               + valid[int(rng.integers(len(valid)))]) for _ in range(100)]
    order = rng.permutation(len(items))
    dec = NmeaDecoder("gnss")
    n_valid = 0
    for t, k in enumerate(order):
        tag, line = items[k]
        out = dec.feed_line(t, line)  # must never raise
        if tag == "bad":
            assert out == [], line
        else:
            n_valid += 1
            clean = line[max(line.rfind(b"$"), 0):]
            assert len(out) == 1 and out[0].fields == dict(parse_sentence(clean).fields)
            assert out[0].t_ns == t
    c = dec.counters
    assert c["samples"] == n_valid == 400
    assert c["rejected"] + c["unsupported"] == 900
    assert c["lines"] == c["samples"] + c["rejected"] + c["unsupported"]
    assert c["reject_internal_error"] == 0
    assert sum(c[f"reject_{r}"] for r in REJECT_REASONS if r != "unsupported") == c["rejected"]
    assert c["reject_bad_checksum"] > 100 and c["reject_missing_checksum"] > 50
    assert c["reject_not_ascii"] > 50


def test_fuzz_byte_stream_through_framer(rng):
    # Valid sentences with random garbage (any bytes, newlines included) between them, cut into
    # random chunks: every valid sentence comes out, in order, and nothing else does.
    valid = _valid_sentences(rng, 400)
    stream = bytearray()
    for s in valid:
        if rng.random() < 0.5:
            stream += rng.bytes(int(rng.integers(1, 300)))
        if rng.random() < 0.2:
            stream += _mutate(rng, s)
        stream += s
    stream = bytes(stream)
    cuts = np.sort(rng.choice(len(stream), size=len(stream) // 40, replace=False))
    framer, dec = LineFramer(115200, max_line_bytes=256), NmeaDecoder("gnss")
    got = []
    for k, (a, b) in enumerate(zip([0, *cuts], [*cuts, len(stream)])):
        for t_line, line in framer.feed(k * 1000, stream[a:b]):
            got += dec.feed_line(t_line, line)
    expected = [dict(parse_sentence(s).fields) for s in valid]
    assert [dict(s.fields) for s in got] == expected
    assert dec.counters["reject_internal_error"] == 0
    assert dec.counters["rejected"] > 0
