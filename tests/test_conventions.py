import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vdps_hil import conventions as cv


@pytest.mark.parametrize("heading,yaw", [(0.0, 90.0), (90.0, 0.0), (180.0, -90.0), (270.0, -180.0), (45.0, 45.0)])
def test_heading_to_yaw(heading, yaw):
    assert math.isclose(cv.heading_to_yaw(heading), math.radians(yaw), abs_tol=1e-12)


@given(st.floats(min_value=0.0, max_value=359.999))
def test_heading_round_trip(h):
    assert math.isclose(cv.yaw_to_heading(cv.heading_to_yaw(h)), h, abs_tol=1e-9)


def test_wheel_order_clockwise():
    assert cv.WHEELS == ("fl", "fr", "rr", "rl")
    assert [cv.WHEEL_SIDE_SIGN[i] for i in cv.LEFT] == [1.0, 1.0]
    assert [cv.WHEEL_AXLE_SIGN[i] for i in cv.REAR] == [-1.0, -1.0]
