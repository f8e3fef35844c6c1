"""The rtklibexplorer drive (``RTKLIB_DRIVE``): RTKLIB ``.pos`` solutions, the rtklibexplorer IMU
``.csv`` with its RTKLIB time-tag file, GPST time scales (RTKLIB prints GPST calendar seconds)
and the publisher's IMU mounting in our conventions.

Publisher mounting (rtklibexplorer drive 0708)
----------------------------------------------
The publisher states the IMU orientation [180, 0, 180] deg plus a misalignment
[0, -6.79, 5.35] deg (roll, pitch, yaw) to a body frame x forward, y right, z down, and applies
them as f_b,FRD = C(e) f_imu with Groves' ``Euler_to_CTM``::

    C(phi, theta, psi) = [[ c_t c_p,                 c_t s_p,                 -s_t   ],
                          [-c_f s_p + s_f s_t c_p,   c_f c_p + s_f s_t s_p,   s_f c_t],
                          [ s_f s_p + c_f s_t c_p,  -s_f c_p + c_f s_t s_p,   c_f c_t]]

Our body frame is x forward, y left, z up (T = diag(1, -1, -1) from FRD) and the pipeline applies
f_b = C_gv(r)^T f_s with C_gv of eq 1 and r = the model file's ``imu_rotation_rpy_rad``, so
C_gv(r) = (T C(e))^T; ``publisher_mounting_rpy`` solves for r (theta = asin C_gv[0, 2],
psi = atan2(C_gv[0, 1], C_gv[0, 0]), phi = atan2(C_gv[1, 2], C_gv[2, 2])). Lever arms
(forward, right, down) from the publisher's system origin become (x, -y, -z) from our CG, which
the model file takes to be that origin (an estimate: the car's CG is not published).
"""

from __future__ import annotations

import calendar
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from vdps_hil.geodesy import EnuOrigin
from vdps_hil.realdata.containers import GnssFixes, ImuSeries, Reference
from vdps_hil.units import GRAVITY_MPS2

__all__ = ["RTKLIB_DRIVE", "GPS_EPOCH_UNIX_S", "gpst_minus_utc_s", "gpst_to_unix", "unix_to_gpst", "RtkSolution",
           "TimeTag", "read_rtklib_pos", "read_timetag", "read_rtklib_imu", "groves_ctm", "publisher_mounting_rpy"]

RTKLIB_DRIVE = "rtklibexplorer_drive_0708"
GPS_EPOCH_UNIX_S = 315_964_800  # 1980-01-06T00:00:00Z
# UTC dates from which GPST - UTC increased (IERS bulletin C; 18 s since 2017-01-01)
_LEAPS = ((1136073600, 14), (1230768000, 15), (1341100800, 16), (1435708800, 17), (1483228800, 18))


# ------------------------------------------------------------------------------ time scales
def gpst_minus_utc_s(unix_utc_s: float) -> int:
    """GPST - UTC [s] at a UTC instant (13 before 2006, 18 from 2017-01-01 on)."""
    off = 13
    for start, n in _LEAPS:
        if unix_utc_s >= start:
            off = n
    return off


def gpst_to_unix(gpst_calendar_s: float) -> float:
    """A GPST calendar time written as seconds since 1970-01-01 (as RTKLIB prints it) -> UTC
    Unix seconds (leap seconds removed)."""
    return gpst_calendar_s - gpst_minus_utc_s(gpst_calendar_s - 18.0)


def unix_to_gpst(unix_utc_s: float) -> float:
    """UTC Unix seconds -> GPST calendar seconds since 1970-01-01 (inverse of ``gpst_to_unix``)."""
    return unix_utc_s + gpst_minus_utc_s(unix_utc_s)


