"""Position and velocity sentences both ways: GGA (fix data -> ``gnss_pos``), RMC and VTG
(speed and course over ground -> ``gnss_vel``).

::

    lat_deg   = s_NS (dd + mm.mmmm / 60)          s_NS = +1 for N, -1 for S   (GGA, RMC)
    lon_deg   = s_EW (ddd + mm.mmmm / 60)         s_EW = +1 for E, -1 for W
    speed_mps = v_kn * 1852 / 3600                (or v_kmh / 3.6 when only km/h is printed)
    gnss_course_rad = wrap(pi/2 - radians(course))   course [deg, clockwise from true N]

Validity: GGA quality 0 (no fix), 7 (manual), 8 (simulator) -> invalid; RMC status V -> invalid;
RMC/VTG mode N (not valid) -> invalid. With no fix GGA may leave position and altitude empty,
RMC (status V) position and speed.
"""

from __future__ import annotations

import datetime as _dt

from vdps_hil.codecs.nmea.fields import (
    RANGE_ALTITUDE_M, RANGE_DIFF_AGE_S, RANGE_DOP, RANGE_GEOID_SEP_M, RANGE_HEADING_DEG,
    RANGE_SPEED_KMH, RANGE_SPEED_KN, Fields, fmt_heading, fmt_latlon, fmt_num, fmt_time, put_field,
)
from vdps_hil.codecs.nmea.sentence import (
    KMH_MPS, KNOT_MPS, ParsedSentence, SentenceError, wrap_sentence,
)
from vdps_hil.conventions import heading_to_yaw, yaw_to_heading

# --------------------------------------------------------------------------------------------
# Generators
# --------------------------------------------------------------------------------------------

def format_gga(utc_time_s: float, lat_deg: float, lon_deg: float, alt_m: float, *,
               fix_quality: int = 4, num_sats: int = 12, hdop: float = 0.8,
               geoid_sep_m: float | None = None, diff_age_s: float | None = None,
               diff_station: int | None = None, talker: str = "GP",
               lat_decimals: int = 6) -> bytes:
    """GGA fix data. ``alt_m`` above mean sea level; ``geoid_sep_m`` printed if given."""
    lat, ns = fmt_latlon(lat_deg, 2, lat_decimals, "NS")
    lon, ew = fmt_latlon(lon_deg, 3, lat_decimals, "EW")
    geoid = fmt_num(geoid_sep_m, 3)
    body = ",".join([
        f"{talker}GGA", fmt_time(utc_time_s, 2), lat, ns, lon, ew, str(int(fix_quality)),
        f"{int(num_sats):02d}", fmt_num(hdop, 1), fmt_num(alt_m, 3), "M", geoid,
        "M" if geoid else "", fmt_num(diff_age_s, 1), "" if diff_station is None else f"{int(diff_station):04d}",
    ])
    return wrap_sentence(body)


def format_rmc(utc_time_s: float, lat_deg: float, lon_deg: float, speed_mps: float,
               course_rad: float | None, *, date: _dt.date = _dt.date(2012, 11, 19),
               status: str = "A", mode: str = "A", talker: str = "GP",
               lat_decimals: int = 6) -> bytes:
    """RMC; ``course_rad`` is the course over ground as a paper yaw (None prints an empty
    course, as receivers do when standing still)."""
    lat, ns = fmt_latlon(lat_deg, 2, lat_decimals, "NS")
    lon, ew = fmt_latlon(lon_deg, 3, lat_decimals, "EW")
    course = "" if course_rad is None else fmt_heading(yaw_to_heading(course_rad), 3)
    body = ",".join([
        f"{talker}RMC", fmt_time(utc_time_s, 2), status, lat, ns, lon, ew,
        fmt_num(speed_mps / KNOT_MPS, 3), course, date.strftime("%d%m%y"), "", "", mode,
    ])
    return wrap_sentence(body)


