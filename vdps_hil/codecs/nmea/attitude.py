"""Heading and attitude sentences both ways (all feed ``gnss_att``): HDT and THS (heading
only), PASHR (OxTS/Applanix/NovAtel: heading, roll, pitch, heave, accuracies), PASHR,HPR
(Ashtech/Spectra), HPR ($GNHPR/$GPHPR, Unicore/ComNav) and PTNL,AVR (Trimble).

::

    psi     = wrap(pi/2 - radians(h))             h: heading [deg, clockwise from true N]
    theta   = s_p * radians(pitch_printed)        s_p = signs[layout].pitch_to_paper
    phi     = s_r * radians(roll_printed)         s_r = signs[layout].roll_to_paper
    sigma_* = radians(accuracy_printed)           (PASHR: 1-sigma accuracies)

psi, theta, phi: paper yaw, pitch, roll [rad] (``vdps_hil.conventions``); ``signs`` defaults to
``ATTITUDE_SIGN`` (one entry per layout of ``ATTITUDE_LAYOUTS``). The generators print
``pitch_printed = degrees(theta) / s_p`` (and the same for roll).

Two-antenna layouts (PASHR,HPR and HPR) print both a pitch and a roll slot but one baseline
measures only one of them; ``dual_antenna_baseline`` says which: ``"along"`` (default, pitch),
``"across"`` (roll) or ``"both"`` (three or more antennas). ``ParsedSentence.has_roll`` says
whether a roll went on the bus.
"""

from __future__ import annotations

import math
from typing import Mapping

from vdps_hil.codecs.nmea.fields import (
    RANGE_ACCURACY_DEG, RANGE_DOP, RANGE_HEADING_DEG, RANGE_HEAVE_M, RANGE_LENGTH_M, RANGE_ROLL_DEG,
    RANGE_SIGNED_HEADING_DEG, RANGE_TILT_DEG, Fields, fmt_heading, fmt_num, fmt_time, heading_yaw,
    put_field,
)
from vdps_hil.codecs.nmea.sentence import (
    ATTITUDE_LAYOUTS, ParsedSentence, SentenceError, wrap_sentence,
)
from vdps_hil.conventions import ATTITUDE_SIGN, AttitudeSign, heading_to_yaw, yaw_to_heading


def _deg(rad: float) -> float:
    return math.degrees(rad)


# --------------------------------------------------------------------------------------------
# Generators
# --------------------------------------------------------------------------------------------

def format_hdt(yaw_rad: float, *, talker: str = "GP") -> bytes:
    """HDT true heading from a paper yaw."""
    return wrap_sentence(f"{talker}HDT,{fmt_heading(yaw_to_heading(yaw_rad), 2)},T")


def format_ths(yaw_rad: float, *, mode: str = "A", talker: str = "GN") -> bytes:
    """THS true heading and status from a paper yaw."""
    return wrap_sentence(f"{talker}THS,{fmt_heading(yaw_to_heading(yaw_rad), 2)},{mode}")


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
            return fmt_num(0.0 if s is None else _deg(s), 3)
        body = ",".join([
            "PASHR", fmt_time(utc_time_s, 3), fmt_heading(heading, 2, 6), "T",
            fmt_num(roll_pr, 2, 6, sign=True), fmt_num(pitch_pr, 2, 6, sign=True),
            fmt_num(heave_m, 2, 6, sign=True), acc(roll_sigma_rad), acc(pitch_sigma_rad),
            acc(yaw_sigma_rad), str(int(quality)), str(int(ins_status)),
        ])
    elif layout == "PASHR,HPR":
        n_vec = 2 if (pitch_pr is not None and roll_pr is not None) else 1
        body = ",".join([
            "PASHR", "HPR", fmt_time(utc_time_s, 2), fmt_heading(heading, 3, 7),
            fmt_num(pitch_pr, 3), fmt_num(roll_pr, 3), "0.0021", "0.0034", "0", "0",
            f"{n_vec}.{'99' if n_vec == 2 else '90'}0", fmt_num(pdop, 1),
        ])
    elif layout == "HPR":
        body = ",".join([
            f"{talker}HPR", fmt_time(utc_time_s, 2), fmt_heading(heading, 2, 6),
            fmt_num(pitch_pr, 2, 6), fmt_num(roll_pr, 2, 6), str(int(quality)),
            f"{int(num_sats):02d}", "1.00", "0004",
        ])
    else:  # PTNL,AVR
        yaw_pr = heading if heading <= 180.0 else heading - 360.0
        body = ",".join([
            "PTNL", "AVR", fmt_time(utc_time_s, 2), fmt_num(yaw_pr, 4, sign=True), "Yaw",
            fmt_num(pitch_pr, 4, sign=True), "Tilt" if pitch_pr is not None else "",
            fmt_num(roll_pr, 4, sign=True), "Roll" if roll_pr is not None else "",
            fmt_num(baseline_m, 3), str(int(quality)), fmt_num(pdop, 1), str(int(num_sats)),
        ])
    return wrap_sentence(body)


