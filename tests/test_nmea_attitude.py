"""Tests of codecs.nmea.attitude: HDT/THS and every attitude layout round trip (checked also by
pynmeagps), the two-antenna baselines, the PASHR sentences of the golden real OxTS file and the
attitude sign table.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.codecs.nmea.attitude import format_attitude, format_hdt, format_ths
from vdps_hil.codecs.nmea.parse import parse_sentence
from vdps_hil.codecs.nmea.sentence import ATTITUDE_LAYOUTS, PRINT_DECIMALS, ParsedSentence
from vdps_hil.conventions import ATTITUDE_SIGN, heading_to_yaw

from nmea_checks import (
    angle_tol_rad, independent, ok, oxts_lines, time_close, times, wrapdiff, yaws,
)


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


# ---------------------------------------------------------------------------------------------
# Golden: the real OxTS file
# ---------------------------------------------------------------------------------------------
def test_oxts_every_pashr_decodes_to_the_printed_numbers(real_data):
    lines = oxts_lines(real_data)
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


def test_oxts_roll_sign_agrees_with_the_turn(real_data):
    # Cross-check of the PASHR roll sign on real data: the car turns right (yaw rate < 0) and the
    # body rolls out of the turn (left side down, phi < 0), harder when the turn is tighter, so
    # the paper roll must rise and fall with the paper yaw rate.
    rows = [parse_sentence(ln) for ln in oxts_lines(real_data) if ln.startswith(b"$PASHR")]
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