def format_vtg(course_rad: float | None, speed_mps: float, *, mode: str = "A",
               talker: str = "GP") -> bytes:
    """VTG: true course (paper yaw in, heading printed), speed in knots and km/h."""
    course = "" if course_rad is None else fmt_heading(yaw_to_heading(course_rad), 3)
    body = ",".join([
        f"{talker}VTG", course, "T", "", "M", fmt_num(speed_mps / KNOT_MPS, 3), "N",
        fmt_num(speed_mps / KMH_MPS, 3), "K", mode,
    ])
    return wrap_sentence(body)


# --------------------------------------------------------------------------------------------
# Parsers: (fields, talker) -> ParsedSentence
# --------------------------------------------------------------------------------------------

def parse_gga(f: Fields, talker: str, **_) -> ParsedSentence:
    f.need(14)
    t = f.time(0)
    q = f.int_(5, "quality", 9)
    have_fix = q != 0
    out: dict[str, float] = {}
    put_field(out, "gnss_lat_deg", f.latlon(1, True, required=have_fix))
    put_field(out, "gnss_lon_deg", f.latlon(3, False, required=have_fix))
    out["gnss_fix_quality"] = float(q)
    put_field(out, "gnss_num_sats", f.int_(6, "satellites", 999, required=False))
    put_field(out, "gnss_hdop", f.num(7, "hdop", RANGE_DOP, required=False))
    alt = f.num(8, "altitude", RANGE_ALTITUDE_M, required=have_fix)
    if alt is not None:
        f.char(9, "altitude unit", "M")
    put_field(out, "gnss_alt_m", alt)
    geoid = f.num(10, "geoid separation", RANGE_GEOID_SEP_M, required=False)
    if geoid is not None:
        f.char(11, "geoid unit", "M")
    put_field(out, "gnss_geoid_sep_m", geoid)
    extras = {"diff_age_s": f.num(12, "diff age", RANGE_DIFF_AGE_S, required=False),
              "diff_station": f.raw(13)}
    return ParsedSentence("GGA", talker, "gnss_pos", out, valid=q not in (0, 7, 8),
                          utc_time_s=t, extras=extras)


def _mode_valid(mode: str) -> bool:
    return mode != "N"


def parse_rmc(f: Fields, talker: str, **_) -> ParsedSentence:
    f.need(11)
    t = f.time(0)
    status = f.char(1, "status", "AV")
    ok = status == "A"
    lat = f.latlon(2, True, required=ok)
    lon = f.latlon(4, False, required=ok)
    out: dict[str, float] = {}
    kn = f.num(6, "speed", RANGE_SPEED_KN, required=ok)
    put_field(out, "gnss_speed_mps", None if kn is None else kn * KNOT_MPS)
    course = f.num(7, "course", RANGE_HEADING_DEG, required=False)
    put_field(out, "gnss_course_rad", None if course is None else heading_to_yaw(course % 360.0))
    mode = f.char(11, "mode", "ADEFMNPRS", required=False)
    extras = {"lat_deg": lat, "lon_deg": lon, "date_ddmmyy": f.raw(8), "mode": mode}
    return ParsedSentence("RMC", talker, "gnss_vel", out, valid=ok and _mode_valid(mode),
                          utc_time_s=t, extras=extras)


def parse_vtg(f: Fields, talker: str, **_) -> ParsedSentence:
    f.need(8)
    out: dict[str, float] = {}
    course = f.num(0, "course", RANGE_HEADING_DEG, required=False)
    put_field(out, "gnss_course_rad", None if course is None else heading_to_yaw(course % 360.0))
    kn = f.num(4, "speed kn", RANGE_SPEED_KN, required=False)
    kmh = f.num(6, "speed km/h", RANGE_SPEED_KMH, required=False)
    if kn is not None:
        out["gnss_speed_mps"] = kn * KNOT_MPS
    elif kmh is not None:
        out["gnss_speed_mps"] = kmh * KMH_MPS
    else:
        raise SentenceError("empty_field", "VTG: no speed")
    mode = f.char(8, "mode", "ADEFMNPRS", required=False)
    return ParsedSentence("VTG", talker, "gnss_vel", out, valid=_mode_valid(mode),
                          extras={"mode": mode})
