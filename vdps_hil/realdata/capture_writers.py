"""Writers of what ``vdps import`` reads, from a real drive's arrays (used by
``tools/convert_*.py``): time-stamped NMEA text of single-antenna fixes (``nmea_fix_lines``) and
an Xsens MTData2 byte capture of an IMU series placed at its wire times (``mti_capture``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vdps_hil.realdata.containers import GnssFixes, ImuSeries

__all__ = ["nmea_fix_lines", "CaptureStats", "mti_capture"]


def _nmea_latlon(value_deg: float, deg_digits: int, hemis: str) -> tuple[str, str]:
    h = hemis[0] if value_deg >= 0 else hemis[1]
    a = abs(float(value_deg))
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 6) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:0{deg_digits}d}{m:09.6f}", h


def _hhmmss(utc_s: float) -> str:
    tod = utc_s % 86400.0
    h = int(tod // 3600)
    mi = int((tod - 3600 * h) // 60)
    s = tod - 3600 * h - 60 * mi
    if round(s, 3) >= 60.0:
        s = 59.999
    return f"{h:02d}{mi:02d}{s:06.3f}"


_RMC_MODE = {4: "R", 5: "F", 2: "D", 1: "A", 6: "P"}


def nmea_fix_lines(fixes: GnssFixes, t0_s: float = 0.0, talker: str = "GP") -> list[bytes]:
    """Time-stamped NMEA text for single-antenna fixes: per epoch ``"<t - t0> $GPGGA..."`` and
    ``"<t - t0> $GPRMC..."`` (stamp in seconds, 6 decimals: the ``vdps import`` text form).

    GGA prints lat/lon to 1e-6 minute (2 mm), the height with 3 decimals in the altitude field
    and a geoid separation of 0.000 (the sources give ellipsoidal heights and no geoid model: the
    pipeline uses h = altitude + separation), the satellites if known; RMC prints speed [kn] and
    course [deg from true north] with 3 decimals (course empty when NaN) and the mode letter of
    the fix quality (R RTK fixed, F float, D differential, A autonomous)."""
    from vdps_hil.codecs.nmea.sentence import KNOT_MPS, wrap_sentence
    from vdps_hil.conventions import yaw_to_heading
    import datetime as dt

    out: list[bytes] = []
    for i in range(len(fixes)):
        t = float(fixes.t_s[i]) - t0_s
        utc = float(fixes.utc_s[i])
        lat, ns = _nmea_latlon(fixes.lat_deg[i], 2, "NS")
        lon, ew = _nmea_latlon(fixes.lon_deg[i], 3, "EW")
        q = int(fixes.quality[i])
        sats = "" if not math.isfinite(float(fixes.num_sats[i])) else f"{int(fixes.num_sats[i]):02d}"
        tod = _hhmmss(utc)
        gga = f"{talker}GGA,{tod},{lat},{ns},{lon},{ew},{q},{sats},,{float(fixes.h_m[i]):.3f},M,0.000,M,,"
        c = float(fixes.course_rad[i])
        course = "" if not math.isfinite(c) else f"{yaw_to_heading(c):.3f}"
        date = dt.datetime.fromtimestamp(utc, dt.timezone.utc).strftime("%d%m%y")
        rmc = (f"{talker}RMC,{tod},A,{lat},{ns},{lon},{ew},{float(fixes.speed_mps[i]) / KNOT_MPS:.3f},{course},"
               f"{date},,,{_RMC_MODE.get(q, 'A')}")
        stamp = f"{t:.6f} ".encode("ascii")
        out.append(stamp + wrap_sentence(gga))
        out.append(stamp + wrap_sentence(rmc))
    return out


@dataclass(frozen=True)
class CaptureStats:
    """How an MTi capture placed its packets: ``packets``, ``padding_bytes``, ``delayed``
    (packets placed later than their stamp because the previous one was still on the wire) and
    the largest placement error ``max_error_s`` (quantisation to one byte time included)."""

    packets: int
    padding_bytes: int
    delayed: int
    max_error_s: float
    baud: int


def mti_capture(imu: ImuSeries, t0_s: float = 0.0, baud: int = 115200, max_lead_s: float = 120.0
                ) -> tuple[bytes, CaptureStats]:
    """An Xsens MTData2 byte stream (``codecs.imu.encode_imu_packet``) of ``imu`` for
    ``vdps import --serial imu=FILE@BAUD``.

    The importer stamps a binary capture with its wire time (``SerialFileAdapter``: byte k
    arrives at (k + 1) 10 / baud s, 8N1). Packet i is therefore placed so its last byte is byte
    n_i = round((t_i - t0) baud / 10) - 1, the gap before it filled with zero bytes (idle line;
    the decoder skips them as ``garbage_bytes``, not an error), so the decoded ``t_ns`` is the
    sample's stamp (to one byte time, 10 / baud s) on the clock t - t0. A packet that would
    overlap its predecessor follows it directly (counted ``delayed``). SampleTimeFine carries the
    same t - t0 (100 us ticks) and the packet counter runs from 0. The axes are written as given
    (``imu.frame``): the mounting rotation stays in the model vehicle file.

    Refuses (ValueError) a first sample more than ``max_lead_s`` after t0 (the padding would be
    that many seconds of idle bytes)."""
    from vdps_hil.codecs.imu_mtdata2 import PACKET_BYTES, encode_imu_packet

    t = np.asarray(imu.t_s, dtype=float) - t0_s
    if t.size and (t[0] < 0 or t[0] > max_lead_s):
        raise ValueError(f"first IMU sample at {t[0]:.3f} s after t0: must be within [0, {max_lead_s}] s")
    byte_s = 10.0 / baud
    buf = bytearray()
    delayed = 0
    max_err = 0.0
    f, w = imu.specific_force_mps2, imu.angular_rate_radps
    for i in range(t.shape[0]):
        end = int(round(t[i] / byte_s))  # bytes received when the packet's last byte arrives
        start = end - PACKET_BYTES
        if start < len(buf):
            start = len(buf)
            delayed += 1
        buf.extend(b"\0" * (start - len(buf)))
        buf.extend(encode_imu_packet(int(round(t[i] * 1e9)), f[i], w[i], i))
        max_err = max(max_err, abs(len(buf) * byte_s - t[i]))
    pad = len(buf) - PACKET_BYTES * t.shape[0]
    return bytes(buf), CaptureStats(int(t.shape[0]), int(pad), delayed, max_err, int(baud))
