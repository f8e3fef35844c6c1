"""SI constants and unit conversions. Everything inside the package is SI; conversions happen
only at the boundaries (wire codecs, configs, reports)."""

from __future__ import annotations

import math

GRAVITY_MPS2 = 9.80665  # standard gravity [m/s^2]

DEG_PER_RAD = 180.0 / math.pi
RAD_PER_DEG = math.pi / 180.0
KPH_PER_MPS = 3.6
NS_PER_S = 1_000_000_000


def deg2rad(x):
    """Degrees to radians (works on floats and numpy arrays)."""
    return x * RAD_PER_DEG


def rad2deg(x):
    """Radians to degrees (works on floats and numpy arrays)."""
    return x * DEG_PER_RAD


def kph2mps(x):
    return x / KPH_PER_MPS


def mps2kph(x):
    return x * KPH_PER_MPS


def s2ns(t_s: float) -> int:
    """Seconds (float) to integer nanoseconds, rounded to the nearest nanosecond."""
    return int(round(t_s * NS_PER_S))


def ns2s(t_ns: int) -> float:
    return t_ns / NS_PER_S


def wrap_pi(angle_rad):
    """Wrap an angle (or array) to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi
