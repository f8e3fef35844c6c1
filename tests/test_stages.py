"""Stages of the physics core (model/stages.py): the Ackermann steering geometry and the eq-14
spring law (the whole composition is tested through ``Model.f`` in tests/test_core.py)."""

import math

import pytest

from vdps_hil.model.params import load_vehicle
from vdps_hil.model.stages import ackermann_angles, spring_force_n

SEDAN = load_vehicle("sedan-truth")


def test_ackermann_inner_wheel_steers_more_and_mean_is_bicycle_angle():
    L, tf = SEDAN.geometry.wheelbase_m, SEDAN.geometry.track_half_front_m
    d1, d2 = ackermann_angles(0.05, L, tf)
    assert d1 > 0.05 > d2 > 0.0  # left turn: FL is the inner wheel
    # both wheel axes meet on the rear-axle line: L / tan d1 + tf == L / tan d2 - tf
    assert L / math.tan(d1) + tf == pytest.approx(L / math.tan(d2) - tf, rel=1e-12)
    assert abs(0.5 * (d1 + d2) - 0.05) <= 1.1 * (tf / L) ** 2 * 0.05 ** 3  # third-order difference


def test_spring_law_eq14():
    a = SEDAN.front
    f = spring_force_n(a.static_compression_m, a.spring_c1_npm, a.spring_c2_per_m, a.spring_c3_m)
    assert f == pytest.approx(a.spring_c1_npm * a.static_compression_m, rel=1e-12)
    f2 = spring_force_n(0.12, a.spring_c1_npm, a.spring_c2_per_m, a.spring_c3_m)
    assert f2 == pytest.approx(a.spring_c1_npm * math.exp(a.spring_c2_per_m * (0.12 - 0.07)) * 0.12)
