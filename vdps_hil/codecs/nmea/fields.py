"""One NMEA field both ways: number formatting for the generators (time, lat/lon, heading,
fixed decimals) and the typed getters of the parser (``Fields``), which raise
``SentenceError`` on malformed content.

Printed forms::

    time     hhmmss.ss            seconds of day, rounded, carried, wrapped at midnight
    lat/lon  ddmm.mmmm / dddmm.mmmm + hemisphere letter; rounded in integer units of the last
             digit so the minutes never print as 60
    heading  [0, 360) rounded to the printed decimals; 359.996 prints as 0.00, never 360.00

Bounded fields. Every numeric getter takes the field's physical range (no defaults): a value
outside it -- or a number so long that it parses to inf or 1e299 -- is a ``bad_field`` reject,
counted by the decoder, never a sample. The ranges (``RANGE_*`` below), wide enough for any
road vehicle and any receiver's printing, narrow enough that a decoded value is physical::

    speed over ground     0 .. 1000 kn = 0 .. 1852 km/h (514.4 m/s; 1000 kn is the COCOM
                          export limit built into GNSS receivers)
    course, heading       0 .. 360 deg (THS, HDT, RMC, VTG, PASHR); PTNL,AVR yaw -360 .. 360
    roll                  -180 .. 180 deg (PASHR, HPR), -90 .. 90 deg (two-antenna slots)
    pitch, tilt           -90 .. 90 deg
    HDOP, PDOP            0 .. 99.99 (receivers print 99.99 for "no solution")
    altitude (MSL)        -1000 .. 100,000 m (Dead Sea shore -430 m; 100 km: the Karman line)
    geoid separation      -200 .. 200 m (EGM96 spans -106 .. +85 m)
    heave                 -100 .. 100 m (PASHR)
    attitude accuracies   0 .. 180 deg (1-sigma)
    RMS, baseline length  0 .. 1000 m (PASHR,HPR carrier/baseline RMS, PTNL,AVR range)
    differential age      0 .. 86,400 s
    integers              stated per field (quality 0..9, satellites 0..999, ...), at most
                          18 digits
"""

from __future__ import annotations

import re

from vdps_hil.codecs.nmea.sentence import SentenceError
from vdps_hil.conventions import heading_to_yaw

# --------------------------------------------------------------------------------------------
# Number formatting (generator side)
# --------------------------------------------------------------------------------------------

def fmt_time(utc_time_s: float, decimals: int) -> str:
    """Seconds of day -> hhmmss.ss (rounded, carried, wrapped at midnight)."""
    scale = 10 ** decimals
    u = int(round(utc_time_s * scale)) % (86400 * scale)
    hh, rem = divmod(u, 3600 * scale)
    mm, rem = divmod(rem, 60 * scale)
    ss, frac = divmod(rem, scale)
    return f"{hh:02d}{mm:02d}{ss:02d}" + (f".{frac:0{decimals}d}" if decimals else "")


def fmt_latlon(value_deg: float, deg_digits: int, decimals: int, hemis: str) -> tuple[str, str]:
    """Degrees -> (d..dmm.mmmm, hemisphere letter), rounded in integer units so minutes never
    print as 60."""
    scale = 10 ** decimals
    u = int(round(abs(value_deg) * 60.0 * scale))
    deg, rem = divmod(u, 60 * scale)
    mins, frac = divmod(rem, scale)
    hemi = hemis[0] if value_deg >= 0.0 else hemis[1]
    return f"{deg:0{deg_digits}d}{mins:02d}.{frac:0{decimals}d}", hemi


def fmt_heading(heading_deg: float, decimals: int, width: int = 0) -> str:
    """Heading [0, 360) rounded to ``decimals``; 359.996 prints as 0.00, never 360.00."""
    scale = 10 ** decimals
    u = int(round((heading_deg % 360.0) * scale)) % (360 * scale)
    return f"{u / scale:0{width}.{decimals}f}"


def fmt_num(value: float | None, decimals: int, width: int = 0, sign: bool = False) -> str:
    """``value`` with ``decimals`` decimals (zero-padded to ``width``, ``+`` if ``sign``);
    None prints an empty field."""
    if value is None:
        return ""
    spec = f"{'+' if sign else ''}0{width}.{decimals}f"
    return format(value, spec)


# --------------------------------------------------------------------------------------------
# Field parsing (parser side)
# --------------------------------------------------------------------------------------------

# physical ranges of the numeric fields (module docstring), (lo, hi) in the printed unit
RANGE_SPEED_KN = (0.0, 1000.0)
RANGE_SPEED_KMH = (0.0, 1852.0)
RANGE_HEADING_DEG = (0.0, 360.0)
RANGE_SIGNED_HEADING_DEG = (-360.0, 360.0)
RANGE_ROLL_DEG = (-180.0, 180.0)
RANGE_TILT_DEG = (-90.0, 90.0)
RANGE_DOP = (0.0, 99.99)
RANGE_ALTITUDE_M = (-1000.0, 100_000.0)
RANGE_GEOID_SEP_M = (-200.0, 200.0)
RANGE_HEAVE_M = (-100.0, 100.0)
RANGE_ACCURACY_DEG = (0.0, 180.0)
RANGE_LENGTH_M = (0.0, 1000.0)
RANGE_DIFF_AGE_S = (0.0, 86_400.0)
_MAX_INT_DIGITS = 18

