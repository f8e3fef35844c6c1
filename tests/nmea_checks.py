"""Shared checks of the NMEA codec tests (tests/test_nmea_*.py): strategies, tolerances of the
printed precision, pynmeagps as the independent parser, the real OxTS file and the fuzz inputs.
"""

from __future__ import annotations

import math

from hypothesis import strategies as st
from pynmeagps import NMEAReader, VALCKSUM

from vdps_hil.bus.samples import FIELDS
from vdps_hil.codecs.nmea.attitude import format_attitude, format_hdt, format_ths
from vdps_hil.codecs.nmea.parse import parse_sentence
from vdps_hil.codecs.nmea.position import format_gga, format_rmc, format_vtg
from vdps_hil.codecs.nmea.sentence import ATTITUDE_LAYOUTS, ParsedSentence


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


def oxts_lines(real_data):
    return (real_data / OXTS).read_bytes().splitlines()


def valid_sentences(rng, n):
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


def mutate(rng, line: bytes) -> bytes:
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
