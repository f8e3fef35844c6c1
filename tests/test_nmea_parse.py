"""Tests of codecs.nmea.parse (and the checksum of codecs.nmea.sentence): every reject reason,
the missing-checksum policy.
"""

from __future__ import annotations

import pytest

from vdps_hil.codecs.nmea.parse import parse_sentence
from vdps_hil.codecs.nmea.sentence import ParsedSentence, Reject, nmea_checksum
from vdps_hil.conventions import heading_to_yaw


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