_NUM_RE = re.compile(r"^[+-]?(?:\d+(?:\.\d*)?|\.\d+)$")
_INT_RE = re.compile(r"^[+-]?\d+$")
_TIME_RE = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d*)?)$")
_LAT_RE = re.compile(r"^(\d{2})(\d{2}(?:\.\d*)?)$")
_LON_RE = re.compile(r"^(\d{3})(\d{2}(?:\.\d*)?)$")


class Fields:
    """The comma-separated data fields of a sentence (after the address), with typed getters
    that raise ``SentenceError`` on malformed content."""

    def __init__(self, items: list[str], name: str):
        self.items = items
        self.name = name

    def need(self, n: int) -> None:
        if len(self.items) < n:
            raise SentenceError("truncated", f"{self.name}: {len(self.items)} fields, needs {n}")

    def raw(self, i: int) -> str:
        return self.items[i] if i < len(self.items) else ""

    def num(self, i: int, what: str, rng: tuple[float, float], required: bool = True
            ) -> float | None:
        """Field ``i`` as a float inside ``rng`` = (lo, hi), finite (module docstring)."""
        s = self.raw(i)
        if s == "":
            if required:
                raise SentenceError("empty_field", f"{self.name}: {what} empty")
            return None
        if not _NUM_RE.match(s):
            raise SentenceError("bad_field", f"{self.name}: {what}={s!r}")
        v = float(s)
        lo, hi = rng
        if not (lo <= v <= hi):  # finite bounds: inf (a 400-digit number) is outside too
            raise SentenceError("bad_field", f"{self.name}: {what}={s[:24]} out of [{lo}, {hi}]")
        return v

    def int_(self, i: int, what: str, hi: int, required: bool = True, lo: int = 0) -> int | None:
        """Field ``i`` as an integer in ``lo .. hi``."""
        s = self.raw(i)
        if s == "":
            if required:
                raise SentenceError("empty_field", f"{self.name}: {what} empty")
            return None
        if len(s) > _MAX_INT_DIGITS or not _INT_RE.match(s):
            raise SentenceError("bad_field", f"{self.name}: {what}={s[:24]!r}")
        v = int(s)
        if not (lo <= v <= hi):
            raise SentenceError("bad_field", f"{self.name}: {what}={s} out of [{lo}, {hi}]")
        return v

    def char(self, i: int, what: str, allowed: str, required: bool = True) -> str:
        s = self.raw(i)
        if s == "":
            if required:
                raise SentenceError("empty_field", f"{self.name}: {what} empty")
            return ""
        if len(s) != 1 or s not in allowed:
            raise SentenceError("bad_field", f"{self.name}: {what}={s!r} not one of {allowed!r}")
        return s

    def time(self, i: int) -> float | None:
        s = self.raw(i)
        if s == "":
            return None
        m = _TIME_RE.match(s)
        if not m:
            raise SentenceError("bad_field", f"{self.name}: time={s!r}")
        h, mi, sec = int(m.group(1)), int(m.group(2)), float(m.group(3))
        if h > 23 or mi > 59 or sec >= 61.0:
            raise SentenceError("bad_field", f"{self.name}: time={s!r}")
        return h * 3600.0 + mi * 60.0 + sec

    def latlon(self, i: int, is_lat: bool, required: bool) -> float | None:
        s, hemi = self.raw(i), self.raw(i + 1)
        what = "lat" if is_lat else "lon"
        if s == "" or hemi == "":
            if required:
                raise SentenceError("empty_field", f"{self.name}: {what} empty")
            return None
        m = (_LAT_RE if is_lat else _LON_RE).match(s)
        if not m:
            raise SentenceError("bad_field", f"{self.name}: {what}={s!r}")
        deg, mins = int(m.group(1)), float(m.group(2))
        val = deg + mins / 60.0
        if mins >= 60.0 or val > (90.0 if is_lat else 180.0):
            raise SentenceError("bad_field", f"{self.name}: {what}={s!r} out of range")
        if hemi not in ("NS" if is_lat else "EW"):
            raise SentenceError("bad_field", f"{self.name}: {what} hemisphere {hemi!r}")
        return -val if hemi in "SW" else val


def put_field(fields: dict, name: str, value: float | None) -> None:
    """``fields[name] = float(value)`` unless ``value`` is None (an empty printed field)."""
    if value is not None:
        fields[name] = float(value)


def heading_yaw(f: Fields, i: int, what: str = "heading", signed_ok: bool = False) -> float:
    """The heading printed in field ``i`` [deg, clockwise from N] as a paper yaw [rad]."""
    h = f.num(i, what, (-180.0, 360.0) if signed_ok else RANGE_HEADING_DEG)
    return heading_to_yaw(h % 360.0)
