"""NMEA 0183 GNSS receivers: a live serial port, and NMEA/ASCII text files with or without
time stamps.

Live: :class:`NmeaAdapter` = :class:`~vdps_hil.adapters.serial_adapter.SerialAdapter` with
:class:`NmeaProtocol` (``codecs.framing.LineFramer`` then
``codecs.nmea.decoder.NmeaDecoder``): every line gets the receive-time rule's ``t_ns``; GGA,
RMC, VTG, HDT/THS and the attitude layouts (bare ``$PASHR``, ``$PASHR,HPR``,
``$GNHPR``/``$GPHPR``, ``$PTNL,AVR``) become samples of kinds ``gnss_pos``, ``gnss_vel``,
``gnss_att`` in SI and paper angles.

Files: :class:`NmeaTextFileAdapter` reads a text file line by line. Accepted time stamps at
the start of a line (then spaces, a tab, ``,`` or ``;`` before the ``$``/``!`` sentence):

=====================================  ====================================================
form                                   meaning
=====================================  ====================================================
``(1673458929.103950) $GPGGA,...``     seconds, in parentheses (candump style)
``[12.345] $GPGGA,...``                seconds, in brackets
``1673458929.103950 $GPGGA,...``       seconds (epoch or relative), bare decimal
``1673458929103950000 $GPGGA,...``     integer nanoseconds (16 digits or more)
``2014-02-19T20:41:32.100Z $GPGGA``    ISO 8601 UTC (``T`` or a space; ``Z``/``+hh:mm``
                                       offset optional, no offset = UTC)
``$GPGGA,...`` (no stamp)              the sentence's own UTC time of day (hhmmss.ss) on the
                                       file's first RMC/ZDA date (else 1970-01-01); sentences
                                       without a time (HDT, VTG) take the last time seen
=====================================  ====================================================

``t_ns`` is the stamp in nanoseconds (seconds since the epoch for dates). Lines starting with
``#`` are comments (counted ``comments``, skipped); blank lines are skipped; anything else is
fed to the decoder and counted there (garbage, bad checksums, non-UTF-8 bytes). A UTC time of
day that goes back by more than 12 h is taken as midnight passing (one day added).
"""

from __future__ import annotations

import datetime as _dt
import os
import re
from typing import Any, Sequence

from vdps_hil.adapters.base import Adapter, AdapterError, EndOfInput
from vdps_hil.adapters.serial_adapter import DEFAULT_BAUD, SerialAdapter
from vdps_hil.bus.clocks import ReplayClock
from vdps_hil.bus.raw import RawSerial
from vdps_hil.codecs.framing import LineFramer
from vdps_hil.codecs.nmea.decoder import NmeaDecoder

__all__ = ["NmeaProtocol", "NmeaAdapter", "NmeaTextFileAdapter", "parse_time_prefix"]

NS = 1_000_000_000
DAY_NS = 86_400 * NS


class NmeaProtocol:
    """Framer + decoder of one NMEA device (a serial protocol, see ``serial_adapter``)."""

    fmt = "nmea"

    def __init__(self, source: str = "gnss", baud: int = DEFAULT_BAUD, **decoder_kw):
        self.source = source
        self.baud = int(baud)
        self.decoder = NmeaDecoder(source, **decoder_kw)
        self.framer = LineFramer(self.baud, start_bytes=b"$!")

    def feed(self, t_ns: int, chunk: bytes) -> list:
        out = []
        dec = self.decoder
        for t_line, line in self.framer.feed(t_ns, chunk):
            out += dec.feed_line(t_line, line)
        return out

    def reset(self) -> None:
        """Drop a partial line (after a device outage)."""
        self.framer.flush()

    @property
    def counters(self) -> dict[str, int]:
        c = {f"framer_{k}": v for k, v in self.framer.counters.items()}
        c["line_overflows"] = c.pop("framer_overflows", 0)
        c.update(self.decoder.counters)
        return c


