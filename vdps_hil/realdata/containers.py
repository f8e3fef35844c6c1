"""The arrays a real drive reads into (package docstring for frames and symbols): IMU samples
(``ImuSeries``), single-antenna GNSS epochs (``GnssFixes``) and a reference trajectory in ENU
(``Reference``). Readers (``comma2k19``, ``rtklib``) fill them; the capture writers and the
comparisons read them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vdps_hil.geodesy import EnuOrigin

__all__ = ["ImuSeries", "GnssFixes", "Reference"]


@dataclass(frozen=True)
class ImuSeries:
    """IMU samples: ``t_s`` (N,), specific force [m/s^2] and angular rate [rad/s] (N, 3) in the
    axes named by ``frame`` (``"flu"``: x forward, y left, z up, the bus convention; ``"sensor"``:
    the device's own axes, the mounting rotation still to apply)."""

    t_s: np.ndarray
    specific_force_mps2: np.ndarray
    angular_rate_radps: np.ndarray
    frame: str


@dataclass(frozen=True)
class GnssFixes:
    """Single-antenna GNSS epochs. ``t_s``: the drive clock; ``utc_s``: the fix's UTC (Unix s);
    ``h_m`` ellipsoidal height; ``course_rad`` paper yaw (NaN when not moving); ``quality``: GGA
    fix quality; ``num_sats`` (NaN if unknown); ``sigma_h_m``/``sigma_v_m`` (NaN if unknown)."""

    t_s: np.ndarray
    utc_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    speed_mps: np.ndarray
    course_rad: np.ndarray
    quality: np.ndarray
    num_sats: np.ndarray
    sigma_h_m: np.ndarray
    sigma_v_m: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True)
class Reference:
    """A reference trajectory in ENU about ``origin``: positions and velocities (N, 3) of the
    reference point (comma2k19: the device; RTKLIB: the antenna) at ``t_s``."""

    t_s: np.ndarray
    origin: EnuOrigin
    pos_enu_m: np.ndarray
    vel_enu_mps: np.ndarray

    @property
    def speed_mps(self) -> np.ndarray:
        return np.hypot(self.vel_enu_mps[:, 0], self.vel_enu_mps[:, 1])

    @property
    def course_rad(self) -> np.ndarray:
        return np.arctan2(self.vel_enu_mps[:, 1], self.vel_enu_mps[:, 0])

    def at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """(positions, velocities) linearly interpolated at ``t_s`` (NaN outside)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        p = np.column_stack([np.interp(t, self.t_s, self.pos_enu_m[:, k], left=np.nan, right=np.nan)
                             for k in range(3)])
        v = np.column_stack([np.interp(t, self.t_s, self.vel_enu_mps[:, k], left=np.nan, right=np.nan)
                             for k in range(3)])
        return p, v
