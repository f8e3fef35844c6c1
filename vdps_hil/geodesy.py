"""WGS-84 geodesy: geodetic <-> ECEF <-> local ENU (the global frame {g}).

Exact closed forms (ECEF -> geodetic by Bowring's iteration to 1e-12 rad). Heights are
ellipsoidal; NMEA GGA altitude is above mean sea level, so add the geoid separation first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def geodetic_to_ecef(lat_deg: float, lon_deg: float, h_m: float) -> np.ndarray:
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl = math.sin(lat), math.cos(lat)
    n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * sl * sl)
    return np.array([(n + h_m) * cl * math.cos(lon), (n + h_m) * cl * math.sin(lon),
                     (n * (1.0 - WGS84_E2) + h_m) * sl])


def ecef_to_geodetic(xyz) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in xyz)
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - WGS84_E2))
    h = 0.0
    for _ in range(10):
        sl = math.sin(lat)
        n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * sl * sl)
        h = p / math.cos(lat) - n if abs(lat) < 1.2 else z / sl - n * (1.0 - WGS84_E2)
        new = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
        if abs(new - lat) < 1e-13:
            lat = new
            break
        lat = new
    sl = math.sin(lat)
    n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * sl * sl)
    h = p / math.cos(lat) - n if abs(lat) < 1.2 else z / sl - n * (1.0 - WGS84_E2)
    return math.degrees(lat), math.degrees(lon), h


def ecef_to_enu_matrix(lat_deg: float, lon_deg: float) -> np.ndarray:
    """Rotation taking ECEF vector components to local East-North-Up components."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


@dataclass(frozen=True)
class EnuOrigin:
    """Origin of the global ENU frame {g}: the scenario reference point or the first fix."""

    lat_deg: float
    lon_deg: float
    h_m: float

    def __post_init__(self):
        object.__setattr__(self, "_ecef", geodetic_to_ecef(self.lat_deg, self.lon_deg, self.h_m))
        object.__setattr__(self, "_rot", ecef_to_enu_matrix(self.lat_deg, self.lon_deg))

    def to_enu(self, lat_deg: float, lon_deg: float, h_m: float) -> np.ndarray:
        return self._rot @ (geodetic_to_ecef(lat_deg, lon_deg, h_m) - self._ecef)

    def to_geodetic(self, enu_m) -> tuple[float, float, float]:
        return ecef_to_geodetic(self._ecef + self._rot.T @ np.asarray(enu_m, dtype=float))


DEFAULT_ORIGIN = EnuOrigin(lat_deg=24.7869, lon_deg=120.9975, h_m=100.0)
"""Simulation reference point (Hsinchu, Taiwan, near the authors' university), ellipsoidal h."""