# ------------------------------------------------------------------------------ solutions
@dataclass(frozen=True)
class RtkSolution:
    """An RTKLIB ``.pos`` solution (llh, velocity in NEU): ``t_gpst_s`` GPST calendar seconds
    since 1970 as printed, ``q`` RTKLIB quality (1 fix, 2 float, 4 DGPS, 5 single), ``sd_neu_m``
    the printed sigmas, ``vel_neu_mps`` velocity north/east/up."""

    t_gpst_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    q: np.ndarray
    ns: np.ndarray
    sd_neu_m: np.ndarray
    vel_neu_mps: np.ndarray

    RTKLIB_TO_GGA = {1: 4, 2: 5, 3: 1, 4: 2, 5: 1, 6: 6}
    """RTKLIB Q (1 fix, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP) -> GGA fix quality."""

    def fixes(self, t0_gpst_s: float = 0.0) -> GnssFixes:
        """As single-antenna GNSS epochs on the clock t = t_gpst - t0 (course NaN below 0.05 m/s)."""
        vn, ve = self.vel_neu_mps[:, 0], self.vel_neu_mps[:, 1]
        speed = np.hypot(vn, ve)
        course = np.where(speed > 0.05, np.arctan2(vn, ve), np.nan)
        q = np.array([self.RTKLIB_TO_GGA.get(int(v), 1) for v in self.q], dtype=float)
        utc = np.array([gpst_to_unix(t) for t in self.t_gpst_s])
        return GnssFixes(self.t_gpst_s - t0_gpst_s, utc, self.lat_deg, self.lon_deg, self.h_m, speed, course, q,
                         self.ns.astype(float), np.hypot(self.sd_neu_m[:, 0], self.sd_neu_m[:, 1]) / math.sqrt(2.0),
                         self.sd_neu_m[:, 2].copy())

    def reference(self, origin: EnuOrigin | None = None, t0_gpst_s: float = 0.0) -> Reference:
        """The solution as a reference trajectory of the antenna (ENU, velocities E/N/U)."""
        if origin is None:
            origin = EnuOrigin(float(self.lat_deg[0]), float(self.lon_deg[0]), float(self.h_m[0]))
        pos = np.array([origin.to_enu(a, b, c) for a, b, c in zip(self.lat_deg, self.lon_deg, self.h_m)])
        vel = np.column_stack([self.vel_neu_mps[:, 1], self.vel_neu_mps[:, 0], self.vel_neu_mps[:, 2]])
        return Reference(self.t_gpst_s - t0_gpst_s, origin, pos, vel)


@dataclass(frozen=True)
class TimeTag:
    """An RTKLIB time-tag file (``stream.c``, demo5 layout): a 60-byte header text, the tick
    [ms] at the file start, the start time (uint32 seconds + float64 fraction; GPST calendar
    seconds since 1970), then records (tick [ms] since start, byte position in the stream)."""

    header: str
    tick0_ms: int
    start_s: float
    ticks_ms: np.ndarray
    fpos: np.ndarray

    @property
    def end_s(self) -> float:
        return self.start_s + (float(self.ticks_ms[-1]) / 1000.0 if self.ticks_ms.size else 0.0)


# ------------------------------------------------------------------------------ readers
def read_rtklib_pos(path) -> RtkSolution:
    """An RTKLIB ``.pos`` file with llh and velocities (``%`` header lines; columns: date, time
    (GPST), lat, lon, height, Q, ns, sdn, sde, sdu, sdne, sdeu, sdun, age, ratio, vn, ve, vu, ...).
    Lines that do not parse are skipped."""
    import datetime as dt

    rows = []
    with open(path, encoding="ascii", errors="replace") as f:
        for line in f:
            if not line.strip() or line.lstrip().startswith("%"):
                continue
            parts = line.split()
            if len(parts) < 18:
                continue
            try:
                day = dt.datetime.strptime(parts[0] + " " + parts[1], "%Y/%m/%d %H:%M:%S.%f")
                nums = [float(x) for x in parts[2:18]]
            except ValueError:
                continue
            t = calendar.timegm(day.timetuple()) + day.microsecond * 1e-6
            rows.append([t, *nums])
    if not rows:
        raise ValueError(f"{path}: no RTKLIB solution lines with velocities")
    a = np.array(rows)
    return RtkSolution(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4].astype(int), a[:, 5].astype(int),
                       a[:, 6:9], a[:, 14:17])


TIMETAG_HEADER_LEN = 60


