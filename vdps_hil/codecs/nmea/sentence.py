"""The frame of an NMEA 0183 sentence and what decoding one gives: the checksum both ways, the
layout tables, the printed precision and the result types (``ParsedSentence``, ``Reject``).

Checksum: ``*hh`` after the body is the XOR of every byte between ``$`` and ``*`` as two hex
digits. Sentences end with CR LF.

Value precision the generators print (as real receivers do): GGA lat/lon 6 decimals of minutes
(OxTS), alt 3 decimals, HDOP 1; RMC/VTG speed and course 3; HDT/THS heading 2; PASHR heading,
roll, pitch, heave 2 and accuracies 3 with the time in ms (OxTS); PASHR,HPR angles 3, RMS 4;
HPR angles 2 (Unicore/ComNav); PTNL,AVR angles 4, range 3 (Trimble). ``PRINT_DECIMALS`` holds
these for tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

from vdps_hil.bus.samples import check_fields

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
check_fields(_BUS_FIELDS)  # every name the NMEA codec puts on the bus is in the catalogue


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ParsedSentence:
    """A decoded sentence.

    ``sentence``: layout name (see the package table); ``talker``: e.g. ``GP``, ``GN`` (empty
    for proprietary sentences); ``sample_kind``: ``gnss_pos``/``gnss_vel``/``gnss_att``;
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


class SentenceError(Exception):
    """Raised inside the parser on bad input; ``parse_sentence`` turns it into a ``Reject``."""

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


def split_checksum(text: str, lenient: bool) -> str:
    """Return the body between ``$`` and ``*`` after checking the checksum."""
    star = text.find("*")
    if star < 0:
        if lenient:
            return text[1:]
        raise SentenceError("missing_checksum", "no '*hh'")
    tail = text[star + 1:]
    if len(tail) != 2 or any(ch not in "0123456789ABCDEFabcdef" for ch in tail):
        raise SentenceError("malformed_checksum", f"checksum field {tail[:8]!r}")
    body = text[1:star]
    if "*" in body:
        raise SentenceError("malformed_checksum", "more than one '*'")
    want, got = int(tail, 16), nmea_checksum(body)
    if want != got:
        raise SentenceError("bad_checksum", f"printed {want:02X}, computed {got:02X}")
    return body