# --------------------------------------------------------------------------------------------
# Parsers: (fields, talker) -> ParsedSentence
# --------------------------------------------------------------------------------------------

def parse_hdt(f: Fields, talker: str, **_) -> ParsedSentence:
    f.need(2)
    yaw = heading_yaw(f, 0)
    f.char(1, "true flag", "T")
    return ParsedSentence("HDT", talker, "gnss_att", {"gnss_yaw_rad": yaw}, has_roll=False)


def parse_ths(f: Fields, talker: str, **_) -> ParsedSentence:
    f.need(2)
    mode = f.char(1, "mode", "AEMSV")
    out: dict[str, float] = {}
    h = f.num(0, "heading", RANGE_HEADING_DEG, required=mode != "V")
    put_field(out, "gnss_yaw_rad", None if h is None else heading_to_yaw(h % 360.0))
    return ParsedSentence("THS", talker, "gnss_att", out, valid=mode in "AE", has_roll=False,
                          extras={"mode": mode})


def _sigma(f: Fields, i: int, what: str) -> float | None:
    v = f.num(i, what, RANGE_ACCURACY_DEG, required=False)
    return None if v is None else math.radians(v)


def parse_pashr(f: Fields, talker: str, *, signs, **_) -> ParsedSentence:
    f.need(10)
    sgn = signs["PASHR"]
    t = f.time(0)
    out: dict[str, float] = {"gnss_yaw_rad": heading_yaw(f, 1)}
    f.char(2, "true flag", "T")
    roll = f.num(3, "roll", RANGE_ROLL_DEG)
    pitch = f.num(4, "pitch", RANGE_TILT_DEG)
    out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(pitch)
    out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    put_field(out, "gnss_roll_sigma_rad", _sigma(f, 6, "roll accuracy"))
    put_field(out, "gnss_pitch_sigma_rad", _sigma(f, 7, "pitch accuracy"))
    put_field(out, "gnss_yaw_sigma_rad", _sigma(f, 8, "heading accuracy"))
    extras = {"heave_m": f.num(5, "heave", RANGE_HEAVE_M, required=False),
              "gnss_quality": f.int_(9, "GNSS quality", 99, required=False),
              "ins_status": f.int_(10, "INS status", 99, required=False)}
    return ParsedSentence("PASHR", "", "gnss_att", out, has_roll=True, utc_time_s=t,
                          extras=extras)


def _dual_slots(baseline: str) -> tuple[bool, bool]:
    """(pitch slot used, roll slot used) for a two-antenna installation."""
    return {"along": (True, False), "across": (False, True), "both": (True, True)}[baseline]