def read_timetag(path) -> TimeTag:
    """An RTKLIB time-tag file (demo5: HEADER(60) + TICK(4) + TIME(4 + 8) + records of
    TICK(4) + FPOS(4), little-endian)."""
    b = Path(path).read_bytes()
    if len(b) < TIMETAG_HEADER_LEN + 16 or not b.startswith(b"TIMETAG"):
        raise ValueError(f"{path}: not an RTKLIB time-tag file")
    header = b[:TIMETAG_HEADER_LEN].rstrip(b"\0").decode("ascii", "replace")
    tick0, t_int = struct.unpack_from("<II", b, TIMETAG_HEADER_LEN)
    (t_frac,) = struct.unpack_from("<d", b, TIMETAG_HEADER_LEN + 8)
    body = b[TIMETAG_HEADER_LEN + 16:]
    body = body[: len(body) // 8 * 8]
    rec = np.frombuffer(body, dtype="<u4").reshape(-1, 2)
    return TimeTag(header, int(tick0), float(t_int) + float(t_frac), rec[:, 0].astype(np.int64),
                   rec[:, 1].astype(np.int64))


def read_rtklib_imu(csv_path, tag_path=None) -> ImuSeries:
    """The rtklibexplorer IMU log: ``ax, ay, az`` [g], ``gx, gy, gz`` [deg/s], device counter
    [ms], one row per sample, in the IMU's own axes (``frame = "sensor"``). Times follow the
    publisher's own rule (GNSS_IMU ``convert_imu_file.py``): the counter relative to the first row,
    stretched so the log spans the time-tag file's start to its last tick::

        t_i = t_start + s_i (t_end - t_start) / s_N,   s_i = (ms_i - ms_0) / 1000

    with t_start, t_end from the tag (GPST calendar seconds). Without a tag: t_i = s_i.
    Rows that do not parse are skipped."""
    rows = []
    with open(csv_path, encoding="ascii", errors="replace") as f:
        for line in f:
            parts = line.strip().split(",")
            if len(parts) < 7:
                continue
            try:
                rows.append([float(x) for x in parts[:7]])
            except ValueError:
                continue
    if len(rows) < 2:
        raise ValueError(f"{csv_path}: fewer than two IMU rows")
    a = np.array(rows)
    s = (a[:, 6] - a[:, 6][0]) / 1000.0
    if tag_path is not None:
        tag = read_timetag(tag_path)
        t = tag.start_s + s * (tag.end_s - tag.start_s) / s[-1]
    else:
        t = s
    return ImuSeries(t, a[:, 0:3] * GRAVITY_MPS2, np.radians(a[:, 3:6]), "sensor")


# ------------------------------------------------------------------------------ mounting
def groves_ctm(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Groves' ``Euler_to_CTM`` (module docstring): the publisher's IMU -> body (FRD) matrix."""
    sf, cf = math.sin(roll_rad), math.cos(roll_rad)
    st, ct = math.sin(pitch_rad), math.cos(pitch_rad)
    sp, cp = math.sin(yaw_rad), math.cos(yaw_rad)
    return np.array([[ct * cp, ct * sp, -st],
                     [-cf * sp + sf * st * cp, cf * cp + sf * st * sp, sf * ct],
                     [sf * sp + cf * st * cp, -sf * cp + cf * st * sp, cf * ct]])


def publisher_mounting_rpy(orientation_deg: Sequence[float], misalign_deg: Sequence[float] = (0.0, 0.0, 0.0)
                           ) -> tuple[float, float, float]:
    """Our ``imu_rotation_rpy_rad`` (body -> sensor, eq 1, body x fwd y left z up) from the
    publisher's IMU orientation + misalignment (Groves Euler angles to an FRD body; module
    docstring). Returns (roll, pitch, yaw) [rad]."""
    e = np.radians(np.asarray(orientation_deg, dtype=float) + np.asarray(misalign_deg, dtype=float))
    c_gv = (np.diag([1.0, -1.0, -1.0]) @ groves_ctm(*e)).T
    theta = math.asin(max(-1.0, min(1.0, c_gv[0, 2])))
    psi = math.atan2(c_gv[0, 1], c_gv[0, 0])
    phi = math.atan2(c_gv[1, 2], c_gv[2, 2])
    return phi, theta, psi
