"""The comma2k19 drive (a 2018 Toyota RAV4, segment ``COMMA_SEGMENT``): readers of its processed
numpy arrays -- the u-blox fixes, the phone IMU and the offline ``global_pose`` reference.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vdps_hil.geodesy import EnuOrigin, ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from vdps_hil.realdata.containers import GnssFixes, ImuSeries, Reference
from vdps_hil.units import wrap_pi

__all__ = ["COMMA_SEGMENT", "read_comma_ublox", "read_comma_phone_imu", "read_comma_reference",
           "read_comma_reference_heading"]

COMMA_SEGMENT = "comma2k19_rav4_2018-08-02_seg40"


def _seg(seg_dir) -> Path:
    return Path(seg_dir)


def read_comma_ublox(seg_dir) -> GnssFixes:
    """comma2k19 ``processed_log/GNSS/live_gnss_ublox``: ``t`` (device boot s) and ``value``
    columns [lat deg, lon deg, speed m/s, UTC ms, altitude m, bearing deg]. The altitude is
    ellipsoidal (it agrees with the height of ``global_pose`` to 2 m, while the geoid there is
    about 32 m below the ellipsoid); the bearing is the course over ground clockwise from north."""
    d = _seg(seg_dir) / "processed_log" / "GNSS" / "live_gnss_ublox"
    t = np.load(d / "t").astype(float)
    v = np.load(d / "value").astype(float)
    if v.ndim != 2 or v.shape[1] < 6 or v.shape[0] != t.shape[0]:
        raise ValueError(f"{d}: expected value of shape (N, 6) matching t, got {v.shape}")
    n = t.shape[0]
    course = np.array([wrap_pi(math.radians(90.0 - b)) for b in v[:, 5]])
    nan = np.full(n, np.nan)
    return GnssFixes(t, v[:, 3] / 1000.0, v[:, 0], v[:, 1], v[:, 4], v[:, 2], course,
                     np.ones(n), nan.copy(), nan.copy(), nan.copy())


def read_comma_phone_imu(seg_dir) -> ImuSeries:
    """comma2k19 phone IMU (``processed_log/IMU/{accelerometer,gyro}``: m/s^2, rad/s, axes
    [forward, right, down]) in the bus axes x forward, y left, z up: (a, b, c) -> (a, -b, -c).
    Gyro samples are matched to accelerometer samples by time (same clock)."""
    d = _seg(seg_dir) / "processed_log" / "IMU"
    ta, a = np.load(d / "accelerometer" / "t").astype(float), np.load(d / "accelerometer" / "value").astype(float)
    tg, g = np.load(d / "gyro" / "t").astype(float), np.load(d / "gyro" / "value").astype(float)
    if a.shape != (ta.shape[0], 3) or g.shape != (tg.shape[0], 3):
        raise ValueError(f"{d}: accelerometer/gyro arrays do not match their time stamps")
    if ta.shape != tg.shape or not np.allclose(ta, tg, atol=1e-4):
        g = np.column_stack([np.interp(ta, tg, g[:, k]) for k in range(3)])
    flip = np.array([1.0, -1.0, -1.0])
    return ImuSeries(ta, a * flip, g * flip, "flu")


def read_comma_reference(seg_dir, origin: EnuOrigin | None = None) -> Reference:
    """comma2k19 ``global_pose`` (20 Hz offline INS/GNSS/vision solution of the device: ECEF
    position and velocity) in ENU about ``origin`` (default: the first pose)."""
    d = _seg(seg_dir) / "global_pose"
    t = np.load(d / "frame_times").astype(float)
    p = np.load(d / "frame_positions").astype(float)
    v = np.load(d / "frame_velocities").astype(float)
    if origin is None:
        origin = EnuOrigin(*ecef_to_geodetic(p[0]))
    rot = ecef_to_enu_matrix(origin.lat_deg, origin.lon_deg)
    ecef0 = geodetic_to_ecef(origin.lat_deg, origin.lon_deg, origin.h_m)
    return Reference(t, origin, (p - ecef0) @ rot.T, v @ rot.T)


def read_comma_reference_heading(seg_dir, origin: EnuOrigin) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, heading_rad) of comma2k19 ``global_pose``: the device's forward axis in ENU, as an
    angle from east counter-clockwise (the pipeline's yaw convention, eq 1), at the reference's
    20 Hz frames. ``frame_orientations`` holds unit quaternions (w, x, y, z) rotating the device
    frame (forward, right, down) into ECEF; the forward axis is the first column of that rotation
    (R e_1 = (1 - 2(y^2 + z^2), 2(xy + wz), 2(xz - wy))), turned into ENU about ``origin``. The
    device sits on the windscreen, so this is the car's heading plus a constant mount yaw."""
    d = _seg(seg_dir) / "global_pose"
    t = np.load(d / "frame_times").astype(float)
    q = np.load(d / "frame_orientations").astype(float)
    if q.ndim != 2 or q.shape != (t.shape[0], 4):
        raise ValueError(f"{d}: expected frame_orientations of shape (N, 4) matching frame_times, got {q.shape}")
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    fwd_ecef = np.column_stack([1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)])
    fwd = fwd_ecef @ ecef_to_enu_matrix(origin.lat_deg, origin.lon_deg).T
    return t, np.arctan2(fwd[:, 1], fwd[:, 0])
