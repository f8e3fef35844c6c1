"""``parse_sentence``: one NMEA line -> ``ParsedSentence`` or ``Reject``. Cleans the line, checks
the checksum (``sentence.split_checksum``) and hands the fields to the parser of the layout its
address names (``position``, ``attitude``).

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
"""

from __future__ import annotations

import re
from typing import Mapping

from vdps_hil.codecs.nmea.attitude import (
    parse_hdt, parse_hpr, parse_pashr, parse_pashr_hpr, parse_ptnl_avr, parse_ths,
)
from vdps_hil.codecs.nmea.fields import Fields
from vdps_hil.codecs.nmea.position import parse_gga, parse_rmc, parse_vtg
from vdps_hil.codecs.nmea.sentence import (
    DUAL_ANTENNA_BASELINES, ParsedSentence, Reject, SentenceError, split_checksum,
)
from vdps_hil.conventions import ATTITUDE_SIGN, AttitudeSign

_ADDR_RE = re.compile(r"^[A-Z0-9]{2,8}$")

_STANDARD = {"GGA": parse_gga, "RMC": parse_rmc, "VTG": parse_vtg, "HDT": parse_hdt,
             "THS": parse_ths, "HPR": parse_hpr}
"""Layouts with a talker address (``GP``/``GN``... + three letters) -> their parser."""


def _parse(line: bytes | str, lenient: bool, baseline: str,
           signs: Mapping[str, AttitudeSign]) -> ParsedSentence | Reject:
    if isinstance(line, (bytes, bytearray, memoryview)):
        raw = bytes(line).strip()
        if not raw:
            raise SentenceError("empty")
        start = max(raw.rfind(b"$"), raw.rfind(b"!"))
        tail = raw[max(start, 0):]
        if any(b > 0x7E or b < 0x20 for b in tail):
            raise SentenceError("not_ascii", "byte outside printable ASCII")
        if start < 0:
            raise SentenceError("no_start", repr(raw[:16]))
        text = tail.decode("ascii")
    elif isinstance(line, str):
        stripped = line.strip()
        if not stripped:
            raise SentenceError("empty")
        start = max(stripped.rfind("$"), stripped.rfind("!"))
        text = stripped[max(start, 0):]
        if any(ord(ch) > 0x7E or ord(ch) < 0x20 for ch in text):
            raise SentenceError("not_ascii", "character outside printable ASCII")
        if start < 0:
            raise SentenceError("no_start", stripped[:16])
    else:
        raise SentenceError("empty", f"not text: {type(line).__name__}")
    skipped = start
    body = split_checksum(text, lenient)
    parts = body.split(",")
    addr = parts[0]
    if not _ADDR_RE.match(addr):
        raise SentenceError("bad_field", f"address {addr[:10]!r}")
    data = parts[1:]
    if addr == "PASHR":
        if data and data[0].isalpha():
            if data[0] != "HPR":
                raise SentenceError("unsupported", f"PASHR,{data[0][:6]}")
            res = parse_pashr_hpr(Fields(data, "PASHR,HPR"), "", signs=signs, baseline=baseline)
        else:
            res = parse_pashr(Fields(data, "PASHR"), "", signs=signs)
    elif addr == "PTNL":
        if not data or data[0] != "AVR":
            raise SentenceError("unsupported", f"PTNL,{(data[0] if data else '')[:6]}")
        res = parse_ptnl_avr(Fields(data, "PTNL,AVR"), "", signs=signs)
    elif addr.startswith("P") or len(addr) != 5:
        raise SentenceError("unsupported", addr)
    else:
        talker, kind = addr[:2], addr[2:]
        fn = _STANDARD.get(kind)
        if fn is None:
            raise SentenceError("unsupported", addr)
        res = fn(Fields(data, kind), talker, signs=signs, baseline=baseline)
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
    except SentenceError as e:
        return Reject(e.reason, e.detail)
    except Exception as e:  # a bug: never let it out of the codec, but make it visible
        return Reject("internal_error", f"{type(e).__name__}: {e}")