def parse_pashr_hpr(f: Fields, talker: str, *, signs, baseline, **_) -> ParsedSentence:
    f.need(8)  # HPR, time, heading, pitch, roll, carrier RMS, baseline RMS, ambiguity
    sgn = signs["PASHR,HPR"]
    t = f.time(1)
    out: dict[str, float] = {"gnss_yaw_rad": heading_yaw(f, 2)}
    use_p, use_r = _dual_slots(baseline)
    pitch = f.num(3, "pitch", RANGE_TILT_DEG, required=False)
    roll = f.num(4, "roll", RANGE_TILT_DEG, required=False)
    if use_p and pitch is not None:
        out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(pitch)
    if use_r and roll is not None:
        out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    extras = {"carrier_rms_m": f.num(5, "carrier RMS", RANGE_LENGTH_M, required=False),
              "baseline_rms_m": f.num(6, "baseline RMS", RANGE_LENGTH_M, required=False),
              "ambiguity": f.int_(7, "ambiguity", 99, required=False),
              "pitch_printed_deg": pitch, "roll_printed_deg": roll}
    return ParsedSentence("PASHR,HPR", "", "gnss_att", out, has_roll="gnss_roll_rad" in out,
                          utc_time_s=t, extras=extras)


def parse_hpr(f: Fields, talker: str, *, signs, baseline, **_) -> ParsedSentence:
    f.need(5)  # time, heading, pitch, roll, QF
    sgn = signs["HPR"]
    t = f.time(0)
    qf = f.int_(4, "QF", 9)
    out: dict[str, float] = {}
    if qf != 0:
        out["gnss_yaw_rad"] = heading_yaw(f, 1)
    use_p, use_r = _dual_slots(baseline)
    pitch = f.num(2, "pitch", RANGE_TILT_DEG, required=False)
    roll = f.num(3, "roll", RANGE_ROLL_DEG, required=False)
    if qf != 0 and use_p and pitch is not None:
        out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(pitch)
    if qf != 0 and use_r and roll is not None:
        out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    extras = {"qf": qf, "num_sats": f.int_(5, "satellites", 999, required=False),
              "pitch_printed_deg": pitch, "roll_printed_deg": roll}
    return ParsedSentence("HPR", talker, "gnss_att", out, valid=qf != 0,
                          has_roll="gnss_roll_rad" in out, utc_time_s=t, extras=extras)


def parse_ptnl_avr(f: Fields, talker: str, *, signs, **_) -> ParsedSentence:
    f.need(10)  # AVR, time, yaw, Yaw, tilt, Tilt, roll, Roll, range, quality
    sgn = signs["PTNL,AVR"]
    t = f.time(1)
    q = f.int_(9, "quality", 9)
    out: dict[str, float] = {}
    if f.raw(3) != "Yaw":
        raise SentenceError("bad_field", f"AVR: yaw label {f.raw(3)!r}")
    yaw = f.num(2, "yaw", RANGE_SIGNED_HEADING_DEG, required=q != 0)
    if yaw is not None:
        out["gnss_yaw_rad"] = heading_to_yaw(yaw % 360.0)
    tilt = f.num(4, "tilt", RANGE_TILT_DEG, required=False)
    if tilt is not None:
        if f.raw(5) != "Tilt":
            raise SentenceError("bad_field", f"AVR: tilt label {f.raw(5)!r}")
        out["gnss_pitch_rad"] = sgn.pitch_to_paper * math.radians(tilt)
    roll = f.num(6, "roll", RANGE_TILT_DEG, required=False)
    if roll is not None:
        if f.raw(7) != "Roll":
            raise SentenceError("bad_field", f"AVR: roll label {f.raw(7)!r}")
        out["gnss_roll_rad"] = sgn.roll_to_paper * math.radians(roll)
    extras = {"range_m": f.num(8, "range", RANGE_LENGTH_M, required=False), "quality": q,
              "pdop": f.num(10, "PDOP", RANGE_DOP, required=False),
              "num_sats": f.int_(11, "satellites", 999, required=False)}
    return ParsedSentence("PTNL,AVR", "", "gnss_att", out, valid=q != 0,
                          has_roll="gnss_roll_rad" in out, utc_time_s=t, extras=extras)
