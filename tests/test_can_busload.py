"""Tests of vdps_hil.codecs.can_busload: CRC-15/CAN, frame lengths (published values, exact
stuffing within its bounds) and the bus load at the Table 1 rates.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from vdps_hil.codecs.can_busload import (
    RATE_PROFILES, _can_crc15, bus_load, frame_bits, frame_bits_stuffed,
)


def test_can_crc15_check_value_published():
    # CRC-15/CAN check value over ASCII "123456789" is 0x059E (reveng catalogue)
    bits = [(b >> (7 - i)) & 1 for b in b"123456789" for i in range(8)]
    assert _can_crc15(bits) == 0x059E


def test_frame_bits_published_lengths():
    # classic CAN, 11-bit ID, 3-bit interframe space: 8 data bytes -> 111 bits unstuffed and
    # 135 bits worst case (Davis et al. 2007); 0 bytes -> 47 and 55
    assert (frame_bits(8, stuffing="none"), frame_bits(8)) == (111, 135)
    assert (frame_bits(0, stuffing="none"), frame_bits(0)) == (47, 55)
    # all-zero frame (ID 0, DLC 0, CRC 0): 34 dominant bits get a stuff bit after every 5
    assert frame_bits_stuffed(0, b"") == 47 + 6


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 0x7FF), st.binary(max_size=8))
def test_exact_stuffing_within_bounds(aid, data):
    n = frame_bits_stuffed(aid, data)
    assert frame_bits(len(data), stuffing="none") <= n <= frame_bits(len(data))


def test_bus_load_at_table1_rates_well_below_capacity():
    worst = {p: bus_load(r)["total"] for p, r in RATE_PROFILES.items()}
    # independent sum with the published frame lengths (n=8: 135, n=6: 115, n=5: 105, n=4: 95 bits)
    c = {"VDPS_Warning": 135, "VDPS_WheelSpeedFront": 115, "VDPS_WheelSpeedRear": 115,
         "VDPS_Suspension": 135, "VDPS_WheelTorqueFront": 105, "VDPS_WheelTorqueRear": 105,
         "VDPS_SteerAngle": 95}
    for p, rates in RATE_PROFILES.items():
        assert worst[p] == pytest.approx(sum(rates[n] * c[n] for n in c) / 1e6, rel=1e-12)
    assert worst["table1-susp1k"] < 0.5 and worst["table1"] < worst["table1-susp1k"]
    assert RATE_PROFILES["table1"]["VDPS_Suspension"] == 1.0
    assert RATE_PROFILES["table1-susp1k"]["VDPS_Suspension"] == 1000.0
