"""Per-source health of the adapters (like opendbc's ``MessageState``): learned rates and
timeouts per sample kind (:class:`KindStats`), counters and device state per source
(:class:`SourceHealth`), kept by ``adapters.base.Adapter`` for every adapter. Per source and
per sample kind ``k``::

    period_k  = (t_last - t_first) / (n - 1)               for the first 100 samples
    period_k <- 0.99 period_k + 0.01 (t_n - t_{n-1})        afterwards (learned, EMA)
    (intervals longer than the timeout are gaps: counted, kept out of the period)
    rate_hz_k = 1e9 / period_k
    timed out when  now - t_last > timeout_periods * period_k   (default 10 periods)

plus counters: records, bytes, samples, invalid samples, ``time_backwards`` (a record or a
sample whose time is below the previous one of the same stream: kept, counted, the sample
marked ``valid=False``), ``queue_overflow`` (a listener's queue was full: the event is dropped
for that listener only and counted), ``reconnects``/``outages``/``outage_s`` (device lost and back), ``read_errors``,
``decoder_exceptions`` (a decoder raised: a bug, counted, never a crash), and the decoder's own
counters (unknown IDs, DLC mismatches, bad checksums, garbage, non-UTF-8 ...) merged in.
``loss`` sorts what was lost by where it happened (:data:`LOSS_STAGES`).
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Mapping

from vdps_hil.units import NS_PER_S

__all__ = ["DROP_COUNTERS", "ERROR_COUNTERS", "LOSS_STAGES", "KindStats", "SourceHealth"]


@dataclasses.dataclass
class KindStats:
    """Learned rate and timeouts of one sample kind of one source."""

    count: int = 0
    first_t_ns: int = -1
    last_t_ns: int = -1
    period_ns: float = 0.0
    timeouts: int = 0
    timed_out: bool = False
    max_gap_ns: int = 0
    _gap_ns: int = 0
    _gaps: int = 0

    LEARN_N = 100
    EMA = 0.01

    @property
    def rate_hz(self) -> float:
        return NS_PER_S / self.period_ns if self.period_ns > 0 else 0.0

    def timeout_ns(self, periods: float, min_timeout_ns: int) -> float:
        return max(periods * self.period_ns, float(min_timeout_ns)) if self.period_ns > 0 \
            else float("inf")

    def add(self, t_ns: int, periods: float, min_timeout_ns: int) -> tuple[bool, bool]:
        """Account one sample at ``t_ns``; returns (went_backwards, resumed_after_timeout)."""
        backwards = resumed = False
        if self.count == 0:
            self.first_t_ns = t_ns
        else:
            dt = t_ns - self.last_t_ns
            if dt < 0:
                backwards = True
            else:
                if dt > self.max_gap_ns:
                    self.max_gap_ns = dt
                gap = self.count >= 2 and dt > self.timeout_ns(periods, min_timeout_ns)
                if gap:
                    if not self.timed_out:
                        self.timeouts += 1  # a gap seen only now (replay, or between polls)
                    resumed = True
                    self._gap_ns += dt  # a gap is not a period: keep it out of the rate
                elif self.timed_out:
                    resumed = True
                if not gap:
                    if self.count < self.LEARN_N:
                        self.period_ns = (t_ns - self.first_t_ns - self._gap_ns) / \
                            (self.count - self._gaps)
                    else:
                        self.period_ns += self.EMA * (dt - self.period_ns)
                else:
                    self._gaps += 1
        self.timed_out = False
        self.count += 1
        if not backwards:
            self.last_t_ns = t_ns
        return backwards, resumed

    def check(self, now_ns: int, periods: float, min_timeout_ns: int) -> bool:
        """Mark (and count once) a timeout when nothing came for too long; True if newly."""
        if self.timed_out or self.count < 2:
            return False
        if now_ns - self.last_t_ns > self.timeout_ns(periods, min_timeout_ns):
            self.timed_out = True
            self.timeouts += 1
            return True
        return False

    def snapshot(self) -> dict:
        return {"count": self.count, "rate_hz": round(self.rate_hz, 3),
                "timeouts": self.timeouts, "timed_out": self.timed_out,
                "max_gap_s": self.max_gap_ns / NS_PER_S}


class SourceHealth:
    """Per-source health: counters, per-kind rates and the device state."""

    def __init__(self, source: str, transport: str, device: str):
        self.source, self.transport, self.device = source, transport, device
        self.state = "closed"
        self.counters: dict[str, int] = {}
        self.kinds: dict[str, KindStats] = {}
        self.records = 0
        self.bytes = 0
        self.samples = 0
        self.outage_ns = 0
        self.lost_since_ns: int | None = None
        self.last_record_t_ns = -1
        self.last_error = ""
        self.reader = "inline"  # what drains the device: inline (poll), thread or process
        self.os_counters = "not read"  # the OS's own loss counters: "yes", or why not
        self.decoder_counters: Callable[[], Mapping[str, int]] | None = None

    def count(self, name: str, n: int = 1) -> None:
        self.counters[name] = self.counters.get(name, 0) + n

    @property
    def drops(self) -> int:
        """Raw data lost (:data:`DROP_COUNTERS`): the OS's overruns, our reader's and queues'
        overflows, what the devices' sequence counters say is missing, refused raw writes."""
        c = self.all_counters()
        return sum(c.get(k, 0) for k in DROP_COUNTERS)

    def all_counters(self) -> dict[str, int]:
        """Own counters merged with the decoder's. A decoder's nested counters (per message,
        ``{"bus": {...}, "VDPS_WheelSpeedFront": {"accepted": ..}}``) are summed per name;
        ours win on a clash."""
        merged: dict[str, int] = {}
        if self.decoder_counters is not None:
            try:
                _flatten_into(merged, self.decoder_counters())
            except Exception:  # noqa: BLE001 - health must never raise
                merged["decoder_counters_unavailable"] = 1
        merged.update(self.counters)
        return merged

    def loss(self, counters: Mapping[str, int] | None = None) -> dict:
        """Where data was lost (:data:`LOSS_STAGES`): per stage the sum of its counters, the
        non-zero counters themselves under ``detail``, and whether the OS's counters were
        read (``os_counters``)."""
        c = self.all_counters() if counters is None else counters
        out: dict = {stage: sum(c.get(k, 0) for k in names)
                     for stage, names in LOSS_STAGES.items()}
        out["detail"] = {k: c[k] for names in LOSS_STAGES.values() for k in names if c.get(k)}
        out["os_counters"] = self.os_counters
        out["read_by"] = self.reader
        return out

    def snapshot(self, now_ns: int | None = None) -> dict:
        outage = self.outage_ns
        if self.lost_since_ns is not None and now_ns is not None:
            outage += max(0, now_ns - self.lost_since_ns)
        c = self.all_counters()
        return {"source": self.source, "transport": self.transport, "device": self.device,
                "state": self.state, "records": self.records, "bytes": self.bytes,
                "samples": self.samples, "drops": sum(c.get(k, 0) for k in DROP_COUNTERS),
                "outage_s": outage / NS_PER_S, "last_error": self.last_error, "counters": c,
                "loss": self.loss(c),
                "kinds": {k: v.snapshot() for k, v in sorted(self.kinds.items())}}

    def error_total(self) -> int:
        """Everything that is a reject or a fault (for a one-line status)."""
        c = self.all_counters()
        return sum(c.get(k, 0) for k in ERROR_COUNTERS)


