"""NMEA 0183 sentences both ways: generator (``format_*``) and parser (``parse_sentence``,
``NmeaDecoder``), converting at the boundary to the bus field catalogue (SI, paper angles).

Conversions (printed value -> catalogue field)
----------------------------------------------
::

    lat_deg   = s_NS (dd + mm.mmmm / 60)          s_NS = +1 for N, -1 for S   (GGA, RMC)
    lon_deg   = s_EW (ddd + mm.mmmm / 60)         s_EW = +1 for E, -1 for W
    speed_mps = v_kn * 1852 / 3600                (or v_kmh / 3.6 when only km/h is printed)
    psi       = wrap(pi/2 - radians(h))           h: heading/course [deg, clockwise from true N]
    theta     = s_p * radians(pitch_printed)      s_p = ATTITUDE_SIGN[layout].pitch_to_paper
    phi       = s_r * radians(roll_printed)       s_r = ATTITUDE_SIGN[layout].roll_to_paper
    sigma_*   = radians(accuracy_printed)         (1-sigma, where the sentence prints it)

Symbols: psi paper yaw [rad, CCW from East], theta paper pitch [rad, nose up positive], phi paper
roll [rad, right side down positive] (``vdps_hil.conventions``); ``gnss_course_rad`` is the course
over ground written as a paper yaw. The generators apply the inverse maps, so a round trip is
exact up to the printed precision (half a unit of the last printed digit).

Checksum: ``*hh`` after the body is the XOR of every byte between ``$`` and ``*`` as two hex
digits. Sentences end with CR LF.

Layouts (``ParsedSentence.sentence``) and the sample kind they feed
-------------------------------------------------------------------
=============  ==========  =================================================================
GGA            gnss_pos    time, lat, N/S, lon, E/W, quality, sats, HDOP, alt, M, geoid sep, M,
                           diff age, station
RMC            gnss_vel    time, status, lat, N/S, lon, E/W, speed kn, course, date, magvar,
                           E/W[, mode[, nav status]]; speed and course only go on the bus
VTG            gnss_vel    course T, T, course M, M, speed kn, N, speed km/h, K[, mode]
HDT            gnss_att    heading, T
THS            gnss_att    heading, mode (A autonomous, E estimated, M manual, S simulator, V)
PASHR          gnss_att    bare OxTS/Applanix/NovAtel layout: time, heading, T, roll, pitch, heave,
                           roll acc, pitch acc, heading acc, GNSS quality[, INS status]; roll
                           present; sigmas from the accuracies
PASHR,HPR      gnss_att    Ashtech/Spectra: time, heading, pitch, roll, carrier RMS, baseline
                           RMS, ambiguity[, mode, antenna setup, PDOP]
HPR            gnss_att    $GNHPR/$GPHPR (Unicore, ComNav): time, heading, pitch, roll, QF[,
                           sats, age, station]
PTNL,AVR       gnss_att    Trimble: time, yaw, Yaw, tilt, Tilt, roll, Roll, range, quality[,
                           PDOP, sats]; tilt is the pitch-like angle; the labelled slot decides
=============  ==========  =================================================================

Two-antenna layouts (PASHR,HPR and HPR) print both a pitch and a roll slot but one baseline
measures only one of them; ``dual_antenna_baseline`` says which: ``"along"`` (default, pitch),
``"across"`` (roll) or ``"both"`` (three or more antennas). ``ParsedSentence.has_roll`` says
whether a roll went on the bus.

Bad input policy
----------------
``parse_sentence`` never raises; it returns a ``Reject(reason, detail)``. Reasons
(``REJECT_REASONS``): ``empty``, ``not_ascii`` (bytes that are not printable ASCII, which
includes every non-UTF-8 sequence), ``no_start`` (no ``$``/``!``), ``missing_checksum``,
``malformed_checksum``, ``bad_checksum``, ``truncated`` (fewer fields than the layout needs),
``empty_field`` (a required field is empty), ``bad_field`` (unparseable or out of range),
``unsupported`` (a well-formed sentence we do not decode, e.g. ZDA, GSV: counted apart from
errors) and ``internal_error`` (a bug; tests assert it never happens).

**Missing checksum: rejected** unless ``lenient_checksum=True``. NMEA 0183 makes the checksum
mandatory on every sentence we decode, and without it a line cut short by a dropped byte cannot
be told from a complete one; some hand-typed or legacy sources omit it, hence the option (a
present but wrong checksum is always rejected). Garbage before the ``$`` is skipped (the
sentence starts at the last ``$``, which cannot occur inside a sentence) and counted
(``ParsedSentence.skipped_prefix``), so a sentence glued to noise is not lost.

Value precision the generators print (as real receivers do): GGA lat/lon 6 decimals of minutes
(OxTS), alt 3 decimals, HDOP 1; RMC/VTG speed and course 3; HDT/THS heading 2; PASHR heading,
roll, pitch, heave 2 and accuracies 3 with the time in ms (OxTS); PASHR,HPR angles 3, RMS 4;
HPR angles 2 (Unicore/ComNav); PTNL,AVR angles 4, range 3 (Trimble). ``PRINT_DECIMALS`` holds
these for tests.
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

from vdps_hil.bus.samples import Sample, check_fields
from vdps_hil.conventions import ATTITUDE_SIGN, AttitudeSign, heading_to_yaw, yaw_to_heading

KNOT_MPS = 1852.0 / 3600.0
"""One knot in m/s (exact: 1852 m per hour)."""
KMH_MPS = 1.0 / 3.6

REJECT_REASONS: tuple[str, ...] = (
    "empty", "not_ascii", "no_start", "missing_checksum", "malformed_checksum", "bad_checksum",
    "truncated", "empty_field", "bad_field", "unsupported", "internal_error",
)

ATTITUDE_LAYOUTS: tuple[str, ...] = ("PASHR", "PASHR,HPR", "HPR", "PTNL,AVR")
"""Attitude sentence layouts carrying pitch/roll (each has an ``ATTITUDE_SIGN`` entry)."""

HEADING_LAYOUTS: tuple[str, ...] = ("HDT", "THS")

SAMPLE_KIND: dict[str, str] = {
    "GGA": "gnss_pos", "RMC": "gnss_vel", "VTG": "gnss_vel", "HDT": "gnss_att", "THS": "gnss_att",
    "PASHR": "gnss_att", "PASHR,HPR": "gnss_att", "HPR": "gnss_att", "PTNL,AVR": "gnss_att",
}

PRINT_DECIMALS: dict[str, dict[str, int]] = {
    "GGA": {"lat_min": 6, "lon_min": 6, "alt": 3, "geoid": 3, "hdop": 1, "time": 2},
    "RMC": {"lat_min": 6, "lon_min": 6, "speed_kn": 3, "course": 3, "time": 2},
    "VTG": {"course": 3, "speed_kn": 3, "speed_kmh": 3},
    "HDT": {"heading": 2},
    "THS": {"heading": 2},
    "PASHR": {"heading": 2, "pitch": 2, "roll": 2, "heave": 2, "sigma": 3, "time": 3},
    "PASHR,HPR": {"heading": 3, "pitch": 3, "roll": 3, "rms": 4, "time": 2},
    "HPR": {"heading": 2, "pitch": 2, "roll": 2, "time": 2},
    "PTNL,AVR": {"heading": 4, "pitch": 4, "roll": 4, "range": 3, "time": 2},
}

DUAL_ANTENNA_BASELINES = ("along", "across", "both")

_BUS_FIELDS = (
    "gnss_lat_deg", "gnss_lon_deg", "gnss_alt_m", "gnss_geoid_sep_m", "gnss_fix_quality",
    "gnss_num_sats", "gnss_hdop", "gnss_speed_mps", "gnss_course_rad", "gnss_yaw_rad",
    "gnss_pitch_rad", "gnss_roll_rad", "gnss_yaw_sigma_rad", "gnss_pitch_sigma_rad",
    "gnss_roll_sigma_rad",
)
check_fields(_BUS_FIELDS)  # every name this module puts on the bus is in the catalogue


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ParsedSentence:
    """A decoded sentence.

    ``sentence``: layout name (see the module table); ``talker``: e.g. ``GP``, ``GN`` (empty for
    proprietary sentences); ``sample_kind``: ``gnss_pos``/``gnss_vel``/``gnss_att``;
    ``fields``: catalogue name -> SI value, exactly what goes on the bus; ``valid``: the
    sentence's own validity (GGA quality 0/7/8, RMC status V, mode N, THS mode V, HPR QF 0,
    AVR quality 0 -> False); ``has_roll``: for attitude layouts whether a roll is in ``fields``
    (None otherwise); ``utc_time_s``: UTC seconds of day printed in the sentence (None if
    absent); ``extras``: decoded values that are not bus fields (heave, quality flags, RMC
    position, range, ...); ``skipped_prefix``: characters of garbage before the ``$``.
    """

    sentence: str
    talker: str
    sample_kind: str
    fields: Mapping[str, float]
    valid: bool = True
    has_roll: bool | None = None
    utc_time_s: float | None = None
    extras: Mapping[str, object] = field(default_factory=dict)
    skipped_prefix: int = 0


@dataclass(frozen=True)
class Reject:
    """Why a line was not decoded (``reason`` in ``REJECT_REASONS``) and a short detail."""

    reason: str
    detail: str = ""


class _Bad(Exception):
    def __init__(self, reason: str, detail: str = ""):
        super().__init__(reason, detail)
        self.reason = reason
        self.detail = detail


# --------------------------------------------------------------------------------------------
# Checksum and sentence assembly
# --------------------------------------------------------------------------------------------

def nmea_checksum(body: str | bytes) -> int:
    """XOR of the bytes of ``body`` (the text between ``$`` and ``*``)."""
    data = body.encode("ascii") if isinstance(body, str) else body
    cs = 0
    for b in data:
        cs ^= b
    return cs


def wrap_sentence(body: str) -> bytes:
    """``$`` + body + ``*hh`` + CR LF (uppercase hex checksum)."""
    return f"${body}*{nmea_checksum(body):02X}\r\n".encode("ascii")


# --------------------------------------------------------------------------------------------
# Number formatting (generator side)
# --------------------------------------------------------------------------------------------

def _fmt_time(utc_time_s: float, decimals: int) -> str:
    """Seconds of day -> hhmmss.ss (rounded, carried, wrapped at midnight)."""
    scale = 10 ** decimals
    u = int(round(utc_time_s * scale)) % (86400 * scale)
    hh, rem = divmod(u, 3600 * scale)
    mm, rem = divmod(rem, 60 * scale)
    ss, frac = divmod(rem, scale)
    return f"{hh:02d}{mm:02d}{ss:02d}" + (f".{frac:0{decimals}d}" if decimals else "")


def _fmt_latlon(value_deg: float, deg_digits: int, decimals: int, hemis: str) -> tuple[str, str]:
    """Degrees -> (d..dmm.mmmm, hemisphere letter), rounded in integer units so minutes never
    print as 60."""
    scale = 10 ** decimals
    u = int(round(abs(value_deg) * 60.0 * scale))
    deg, rem = divmod(u, 60 * scale)
    mins, frac = divmod(rem, scale)
    hemi = hemis[0] if value_deg >= 0.0 else hemis[1]
    return f"{deg:0{deg_digits}d}{mins:02d}.{frac:0{decimals}d}", hemi


def _fmt_heading(heading_deg: float, decimals: int, width: int = 0) -> str:
    """Heading [0, 360) rounded to ``decimals``; 359.996 prints as 0.00, never 360.00."""
    scale = 10 ** decimals
    u = int(round((heading_deg % 360.0) * scale)) % (360 * scale)
    return f"{u / scale:0{width}.{decimals}f}"


def _fmt(value: float | None, decimals: int, width: int = 0, sign: bool = False) -> str:
    if value is None:
        return ""
    spec = f"{'+' if sign else ''}0{width}.{decimals}f"
    return format(value, spec)


def _deg(rad: float) -> float:
    return math.degrees(rad)


# --------------------------------------------------------------------------------------------
# Generators
# --------------------------------------------------------------------------------------------

def format_gga(utc_time_s: float, lat_deg: float, lon_deg: float, alt_m: float, *,
               fix_quality: int = 4, num_sats: int = 12, hdop: float = 0.8,
               geoid_sep_m: float | None = None, diff_age_s: float | None = None,
               diff_station: int | None = None, talker: str = "GP",
               lat_decimals: int = 6) -> bytes:
    """GGA fix data. ``alt_m`` above mean sea level; ``geoid_sep_m`` printed if given."""
    lat, ns = _fmt_latlon(lat_deg, 2, lat_decimals, "NS")
    lon, ew = _fmt_latlon(lon_deg, 3, lat_decimals, "EW")
    geoid = _fmt(geoid_sep_m, 3)
    body = ",".join([
        f"{talker}GGA", _fmt_time(utc_time_s, 2), lat, ns, lon, ew, str(int(fix_quality)),
        f"{int(num_sats):02d}", _fmt(hdop, 1), _fmt(alt_m, 3), "M", geoid, "M" if geoid else "",
        _fmt(diff_age_s, 1), "" if diff_station is None else f"{int(diff_station):04d}",
    ])
    return wrap_sentence(body)


def format_rmc(utc_time_s: float, lat_deg: float, lon_deg: float, speed_mps: float,
               course_rad: float | None, *, date: _dt.date = _dt.date(2012, 11, 19),
               status: str = "A", mode: str = "A", talker: str = "GP",
               lat_decimals: int = 6) -> bytes:
    """RMC; ``course_rad`` is the course over ground as a paper yaw (None prints an empty
    course, as receivers do when standing still)."""
    lat, ns = _fmt_latlon(lat_deg, 2, lat_decimals, "NS")
    lon, ew = _fmt_latlon(lon_deg, 3, lat_decimals, "EW")
    course = "" if course_rad is None else _fmt_heading(yaw_to_heading(course_rad), 3)
    body = ",".join([
        f"{talker}RMC", _fmt_time(utc_time_s, 2), status, lat, ns, lon, ew,
        _fmt(speed_mps / KNOT_MPS, 3), course, date.strftime("%d%m%y"), "", "", mode,
    ])
    return wrap_sentence(body)


def format_vtg(course_rad: float | None, speed_mps: float, *, mode: str = "A",
               talker: str = "GP") -> bytes:
    """VTG: true course (paper yaw in, heading printed), speed in knots and km/h."""
    course = "" if course_rad is None else _fmt_heading(yaw_to_heading(course_rad), 3)
    body = ",".join([
        f"{talker}VTG", course, "T", "", "M", _fmt(speed_mps / KNOT_MPS, 3), "N",
        _fmt(speed_mps / KMH_MPS, 3), "K", mode,
    ])
    return wrap_sentence(body)


def format_hdt(yaw_rad: float, *, talker: str = "GP") -> bytes:
    """HDT true heading from a paper yaw."""
    return wrap_sentence(f"{talker}HDT,{_fmt_heading(yaw_to_heading(yaw_rad), 2)},T")


def format_ths(yaw_rad: float, *, mode: str = "A", talker: str = "GN") -> bytes:
    """THS true heading and status from a paper yaw."""
    return wrap_sentence(f"{talker}THS,{_fmt_heading(yaw_to_heading(yaw_rad), 2)},{mode}")


def format_attitude(layout: str, *, utc_time_s: float, yaw_rad: float,
                    pitch_rad: float | None = None, roll_rad: float | None = None,
                    yaw_sigma_rad: float | None = None, pitch_sigma_rad: float | None = None,
                    roll_sigma_rad: float | None = None, heave_m: float = 0.0,
                    quality: int = 4, ins_status: int = 1, num_sats: int = 14,
                    baseline_m: float = 1.5, pdop: float = 1.4, talker: str = "GN",
                    signs: Mapping[str, AttitudeSign] = ATTITUDE_SIGN) -> bytes:
    """One attitude sentence of ``layout`` (``ATTITUDE_LAYOUTS`` or ``HDT``/``THS``) from paper
    angles [rad]. Pitch/roll are printed in the vendor's sign (``signs[layout]``); a pitch or
    roll of None leaves its slot empty (two-antenna layouts fill one of them). PASHR needs both
    and prints the sigmas (1-sigma, 0 if not given) as its accuracies; ``quality`` is the GNSS
    quality / QF / AVR quality flag and ``ins_status`` the PASHR INS status."""
    if layout == "HDT":
        return format_hdt(yaw_rad, talker=talker)
    if layout == "THS":
        return format_ths(yaw_rad, talker=talker)
    if layout not in ATTITUDE_LAYOUTS:
        raise ValueError(f"unknown attitude layout {layout!r}; "
                         f"one of {ATTITUDE_LAYOUTS} or HDT/THS")
    sgn = signs[layout]
    heading = yaw_to_heading(yaw_rad)
    pitch_pr = None if pitch_rad is None else _deg(pitch_rad) / sgn.pitch_to_paper
    roll_pr = None if roll_rad is None else _deg(roll_rad) / sgn.roll_to_paper
    if layout == "PASHR":
        if pitch_pr is None or roll_pr is None:
            raise ValueError("PASHR prints both pitch and roll")

        def acc(s):
            return _fmt(0.0 if s is None else _deg(s), 3)
        body = ",".join([
            "PASHR", _fmt_time(utc_time_s, 3), _fmt_heading(heading, 2, 6), "T",
            _fmt(roll_pr, 2, 6, sign=True), _fmt(pitch_pr, 2, 6, sign=True),
            _fmt(heave_m, 2, 6, sign=True), acc(roll_sigma_rad), acc(pitch_sigma_rad),
            acc(yaw_sigma_rad), str(int(quality)), str(int(ins_status)),
        ])
    elif layout == "PASHR,HPR":
        n_vec = 2 if (pitch_pr is not None and roll_pr is not None) else 1
        body = ",".join([
            "PASHR", "HPR", _fmt_time(utc_time_s, 2), _fmt_heading(heading, 3, 7),
            _fmt(pitch_pr, 3), _fmt(roll_pr, 3), "0.0021", "0.0034", "0", "0",
            f"{n_vec}.{'99' if n_vec == 2 else '90'}0", _fmt(pdop, 1),
        ])
    elif layout == "HPR":
        body = ",".join([
            f"{talker}HPR", _fmt_time(utc_time_s, 2), _fmt_heading(heading, 2, 6),
            _fmt(pitch_pr, 2, 6), _fmt(roll_pr, 2, 6), str(int(quality)), f"{int(num_sats):02d}",
            "1.00", "0004",
        ])
    else:  # PTNL,AVR
        yaw_pr = heading if heading <= 180.0 else heading - 360.0
        body = ",".join([
            "PTNL", "AVR", _fmt_time(utc_time_s, 2), _fmt(yaw_pr, 4, sign=True), "Yaw",
            _fmt(pitch_pr, 4, sign=True), "Tilt" if pitch_pr is not None else "",
            _fmt(roll_pr, 4, sign=True), "Roll" if roll_pr is not None else "",
            _fmt(baseline_m, 3), str(int(quality)), _fmt(pdop, 1), str(int(num_sats)),
        ])
    return wrap_sentence(body)


# --------------------------------------------------------------------------------------------
# Field parsing (parser side)
# --------------------------------------------------------------------------------------------

_NUM_RE = re.compile(r"^[+-]?(?:\d+(?:\.\d*)?|\.\d+)$")
_INT_RE = re.compile(r"^[+-]?\d+$")
_TIME_RE = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d*)?)$")
_LAT_RE = re.compile(r"^(\d{2})(\d{2}(?:\.\d*)?)$")
_LON_RE = re.compile(r"^(\d{3})(\d{2}(?:\.\d*)?)$")
_ADDR_RE = re.compile(r"^[A-Z0-9]{2,8}$")


class _Fields:
    """The comma-separated data fields of a sentence (after the address), with typed getters
    that raise ``_Bad`` on malformed content."""

    def __init__(self, items: list[str], name: str):
        self.items = items
        self.name = name

    def need(self, n: int) -> None:
        if len(self.items) < n:
            raise _Bad("truncated", f"{self.name}: {len(self.items)} fields, needs {n}")

    def raw(self, i: int) -> str:
        return self.items[i] if i < len(self.items) else ""

    def num(self, i: int, what: str, required: bool = True, lo: float = -math.inf,
            hi: float = math.inf) -> float | None:
        s = self.raw(i)
        if s == "":
            if required:
                raise _Bad("empty_field", f"{self.name}: {what} empty")
            return None
        if not _NUM_RE.match(s):
            raise _Bad("bad_field", f"{self.name}: {what}={s!r}")
        v = float(s)
        if not (lo <= v <= hi):
            raise _Bad("bad_field", f"{self.name}: {what}={s} out of [{lo}, {hi}]")
        return v

    def int_(self, i: int, what: str, required: bool = True, lo: int = 0,
             hi: int = 1 << 31) -> int | None:
        s = self.raw(i)
        if s == "":
            if required:
                raise _Bad("empty_field", f"{self.name}: {what} empty")
            return None
        if not _INT_RE.match(s):
            raise _Bad("bad_field", f"{self.name}: {what}={s!r}")
        v = int(s)
        if not (lo <= v <= hi):
            raise _Bad("bad_field", f"{self.name}: {what}={s} out of [{lo}, {hi}]")
        return v

    def char(self, i: int, what: str, allowed: str, required: bool = True) -> str:
        s = self.raw(i)
        if s == "":
            if required:
                raise _Bad("empty_field", f"{self.name}: {what} empty")
            return ""
        if len(s) != 1 or s not in allowed:
            raise _Bad("bad_field", f"{self.name}: {what}={s!r} not one of {allowed!r}")
        return s

    def time(self, i: int) -> float | None:
        s = self.raw(i)
        if s == "":
            return None
        m = _TIME_RE.match(s)
        if not m:
            raise _Bad("bad_field", f"{self.name}: time={s!r}")
        h, mi, sec = int(m.group(1)), int(m.group(2)), float(m.group(3))
        if h > 23 or mi > 59 or sec >= 61.0:
            raise _Bad("bad_field", f"{self.name}: time={s!r}")
        return h * 3600.0 + mi * 60.0 + sec

    def latlon(self, i: int, is_lat: bool, required: bool) -> float | None:
        s, hemi = self.raw(i), self.raw(i + 1)
        what = "lat" if is_lat else "lon"
        if s == "" or hemi == "":
            if required:
                raise _Bad("empty_field", f"{self.name}: {what} empty")
            return None
        m = (_LAT_RE if is_lat else _LON_RE).match(s)
        if not m:
            raise _Bad("bad_field", f"{self.name}: {what}={s!r}")
        deg, mins = int(m.group(1)), float(m.group(2))
        val = deg + mins / 60.0
        if mins >= 60.0 or val > (90.0 if is_lat else 180.0):
            raise _Bad("bad_field", f"{self.name}: {what}={s!r} out of range")
        if hemi not in ("NS" if is_lat else "EW"):
            raise _Bad("bad_field", f"{self.name}: {what} hemisphere {hemi!r}")
        return -val if hemi in "SW" else val


def _put(fields: dict, name: str, value: float | None) -> None:
    if value is not None:
        fields[name] = float(value)


def _heading_yaw(f: _Fields, i: int, what: str = "heading", signed_ok: bool = False) -> float:
    lo = -180.0 if signed_ok else 0.0
    h = f.num(i, what, lo=lo, hi=360.0)
    return heading_to_yaw(h % 360.0)


# --------------------------------------------------------------------------------------------
# Per-layout parsers: (fields, talker) -> ParsedSentence pieces
# --------------------------------------------------------------------------------------------

def _parse_gga(f: _Fields, talker: str, **_) -> ParsedSentence:
    f.need(14)
    t = f.time(0)
    q = f.int_(5, "quality", hi=9)
    have_fix = q != 0
    out: dict[str, float] = {}
    _put(out, "gnss_lat_deg", f.latlon(1, True, required=have_fix))
    _put(out, "gnss_lon_deg", f.latlon(3, False, required=have_fix))
    out["gnss_fix_quality"] = float(q)
    _put(out, "gnss_num_sats", f.int_(6, "satellites", required=False, hi=999))
    _put(out, "gnss_hdop", f.num(7, "hdop", required=False, lo=0.0))
    alt = f.num(8, "altitude", required=have_fix, lo=-1.0e5, hi=1.0e6)
    if alt is not None:
        f.char(9, "altitude unit", "M")
    _put(out, "gnss_alt_m", alt)
    geoid = f.num(10, "geoid separation", required=False, lo=-1.0e3, hi=1.0e3)
    if geoid is not None:
        f.char(11, "geoid unit", "M")
    _put(out, "gnss_geoid_sep_m", geoid)
    extras = {"diff_age_s": f.num(12, "diff age", required=False, lo=0.0),
              "diff_station": f.raw(13)}
    return ParsedSentence("GGA", talker, "gnss_pos", out, valid=q not in (0, 7, 8),
                          utc_time_s=t, extras=extras)


def _mode_valid(mode: str) -> bool:
    return mode != "N"


def _parse_rmc(f: _Fields, talker: str, **_) -> ParsedSentence:
    f.need(11)
    t = f.time(0)
    status = f.char(1, "status", "AV")
    ok = status == "A"
    lat = f.latlon(2, True, required=ok)
    lon = f.latlon(4, False, required=ok)
    out: dict[str, float] = {}
    kn = f.num(6, "speed", required=ok, lo=0.0)
    _put(out, "gnss_speed_mps", None if kn is None else kn * KNOT_MPS)
    course = f.num(7, "course", required=False, lo=0.0, hi=360.0)
    _put(out, "gnss_course_rad", None if course is None else heading_to_yaw(course % 360.0))
    mode = f.char(11, "mode", "ADEFMNPRS", required=False)
    extras = {"lat_deg": lat, "lon_deg": lon, "date_ddmmyy": f.raw(8), "mode": mode}
    return ParsedSentence("RMC", talker, "gnss_vel", out, valid=ok and _mode_valid(mode),
                          utc_time_s=t, extras=extras)


def _parse_vtg(f: _Fields, talker: str, **_) -> ParsedSentence:
    f.need(8)
    out: dict[str, float] = {}
    course = f.num(0, "course", required=False, lo=0.0, hi=360.0)
    _put(out, "gnss_course_rad", None if course is None else heading_to_yaw(course % 360.0))
    kn = f.num(4, "speed kn", required=False, lo=0.0)
    kmh = f.num(6, "speed km/h", required=False, lo=0.0)
    if kn is not None:
        out["gnss_speed_mps"] = kn * KNOT_MPS
    elif kmh is not None:
        out["gnss_speed_mps"] = kmh * KMH_MPS
    else:
        raise _Bad("empty_field", "VTG: no speed")
    mode = f.char(8, "mode", "ADEFMNPRS", required=False)
    return ParsedSentence("VTG", talker, "gnss_vel", out, valid=_mode_valid(mode),
                          extras={"mode": mode})


def _parse_hdt(f: _Fields, talker: str, **_) -> ParsedSentence:
    f.need(2)
    yaw = _heading_yaw(f, 0)
    f.char(1, "true flag", "T")
    return ParsedSentence("HDT", talker, "gnss_att", {"gnss_yaw_rad": yaw}, has_roll=False)


def _parse_ths(f: _Fields, talker: str, **_) -> ParsedSentence:
    f.need(2)
    mode = f.char(1, "mode", "AEMSV")
    out: dict[str, float] = {}
    h = f.num(0, "heading", required=mode != "V", lo=0.0, hi=360.0)
    _put(out, "gnss_yaw_rad", None if h is None else heading_to_yaw(h % 360.0))
    return ParsedSentence("THS", talker, "gnss_att", out, valid=mode in "AE", has_roll=False,
                          extras={"mode": mode})


def _sigma(f: _Fields, i: int, what: str) -> float | None:
    v = f.num(i, what, required=False, lo=0.0, hi=360.0)
    return None if v is None else math.radians(v)


def _parse_pashr(f: _Fields, talker: str, *, signs, **_) -> ParsedSentence:
    f.need(10)
    sgn = signs["PASHR"]
    t = f.time(0)
    out: dict[str, float] = {"gnss_yaw_rad": _heading_yaw(f, 1)}
    f.char(2, "true flag", "T")
    roll = f.num(3, "roll", lo=-180.0, hi=180.0)
    pitch = f.num(4, "pitch", lo=-90.0, hi=90.0)
    out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(pitch)
    out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    _put(out, "gnss_roll_sigma_rad", _sigma(f, 6, "roll accuracy"))
    _put(out, "gnss_pitch_sigma_rad", _sigma(f, 7, "pitch accuracy"))
    _put(out, "gnss_yaw_sigma_rad", _sigma(f, 8, "heading accuracy"))
    extras = {"heave_m": f.num(5, "heave", required=False),
              "gnss_quality": f.int_(9, "GNSS quality", required=False, hi=99),
              "ins_status": f.int_(10, "INS status", required=False, hi=99)}
    return ParsedSentence("PASHR", "", "gnss_att", out, has_roll=True, utc_time_s=t,
                          extras=extras)


def _dual_slots(baseline: str) -> tuple[bool, bool]:
    """(pitch slot used, roll slot used) for a two-antenna installation."""
    return {"along": (True, False), "across": (False, True), "both": (True, True)}[baseline]


def _parse_pashr_hpr(f: _Fields, talker: str, *, signs, baseline, **_) -> ParsedSentence:
    f.need(8)  # HPR, time, heading, pitch, roll, carrier RMS, baseline RMS, ambiguity
    sgn = signs["PASHR,HPR"]
    t = f.time(1)
    out: dict[str, float] = {"gnss_yaw_rad": _heading_yaw(f, 2)}
    use_p, use_r = _dual_slots(baseline)
    pitch = f.num(3, "pitch", required=False, lo=-90.0, hi=90.0)
    roll = f.num(4, "roll", required=False, lo=-90.0, hi=90.0)
    if use_p and pitch is not None:
        out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(pitch)
    if use_r and roll is not None:
        out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    extras = {"carrier_rms_m": f.num(5, "carrier RMS", required=False, lo=0.0),
              "baseline_rms_m": f.num(6, "baseline RMS", required=False, lo=0.0),
              "ambiguity": f.int_(7, "ambiguity", required=False),
              "pitch_printed_deg": pitch, "roll_printed_deg": roll}
    return ParsedSentence("PASHR,HPR", "", "gnss_att", out, has_roll="gnss_roll_rad" in out,
                          utc_time_s=t, extras=extras)


def _parse_hpr(f: _Fields, talker: str, *, signs, baseline, **_) -> ParsedSentence:
    f.need(5)  # time, heading, pitch, roll, QF
    sgn = signs["HPR"]
    t = f.time(0)
    qf = f.int_(4, "QF", hi=9)
    out: dict[str, float] = {}
    if qf != 0:
        out["gnss_yaw_rad"] = _heading_yaw(f, 1)
    use_p, use_r = _dual_slots(baseline)
    pitch = f.num(2, "pitch", required=False, lo=-90.0, hi=90.0)
    roll = f.num(3, "roll", required=False, lo=-180.0, hi=180.0)
    if qf != 0 and use_p and pitch is not None:
        out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(pitch)
    if qf != 0 and use_r and roll is not None:
        out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    extras = {"qf": qf, "num_sats": f.int_(5, "satellites", required=False, hi=999),
              "pitch_printed_deg": pitch, "roll_printed_deg": roll}
    return ParsedSentence("HPR", talker, "gnss_att", out, valid=qf != 0,
                          has_roll="gnss_roll_rad" in out, utc_time_s=t, extras=extras)


def _parse_ptnl_avr(f: _Fields, talker: str, *, signs, **_) -> ParsedSentence:
    f.need(10)  # AVR, time, yaw, Yaw, tilt, Tilt, roll, Roll, range, quality
    sgn = signs["PTNL,AVR"]
    t = f.time(1)
    q = f.int_(9, "quality", hi=9)
    out: dict[str, float] = {}
    if f.raw(3) != "Yaw":
        raise _Bad("bad_field", f"AVR: yaw label {f.raw(3)!r}")
    yaw = f.num(2, "yaw", required=q != 0, lo=-360.0, hi=360.0)
    if yaw is not None:
        out["gnss_yaw_rad"] = heading_to_yaw(yaw % 360.0)
    tilt = f.num(4, "tilt", required=False, lo=-90.0, hi=90.0)
    if tilt is not None:
        if f.raw(5) != "Tilt":
            raise _Bad("bad_field", f"AVR: tilt label {f.raw(5)!r}")
        out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(tilt)
    roll = f.num(6, "roll", required=False, lo=-90.0, hi=90.0)
    if roll is not None:
        if f.raw(7) != "Roll":
            raise _Bad("bad_field", f"AVR: roll label {f.raw(7)!r}")
        out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    extras = {"range_m": f.num(8, "range", required=False, lo=0.0), "quality": q,
              "pdop": f.num(10, "PDOP", required=False, lo=0.0),
              "num_sats": f.int_(11, "satellites", required=False, hi=999)}
    return ParsedSentence("PTNL,AVR", "", "gnss_att", out, valid=q != 0,
                          has_roll="gnss_roll_rad" in out, utc_time_s=t, extras=extras)


_STANDARD = {"GGA": _parse_gga, "RMC": _parse_rmc, "VTG": _parse_vtg, "HDT": _parse_hdt,
             "THS": _parse_ths, "HPR": _parse_hpr}


# --------------------------------------------------------------------------------------------
# Sentence parser
# --------------------------------------------------------------------------------------------

def _split_checksum(text: str, lenient: bool) -> str:
    """Return the body between ``$`` and ``*`` after checking the checksum."""
    star = text.find("*")
    if star < 0:
        if lenient:
            return text[1:]
        raise _Bad("missing_checksum", "no '*hh'")
    tail = text[star + 1:]
    if len(tail) != 2 or any(ch not in "0123456789ABCDEFabcdef" for ch in tail):
        raise _Bad("malformed_checksum", f"checksum field {tail[:8]!r}")
    body = text[1:star]
    if "*" in body:
        raise _Bad("malformed_checksum", "more than one '*'")
    want, got = int(tail, 16), nmea_checksum(body)
    if want != got:
        raise _Bad("bad_checksum", f"printed {want:02X}, computed {got:02X}")
    return body


def _parse(line: bytes | str, lenient: bool, baseline: str,
           signs: Mapping[str, AttitudeSign]) -> ParsedSentence | Reject:
    if isinstance(line, (bytes, bytearray, memoryview)):
        raw = bytes(line).strip()
        if not raw:
            raise _Bad("empty")
        start = max(raw.rfind(b"$"), raw.rfind(b"!"))
        tail = raw[max(start, 0):]
        if any(b > 0x7E or b < 0x20 for b in tail):
            raise _Bad("not_ascii", "byte outside printable ASCII")
        if start < 0:
            raise _Bad("no_start", repr(raw[:16]))
        text = tail.decode("ascii")
    elif isinstance(line, str):
        stripped = line.strip()
        if not stripped:
            raise _Bad("empty")
        start = max(stripped.rfind("$"), stripped.rfind("!"))
        text = stripped[max(start, 0):]
        if any(ord(ch) > 0x7E or ord(ch) < 0x20 for ch in text):
            raise _Bad("not_ascii", "character outside printable ASCII")
        if start < 0:
            raise _Bad("no_start", stripped[:16])
    else:
        raise _Bad("empty", f"not text: {type(line).__name__}")
    skipped = start
    body = _split_checksum(text, lenient)
    parts = body.split(",")
    addr = parts[0]
    if not _ADDR_RE.match(addr):
        raise _Bad("bad_field", f"address {addr[:10]!r}")
    data = parts[1:]
    if addr == "PASHR":
        if data and data[0].isalpha():
            if data[0] != "HPR":
                raise _Bad("unsupported", f"PASHR,{data[0][:6]}")
            res = _parse_pashr_hpr(_Fields(data, "PASHR,HPR"), "", signs=signs, baseline=baseline)
        else:
            res = _parse_pashr(_Fields(data, "PASHR"), "", signs=signs)
    elif addr == "PTNL":
        if not data or data[0] != "AVR":
            raise _Bad("unsupported", f"PTNL,{(data[0] if data else '')[:6]}")
        res = _parse_ptnl_avr(_Fields(data, "PTNL,AVR"), "", signs=signs)
    elif addr.startswith("P") or len(addr) != 5:
        raise _Bad("unsupported", addr)
    else:
        talker, kind = addr[:2], addr[2:]
        fn = _STANDARD.get(kind)
        if fn is None:
            raise _Bad("unsupported", addr)
        res = fn(_Fields(data, kind), talker, signs=signs, baseline=baseline)
    if skipped:
        res = ParsedSentence(res.sentence, res.talker, res.sample_kind, res.fields, res.valid,
                             res.has_roll, res.utc_time_s, res.extras, skipped)
    return res


def parse_sentence(line: bytes | str, *, lenient_checksum: bool = False,
                   dual_antenna_baseline: str = "along",
                   signs: Mapping[str, AttitudeSign] = ATTITUDE_SIGN) -> ParsedSentence | Reject:
    """Parse one NMEA line (with or without CR LF). Never raises: bad input gives a ``Reject``.

    ``lenient_checksum``: accept sentences without ``*hh`` (a wrong checksum is still rejected).
    ``dual_antenna_baseline``: ``along``/``across``/``both`` for PASHR,HPR and HPR.
    ``signs``: the sign table (``ATTITUDE_SIGN``; pass a modified copy to override one layout).
    """
    if dual_antenna_baseline not in DUAL_ANTENNA_BASELINES:
        return Reject("internal_error", f"bad dual_antenna_baseline {dual_antenna_baseline!r}")
    try:
        return _parse(line, lenient_checksum, dual_antenna_baseline, signs)
    except _Bad as e:
        return Reject(e.reason, e.detail)
    except Exception as e:  # a bug: never let it out of the codec, but make it visible
        return Reject("internal_error", f"{type(e).__name__}: {e}")


# --------------------------------------------------------------------------------------------
# Decoder: lines -> bus samples, with counters
# --------------------------------------------------------------------------------------------

class NmeaDecoder:
    """Decode NMEA lines of one device into bus ``Sample``s (kinds ``gnss_pos``, ``gnss_vel``,
    ``gnss_att``), counting everything.

    ``feed_line(t_ns, line)`` returns zero or one sample; ``t_ns`` is the line's receive time
    (``codecs.framing.LineFramer``). A sentence flagged invalid by the receiver still gives a
    sample with ``valid=False`` (the gap stays visible). Counters (read-only ``counters``):
    ``lines``, ``samples``, ``invalid_samples``, ``unsupported``, ``rejected``,
    ``reject_<reason>`` per reason, ``garbage_prefix`` and ``sentence_<layout>`` per layout.
    """

    def __init__(self, source: str = "gnss", *, lenient_checksum: bool = False,
                 dual_antenna_baseline: str = "along",
                 sign_overrides: Mapping[str, AttitudeSign] | None = None):
        if dual_antenna_baseline not in DUAL_ANTENNA_BASELINES:
            raise ValueError(f"dual_antenna_baseline must be one of {DUAL_ANTENNA_BASELINES}")
        self.source = source
        self.lenient_checksum = bool(lenient_checksum)
        self.dual_antenna_baseline = dual_antenna_baseline
        signs = dict(ATTITUDE_SIGN)
        if sign_overrides:
            unknown = set(sign_overrides) - set(ATTITUDE_SIGN)
            if unknown:
                raise ValueError(f"sign overrides for unknown layouts {sorted(unknown)}")
            signs.update(sign_overrides)
        self.signs: Mapping[str, AttitudeSign] = MappingProxyType(signs)
        self._counters: dict[str, int] = {"lines": 0, "samples": 0, "invalid_samples": 0,
                                          "unsupported": 0, "rejected": 0, "garbage_prefix": 0}
        for r in REJECT_REASONS:
            if r != "unsupported":
                self._counters[f"reject_{r}"] = 0
        self.last: ParsedSentence | None = None
        """The last decoded sentence (extras such as heave or RMC position live there)."""

    @property
    def counters(self) -> Mapping[str, int]:
        return MappingProxyType(self._counters)

    def feed_line(self, t_ns: int, line: bytes | str) -> list[Sample]:
        c = self._counters
        c["lines"] += 1
        r = parse_sentence(line, lenient_checksum=self.lenient_checksum,
                           dual_antenna_baseline=self.dual_antenna_baseline, signs=self.signs)
        if isinstance(r, Reject):
            if r.reason == "unsupported":
                c["unsupported"] += 1
            else:
                c["rejected"] += 1
                c[f"reject_{r.reason}"] += 1
            return []
        self.last = r
        if r.skipped_prefix:
            c["garbage_prefix"] += 1
        key = f"sentence_{r.sentence}"
        c[key] = c.get(key, 0) + 1
        c["samples"] += 1
        if not r.valid:
            c["invalid_samples"] += 1
        return [Sample(t_ns=int(t_ns), source=self.source, kind=r.sample_kind,
                       fields=dict(r.fields), valid=r.valid)]