class NmeaAdapter(SerialAdapter):
    """A live NMEA receiver on a serial port (``port``, ``baud``); samples' source = ``name``."""

    def __init__(self, name: str, port: str, baud: int = DEFAULT_BAUD, *, decoder_kw=None, **kw):
        super().__init__(name, port, baud, NmeaProtocol(name, baud, **(decoder_kw or {})), **kw)


# --- text files -----------------------------------------------------------------------------

_PAREN = re.compile(rb"^\s*[\(\[]\s*(-?\d+(?:\.\d*)?)\s*[\)\]][\s,;]*")
_BARE = re.compile(rb"^\s*(-?\d+(?:\.\d*)?)(?:\s+|\s*[,;]\s*)(?=[$!])")
_ISO = re.compile(rb"^\s*(\d{4})-(\d{2})-(\d{2})[T ](\d{2}):(\d{2}):(\d{2})(\.\d+)?"
                  rb"(Z|[+-]\d{2}:?\d{2})?[\s,;]*")
_UTC_FIELD = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d+)?)$")


def _seconds_to_ns(text: bytes) -> int:
    s = text.decode("ascii")
    if "." not in s and len(s.lstrip("-")) >= 16:
        return int(s)
    whole, _, frac = s.partition(".")
    neg = whole.startswith("-")
    w = int(whole) if whole not in ("", "-") else 0
    f = int((frac + "000000000")[:9]) if frac else 0
    return w * NS - f if neg else w * NS + f


def parse_time_prefix(line: bytes) -> tuple[int | None, bytes]:
    """``(t_ns or None, rest of the line)`` for the accepted time-stamp forms (module
    docstring); never raises."""
    m = _PAREN.match(line)
    if m:
        return _seconds_to_ns(m.group(1)), line[m.end():]
    m = _ISO.match(line)
    if m:
        try:
            y, mo, d, h, mi, s = (int(g) for g in m.groups()[:6])
            frac = m.group(7)
            tz = m.group(8)
            dt = _dt.datetime(y, mo, d, h, mi, s, tzinfo=_dt.timezone.utc)
            off = 0
            if tz and tz not in (b"Z",):
                t = tz.decode().replace(":", "")
                off = (int(t[1:3]) * 3600 + int(t[3:5]) * 60) * (1 if t[0] == "+" else -1)
            t_ns = (int(dt.timestamp()) - off) * NS
            if frac:
                t_ns += int((frac[1:].decode() + "000000000")[:9])
            return t_ns, line[m.end():]
        except (ValueError, OverflowError):
            return None, line
    m = _BARE.match(line)
    if m:
        return _seconds_to_ns(m.group(1)), line[m.end():]
    return None, line


def _sentence_utc_s(line: bytes) -> float | None:
    """UTC seconds of day printed in a sentence (the first hhmmss[.ss] among its first
    fields), or None."""
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        return None
    body = text.split("*", 1)[0]
    for f in body.split(",")[1:4]:
        m = _UTC_FIELD.match(f)
        if m:
            h, mi, s = int(m.group(1)), int(m.group(2)), float(m.group(3))
            if h < 24 and mi < 60 and s < 61:
                return h * 3600 + mi * 60 + s
    return None


def _sentence_date(line: bytes) -> _dt.date | None:
    """The date of an RMC (ddmmyy) or ZDA (dd, mm, yyyy) sentence, else None."""
    try:
        f = line.decode("ascii").split("*", 1)[0].split(",")
    except UnicodeDecodeError:
        return None
    head = f[0][-3:] if f and f[0].startswith("$") else ""
    try:
        if head == "RMC" and len(f) > 9 and re.fullmatch(r"\d{6}", f[9]):
            d, mo, y = int(f[9][:2]), int(f[9][2:4]), int(f[9][4:])
            return _dt.date(2000 + y if y < 80 else 1900 + y, mo, d)
        if head == "ZDA" and len(f) > 4 and f[2] and f[3] and f[4]:
            return _dt.date(int(f[4]), int(f[3]), int(f[2]))
    except ValueError:
        return None
    return None