def _flatten_into(out: dict[str, int], counters: Mapping) -> None:
    for k, v in counters.items():
        if isinstance(v, Mapping):
            for kk, vv in v.items():
                if isinstance(vv, (int, float)) and not isinstance(vv, bool):
                    out[str(kk)] = out.get(str(kk), 0) + int(vv)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out[str(k)] = int(v)


ERROR_COUNTERS = frozenset({
    # serial decoders (NMEA, IMU): every reject, whatever the reason, is in "rejected"
    "rejected",
    # CAN decoders (VdpsCanDecoder, SignalMapDecoder): per-frame rejects
    "dlc_mismatch", "undecodable", "out_of_range", "crc_mismatch", "checksum_mismatch",
    "counter_repeat", "counter_jump", "malformed", "bad_frames", "remote_frame", "fd_frame",
    "fd_mismatch",
    # file adapters: lines of a text log that could not be read
    "bad_lines", "non_utf8_lines",
    # this base class
    "time_backwards", "decoder_exceptions", "read_errors",
    # the serial driver (TIOCGICOUNT): bytes with framing or parity errors
    "os_frame_errors", "os_parity_errors"})
"""Counter names that mean a rejected or faulty input (summed as ``errors`` in the status).
Unknown CAN IDs, unsupported sentences and frames of other channels are not errors."""

LOSS_STAGES: dict[str, tuple[str, ...]] = {
    "os": ("os_overrun", "os_buf_overrun"),
    "reader": ("reader_overflow", "queue_overflow"),
    "sequence": ("seq_gaps", "lost_frames"),
    "decoded_skipped": ("decoded_skipped", "decoded_skipped_disk", "decoded_write_errors"),
    "raw_write_errors": ("raw_write_errors",),
}
"""Where data is lost, per source. ``os``: what the serial driver says it dropped (overruns of
the UART and of its buffer, ``TIOCGICOUNT``; not known for pseudo-terminals and most USB-CAN
adapters). ``reader``: what our reader's bounded buffer (or a listener's queue) had no room
for. ``sequence``: what the devices' own counters say is missing (IMU packet counter, CAN
rolling counters): lost anywhere before the decoder, on the wire, in the device, the OS or our
reader. ``decoded_skipped``: raw records kept but not decoded (the decoder was behind) and
samples not written (disk reserve reached, or refused). ``raw_write_errors``: raw records the
recording refused."""

DROP_COUNTERS = ("queue_overflow", "seq_gaps", "lost_frames", "reader_overflow", "os_overrun",
                 "os_buf_overrun", "raw_write_errors")
"""Counter names that mean raw data lost on the way (summed as ``drops``; decoded samples
skipped while their raw records were kept are not drops)."""
