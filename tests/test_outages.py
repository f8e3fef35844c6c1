"""vdps_hil.realdata.outages and runs.gnss_denied without the real data: outage windows and
GNSS-denied filtering."""

from __future__ import annotations

from vdps_hil.bus.samples import Sample
from vdps_hil.realdata.outages import outage_windows
from vdps_hil.realdata.runs import gnss_denied


def test_gnss_denied_and_outage_windows():
    wins = outage_windows(100.0, 200.0, 30.0, (5.0, 10.0), first_offset_s=0.0)
    assert wins == [(100.0, 105.0), (130.0, 140.0), (160.0, 165.0)]  # (190, 200) would not end before 200
    drop = gnss_denied(wins)
    assert drop(Sample(int(101e9), "gnss", "gnss_pos")) and not drop(Sample(int(105e9), "gnss", "gnss_pos"))
    assert not drop(Sample(int(101e9), "imu", "imu")) and drop(Sample(int(139.9e9), "gnss", "gnss_vel"))
