import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from vdps_hil.geodesy import DEFAULT_ORIGIN, EnuOrigin, ecef_to_geodetic, geodetic_to_ecef


@given(st.floats(-89.0, 89.0), st.floats(-180.0, 180.0), st.floats(-500.0, 9000.0))
def test_geodetic_ecef_round_trip(lat, lon, h):
    la, lo, hh = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h))
    assert abs(la - lat) < 1e-9 and abs(math.remainder(lo - lon, 360.0)) < 1e-9 and abs(hh - h) < 1e-5


@given(st.lists(st.floats(-5000.0, 5000.0), min_size=3, max_size=3))
def test_enu_round_trip(enu):
    back = DEFAULT_ORIGIN.to_enu(*DEFAULT_ORIGIN.to_geodetic(enu))
    np.testing.assert_allclose(back, enu, atol=1e-6)


def test_enu_axes():
    o = EnuOrigin(45.0, 7.0, 0.0)
    north = o.to_enu(45.0 + 1e-3, 7.0, 0.0)
    east = o.to_enu(45.0, 7.0 + 1e-3, 0.0)
    assert north[1] > 110 and abs(north[0]) < 1e-6  # 1e-3 deg lat ~ 111 m north
    assert east[0] > 78 and abs(east[1]) < 0.01     # 1e-3 deg lon ~ 78.8 m east at 45 deg
    np.testing.assert_allclose(o.to_enu(45.0, 7.0, 10.0), [0, 0, 10.0], atol=1e-6)
