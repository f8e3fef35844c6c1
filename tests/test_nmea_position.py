"""Tests of codecs.nmea.position: GGA, RMC and VTG round trips (checked also by pynmeagps, an
independent parser) and the GGA/RMC/HDT sentences of the golden real OxTS file.
"""

from __future__ import annotations

import datetime as dt

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.codecs.nmea.parse import parse_sentence
from vdps_hil.codecs.nmea.position import format_gga, format_rmc, format_vtg
from vdps_hil.codecs.nmea.sentence import KNOT_MPS, PRINT_DECIMALS, ParsedSentence
from vdps_hil.conventions import heading_to_yaw

from nmea_checks import (
    angle_tol_rad, independent, lats, lons, ok, oxts_lines, time_close, times, wrapdiff, yaws,
)


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


# ---------------------------------------------------------------------------------------------
# Golden: the real OxTS file
# ---------------------------------------------------------------------------------------------
def test_oxts_gga_rmc_hdt_match_pynmeagps(real_data):
    n = {"GGA": 0, "RMC": 0, "HDT": 0}
    for ln in oxts_lines(real_data):
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
