"""Tests of codecs.nmea.fields: the generators print with the precision of real receivers, and a
heading never prints as 360.
"""

from __future__ import annotations

import math

from vdps_hil.codecs.nmea.attitude import format_attitude, format_hdt
from vdps_hil.codecs.nmea.position import format_gga
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
