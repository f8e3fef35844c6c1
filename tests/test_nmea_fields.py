"""Tests of codecs.nmea.fields: the generators print with the precision of real receivers, a
heading never prints as 360, and every numeric field is finite and inside its physical range
or the sentence is rejected (counted).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from nmea_checks import valid_sentences

from vdps_hil.codecs.nmea.attitude import format_attitude, format_hdt
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.codecs.nmea.parse import parse_sentence
from vdps_hil.codecs.nmea.position import format_gga
from vdps_hil.codecs.nmea.sentence import ParsedSentence, Reject, wrap_sentence
from vdps_hil.conventions import heading_to_yaw


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


# --------------------------------------------------------------------------- bounded fields
_NUMBER = re.compile(r"^[+-]?(?:\d+(?:\.\d*)?|\.\d+)$")
HUGE = ["9" * 400, "9" * 300, "-" + "9" * 300, "1" + "0" * 40 + ".5", "9" * 5000]
"""Numbers with valid syntax that no physical field holds: 400 digits parse to inf, 300 to
1e300; 5000 digits are beyond Python's int() limit."""

BOUNDS = {"gnss_speed_mps": (0.0, 514.45), "gnss_hdop": (0.0, 99.99),
          "gnss_alt_m": (-1000.0, 1e5), "gnss_geoid_sep_m": (-200.0, 200.0),
          "gnss_fix_quality": (0, 9), "gnss_num_sats": (0, 999)}
"""Physical ranges (fields.py's table) of the non-angle sample fields; angles: |x| <= 2 pi."""


def _assert_physical(r: ParsedSentence) -> None:
    for name, v in r.fields.items():
        assert math.isfinite(v), (name, v)
        lo, hi = BOUNDS.get(name, (-2 * math.pi, 2 * math.pi))
        assert lo <= v <= hi, (name, v)
    for name, v in r.extras.items():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            assert math.isfinite(v) and abs(v) <= 1e5, (name, v)


def test_every_numeric_field_of_every_layout_is_bounded():
    """Each numeric field of each layout replaced by a huge number with a correct checksum: the
    sentence is rejected as ``bad_field`` (counted) or the field is one the decoder does not
    read; never a sample with inf or 1e299, never an internal error."""
    rng = np.random.default_rng(20)
    rejected = 0
    for line in valid_sentences(rng, 9 * 3):
        body = line.decode().strip()[1:line.decode().index("*")]
        items = body.split(",")
        for j, item in enumerate(items[1:], start=1):
            if not _NUMBER.match(item):
                continue
            for huge in HUGE:
                new = ",".join(items[:j] + [huge] + items[j + 1:])
                r = parse_sentence(wrap_sentence(new))
                if isinstance(r, Reject):
                    assert r.reason == "bad_field", (new[:40], r)
                    rejected += 1
                else:
                    _assert_physical(r)
    assert rejected > 200  # the decoded fields: all of them in every layout


@pytest.mark.parametrize("line, reason", [
    (wrap_sentence("GPRMC,204132.00,A,4205.733476,N,08802.041110,W," + "9" * 400 + ",21.4,190214,,,D"), "bad_field"),
    (wrap_sentence("GPVTG,21.4,T,,M," + "9" * 300 + ",N,,K,A"), "bad_field"),
    (wrap_sentence("GPVTG,21.4,T,,M,,N," + "9" * 300 + ",K,A"), "bad_field"),
    (wrap_sentence("GPGGA,204132.10,4205.733715,N,08802.040978,W,2,08," + "9" * 400 + ",221.9,M,,,3,0138"), "bad_field"),
    (wrap_sentence("PASHR,204132.000,010.51,T,+00.39,-00.79," + "9" * 400 + ",0.151,0.075,0.555,1,0"), "bad_field"),
    (wrap_sentence("GPRMC,204132.00,A,4205.733476,N,08802.041110,W,1000.1,21.4,190214,,,D"), "bad_field"),
    (wrap_sentence("PASHR,204132.000,010.51,T,+00.39,-00.79,-100.01,0.151,0.075,0.555,1,0"), "bad_field"),
])
def test_the_issue_s_sentences_are_rejected(line, reason):
    r = parse_sentence(line)
    assert isinstance(r, Reject) and r.reason == reason, r


def test_the_edges_of_the_ranges_are_accepted():
    r = parse_sentence(wrap_sentence("GPRMC,204132.00,A,4205.733476,N,08802.041110,W,1000.0,21.4,190214,,,D"))
    assert isinstance(r, ParsedSentence) and r.fields["gnss_speed_mps"] == pytest.approx(1000 * 1852 / 3600)
    r = parse_sentence(wrap_sentence("PASHR,204132.000,010.51,T,+00.39,-00.79,-100.00,0.151,0.075,0.555,1,0"))
    assert isinstance(r, ParsedSentence) and r.extras["heave_m"] == -100.0


def test_the_decoder_counts_the_rejects():
    d = NmeaDecoder()
    assert d.feed_line(0, wrap_sentence("GPVTG,21.4,T,,M," + "9" * 400 + ",N,,K,A")) == []
    assert d.counters["reject_bad_field"] == 1 and d.counters["rejected"] == 1
