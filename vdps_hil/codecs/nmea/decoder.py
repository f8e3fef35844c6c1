"""``NmeaDecoder``: the NMEA lines of one device -> bus samples (``gnss_pos``, ``gnss_vel``,
``gnss_att``), with counters; each line goes through ``parse.parse_sentence``."""

from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.nmea.parse import parse_sentence
from vdps_hil.codecs.nmea.sentence import (
    DUAL_ANTENNA_BASELINES, REJECT_REASONS, ParsedSentence, Reject,
)
from vdps_hil.conventions import ATTITUDE_SIGN, AttitudeSign


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