class NmeaTextFileAdapter(Adapter):
    """An NMEA text file replayed line by line (time stamps: module docstring).

    Raw records are the sentences as read plus CR LF, on ``/raw/serial/<name>`` with the
    given ``baud``; samples come from an :class:`~vdps_hil.codecs.nmea.decoder.NmeaDecoder`.
    """

    transport = "serial"

    def __init__(self, name: str, path: str | os.PathLike, baud: int = DEFAULT_BAUD, *,
                 decoder_kw=None, batch: int = 1024, **kw):
        kw.setdefault("clock", ReplayClock())
        super().__init__(name, os.fspath(path), **kw)
        self.path = os.fspath(path)
        self.baud = int(baud)
        self.decoder = NmeaDecoder(name, **(decoder_kw or {}))
        self.batch = int(batch)
        self._lines: list[bytes] = []
        self._i = 0
        self._day_ns = 0
        self._last_tod_ns: int | None = None
        self._last_t: int | None = None
        self._comments = 0
        self._stamped = {"time_prefix": 0, "sentence_utc": 0, "carried": 0}

    def _open(self) -> None:
        try:
            with open(self.path, "rb") as f:
                data = f.read()
        except OSError as e:
            raise AdapterError(f"NMEA file {self.path}: {e.strerror or e}") from None
        self._lines = data.split(b"\n")
        self._i = 0
        for ln in self._lines:  # the first date in the file anchors time-of-day stamps
            if b"RMC" in ln[:8] or b"ZDA" in ln[:8]:
                _, body = parse_time_prefix(ln.strip())
                d = _sentence_date(body)
                if d is not None:
                    self._day_ns = int(_dt.datetime(d.year, d.month, d.day,
                                                    tzinfo=_dt.timezone.utc).timestamp()) * NS
                    break

    def _close(self) -> None:
        self._lines = []

    def decoder_counters(self):
        c = dict(self.decoder.counters)
        c["comments"] = self._comments
        for k, v in self._stamped.items():
            c[f"stamp_{k}"] = v
        return c

    def _time_of(self, body: bytes) -> int | None:
        tod = _sentence_utc_s(body)
        if tod is None:
            return None
        tod_ns = int(round(tod * 1e6)) * 1000
        if self._last_tod_ns is not None and tod_ns < self._last_tod_ns - DAY_NS // 2:
            self._day_ns += DAY_NS
        self._last_tod_ns = tod_ns
        return self._day_ns + tod_ns

    def _read(self, timeout_s: float) -> Sequence[tuple[int | None, Any]]:
        out = []
        lines = self._lines
        while self._i < len(lines) and len(out) < self.batch:
            ln = lines[self._i].rstrip(b"\r").strip()
            self._i += 1
            if not ln:
                continue
            if ln.startswith(b"#"):
                self._comments += 1
                continue
            t, body = parse_time_prefix(ln)
            if t is not None:
                self._stamped["time_prefix"] += 1
            else:
                t = self._time_of(body)
                if t is not None:
                    self._stamped["sentence_utc"] += 1
                else:
                    self._stamped["carried"] += 1
                    t = self._last_t if self._last_t is not None else self._first_time()
            if t < 0:
                t = 0
            self._last_t = t
            out.append((t, body))
        if not out and self._i >= len(lines):
            raise EndOfInput()
        return out

    def _first_time(self) -> int:
        """Time for untimed lines before the first timed one: the first time in the file."""
        save = (self._day_ns, self._last_tod_ns)
        try:
            for ln in self._lines[self._i:]:
                t, body = parse_time_prefix(ln.strip())
                if t is None:
                    t = self._time_of(body)
                if t is not None:
                    return t
            return 0
        finally:
            self._day_ns, self._last_tod_ns = save

    def _raw(self, t_ns, wall_time_ns, body):
        return RawSerial(t_ns, wall_time_ns, self.name, bytes(body) + b"\r\n", self.baud, "nmea")

    def _decode(self, t_ns, body):
        return self.decoder.feed_line(t_ns, body)
