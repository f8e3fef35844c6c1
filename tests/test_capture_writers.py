"""vdps_hil.realdata.capture_writers without the real data: the NMEA and MTi writers against the
project's own decoders (property tests)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.realdata.capture_writers import mti_capture, nmea_fix_lines
from vdps_hil.realdata.containers import GnssFixes, ImuSeries
from vdps_hil.units import wrap_pi


@settings(max_examples=60, deadline=None)
@given(lat=st.floats(-89.0, 89.0), lon=st.floats(-179.9, 179.9), h=st.floats(-100.0, 5000.0),
       speed=st.floats(0.0, 80.0), course=st.floats(-math.pi, math.pi - 1e-6), q=st.sampled_from([1, 2, 4, 5]),
       t=st.floats(0.0, 1e5), utc=st.floats(1.5e9, 1.8e9))
def test_nmea_fix_lines_round_trip(lat, lon, h, speed, course, q, t, utc):
    fx = GnssFixes(np.array([t]), np.array([utc]), np.array([lat]), np.array([lon]), np.array([h]),
                   np.array([speed]), np.array([course]), np.array([float(q)]), np.array([12.0]),
                   np.array([np.nan]), np.array([np.nan]))
    dec = NmeaDecoder()
    from vdps_hil.adapters.nmea_adapter import parse_time_prefix
    got = []
    for line in nmea_fix_lines(fx, 0.0):
        ts, rest = parse_time_prefix(line)
        assert ts == round(t * 1e6) * 1000
        got += dec.feed_line(ts, rest)
    assert dec.counters["rejected"] == 0 and [s.kind for s in got] == ["gnss_pos", "gnss_vel"]
    p, v = got[0].fields, got[1].fields
    assert abs(p["gnss_lat_deg"] - lat) <= 1e-6 / 60 and abs(p["gnss_lon_deg"] - lon) <= 1e-6 / 60
    assert abs(p["gnss_alt_m"] + p["gnss_geoid_sep_m"] - h) <= 5e-4 + 1e-9
    assert p["gnss_fix_quality"] == q
    assert abs(v["gnss_speed_mps"] - speed) <= 0.0005 * 1852 / 3600 + 1e-9
    assert abs(wrap_pi(v["gnss_course_rad"] - course)) <= math.radians(0.0005) + 1e-9


@settings(max_examples=40, deadline=None)
@given(gaps=st.lists(st.floats(0.0005, 0.02), min_size=1, max_size=60), baud=st.sampled_from([57600, 115200]))
def test_mti_capture_puts_each_packet_at_its_stamp(gaps, baud):
    t = 0.05 + np.cumsum(gaps)
    n = t.shape[0]
    f = np.tile([0.1, -0.2, 9.8], (n, 1)) + np.arange(n)[:, None] * 1e-3
    imu = ImuSeries(t, f, np.zeros((n, 3)), "flu")
    data, stats = mti_capture(imu, 0.0, baud)
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
        mti_capture(ImuSeries(t + 500.0, f, np.zeros((n, 3)), "flu"), 0.0, baud)
