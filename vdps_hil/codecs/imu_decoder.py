"""The MTi byte stream -> ``imu`` bus samples: Xbus framing (hunting for ``FA FF``, the announced
length, the checksum, messages overlapping false headers), the receive time of each message,
and the bus fields and counters of each ``MTData2`` message (``codecs.imu_mtdata2`` decodes its
DATA).

Receive time
------------
A packet's ``t_ns`` follows the framing rule (``codecs.framing``): chunk time minus the wire time
of the bytes after the packet's last byte in that chunk. The device time (SampleTimeFine) is
kept on ``ImuPacket`` for clock studies; the bus sample carries the packet counter.
"""

from __future__ import annotations

from collections import deque
from types import MappingProxyType
from typing import Mapping, Sequence

from vdps_hil.bus.samples import Sample, axis_fields, check_fields
from vdps_hil.codecs.framing import BITS_PER_BYTE_8N1, message_time_ns
from vdps_hil.codecs.imu_mtdata2 import (
    BID_MASTER, DEFAULT_BAUD, MAX_EXTENDED_LEN, MID_MTDATA2, MTDATA2_START, PREAMBLE,
    SENSOR_TO_BODY, ImuPacket, MtData2Error, check_rotation, decode_mtdata2_rotated,
)

F_FIELDS = axis_fields("specific_force_mps2")
W_FIELDS = axis_fields("angular_rate_radps")
check_fields((*F_FIELDS, *W_FIELDS, "seq_counter"))
_FX, _FY, _FZ = F_FIELDS
_WX, _WY, _WZ = W_FIELDS

IMU_REJECT_REASONS: tuple[str, ...] = ("bad_checksum", "bad_length", "malformed_payload",
                                       "unsupported_format", "no_imu_data", "overlapped")


class ImuDecoder:
    """Streaming decoder of an MTi byte stream into ``imu`` bus samples.

    ``feed(t_ns, chunk)`` returns the samples of every MTData2 message completed by this chunk,
    each stamped by the receive-time rule at ``baud``. The decoder hunts for ``FA FF``, waits
    for the announced length, checks the checksum, and on any failure advances one byte and
    hunts again, so a valid message next to (or inside the claimed span of) garbage is never
    lost. A message is accepted only if its checksum is right, its payload parses, and no
    valid MTData2 message starts inside its span (the 8-bit checksum passes 1 corrupt span in
    256; a packet cut just before its checksum byte, followed by the next packet, is the
    common case). ``flush()`` at the end of a stream releases what is still held.

    Counters (read-only ``counters``): ``bytes``, ``messages`` (valid MTData2 messages),
    ``samples``, ``other_messages`` (checksum-valid Xbus messages of another kind, not
    consumed), ``garbage_bytes`` (skipped while hunting), ``rejected`` and ``reject_<reason>``
    for ``IMU_REJECT_REASONS``, ``seq_gaps`` (packets missing according to the counter) and
    ``time_backwards`` (chunk times going back).
    """

    def __init__(self, source: str = "imu", *, baud: int = DEFAULT_BAUD,
                 sensor_to_body: Sequence[Sequence[float]] = SENSOR_TO_BODY,
                 bits_per_byte: int = BITS_PER_BYTE_8N1):
        if baud <= 0:
            raise ValueError(f"baud must be positive, got {baud}")
        self.source = source
        self.baud = int(baud)
        self.bits_per_byte = int(bits_per_byte)
        self.sensor_to_body = check_rotation(sensor_to_body)
        self._buf = bytearray()
        self._base = 0  # stream offset of self._buf[0]
        self._chunk_ends: deque[tuple[int, int]] = deque()  # (stream offset after chunk, t_ns)
        self._last_counter: int | None = None
        self._last_t_ns: int | None = None
        self._counters = {"bytes": 0, "messages": 0, "samples": 0, "other_messages": 0,
                          "garbage_bytes": 0, "rejected": 0, "seq_gaps": 0,
                          "time_backwards": 0}
        for r in IMU_REJECT_REASONS:
            self._counters[f"reject_{r}"] = 0
        self.last_packet: ImuPacket | None = None

    @property
    def counters(self) -> Mapping[str, int]:
        return MappingProxyType(self._counters)

    def _reject(self, reason: str) -> None:
        self._counters["rejected"] += 1
        self._counters[f"reject_{reason}"] += 1

    def feed(self, t_ns: int, chunk: bytes) -> list[Sample]:
        return self.samples(self.feed_messages(t_ns, chunk))

    def flush(self) -> list[Sample]:
        """End of stream: decode what is left, treating headers whose bytes never arrived as
        garbage (so messages held behind a false header are released)."""
        return self.samples(self.flush_messages())

    def feed_messages(self, t_ns: int, chunk: bytes) -> list[tuple[int, dict[str, float], ImuPacket]]:
        """``feed`` before the samples are made: per accepted message ``(receive time [ns], bus
        fields, packet)``, for a caller that stamps the samples by another clock
        (``record.decode``: the device time); :meth:`samples` makes the samples."""
        c = self._counters
        c["bytes"] += len(chunk)
        if self._last_t_ns is not None and t_ns < self._last_t_ns:
            c["time_backwards"] += 1
        self._last_t_ns = t_ns
        self._buf += chunk
        self._chunk_ends.append((self._base + len(self._buf), int(t_ns)))
        return self._run(final=False)

    def flush_messages(self) -> list[tuple[int, dict[str, float], ImuPacket]]:
        """``flush`` as ``feed_messages`` gives its messages."""
        if not self._chunk_ends:
            return []
        return self._run(final=True)

    def samples(self, messages, times=None) -> list[Sample]:
        """The bus samples of ``feed_messages`` output, stamped by the receive-time rule or by
        ``times`` (one per message; None keeps the receive time)."""
        src = self.source
        if times is None:
            return [Sample(t, src, "imu", f) for t, f, _ in messages]  # (t_ns, source, kind, fields)
        return [Sample(t if tt is None else tt, src, "imu", f) for (t, f, _), tt in zip(messages, times)]

    def _run(self, final: bool) -> list[tuple[int, dict[str, float], ImuPacket]]:
        c = self._counters
        buf = self._buf
        r = self.sensor_to_body
        out: list[tuple[int, dict[str, float], ImuPacket]] = []
        i = 0
        n = len(buf)
        while True:
            k = buf.find(PREAMBLE, i)
            if k < 0:
                c["garbage_bytes"] += n - i
                i = n
                break
            c["garbage_bytes"] += k - i
            i = k
            status, mid, head, end = self._probe(buf, i, n)
            if status == "need_more":
                if head:
                    # The header claims bytes not yet here. A valid MTData2 message already
                    # complete inside the claimed span shows the header is false: skip it now
                    # rather than hold good messages back.
                    inner = self._inner_message(buf, i, n, n)
                    if inner > 0:
                        self._reject("overlapped")
                        i = inner
                        continue
                if final:
                    c["garbage_bytes"] += 1
                    i += 1
                    continue
                break
            if status == "not_header":
                c["garbage_bytes"] += 1
                i += 1
                continue
            if status != "ok":
                self._reject(status)
                i += 1
                continue
            if mid != MID_MTDATA2:
                # A checksum-valid message of another kind (an ack, an error) is not consumed:
                # its span is rescanned, so a false header that happens to pass the 8-bit
                # checksum cannot swallow the MTData2 messages inside its claimed length.
                c["other_messages"] += 1
                i += 1
                continue
            try:
                pkt = decode_mtdata2_rotated(buf[i + head:end - 1], r)  # a copy: the buffer moves on
            except MtData2Error as e:
                self._reject(e.reason)
                i += 1  # same reasoning: never consume a span that does not parse
                continue
            inner = self._inner_message(buf, i, end, n)
            if inner == -1 and not final:
                break  # a header inside this span is not complete yet: decide later
            if inner > 0:
                # A valid MTData2 message starts inside this one's span: this one is a corrupt
                # span that passed the 8-bit checksum by chance (e.g. a packet cut before its
                # checksum byte, followed by the next packet). The inner message wins.
                self._reject("overlapped")
                i = inner
                continue
            c["messages"] += 1
            t_msg = self._time_of_byte(self._base + end - 1)
            i = end
            fields = self._fields(pkt)
            if fields is not None:
                out.append((t_msg, fields, pkt))
        del buf[:i]
        self._base += i
        while len(self._chunk_ends) > 1 and self._chunk_ends[0][0] <= self._base:
            self._chunk_ends.popleft()
        return out

    @staticmethod
    def _probe(buf: bytearray, i: int, n: int) -> tuple[str, int, int, int]:
        """Classify the bytes at ``buf[i]`` (a preamble): ("need_more"|"not_header"|
        "bad_length"|"bad_checksum"|"ok", MID, header length, end index (exclusive))."""
        if n - i < 4:
            return "need_more", 0, 0, 0
        if buf[i + 1] != BID_MASTER:
            return "not_header", 0, 0, 0
        mid, ln, head = buf[i + 2], buf[i + 3], 4
        if ln == 0xFF:
            if n - i < 6:
                return "need_more", mid, 0, 0
            ln, head = (buf[i + 4] << 8) | buf[i + 5], 6
            if ln > MAX_EXTENDED_LEN or ln < 0xFF:
                return "bad_length", mid, head, 0
        end = i + head + ln + 1
        if end > n:
            return "need_more", mid, head, end
        if sum(buf[i + 1:end]) & 0xFF:
            return "bad_checksum", mid, head, end
        return "ok", mid, head, end

    def _inner_message(self, buf: bytearray, i: int, end: int, n: int) -> int:
        """Index of a valid MTData2 message starting inside ``buf[i+1:end]`` (0 if none, -1 if
        one may start there but its bytes have not all arrived)."""
        sig = MTDATA2_START
        j = buf.find(sig, i + 1, end + 2)
        while 0 <= j < end:
            status, _, head, end_j = self._probe(buf, j, n)
            if status == "need_more":
                return -1
            if status == "ok":
                try:
                    decode_mtdata2_rotated(buf[j + head:end_j - 1], self.sensor_to_body)
                    return j
                except MtData2Error:
                    pass
            j = buf.find(sig, j + 1, end + 2)
        return 0

    def _time_of_byte(self, pos: int) -> int:
        """Receive-time rule for the byte at stream offset ``pos``: the time of the chunk holding
        it minus the wire time of the bytes after it in that chunk (a message that had to wait
        for later bytes, behind a false header, still gets its own chunk's time)."""
        for end, t_chunk in self._chunk_ends:
            if pos < end:
                return message_time_ns(t_chunk, end - 1 - pos, self.baud, self.bits_per_byte)
        end, t_chunk = self._chunk_ends[-1]
        return message_time_ns(t_chunk, 0, self.baud, self.bits_per_byte)

    def _fields(self, pkt: ImuPacket) -> dict[str, float] | None:
        """The bus fields of a packet (None: rejected, no IMU data); counts gaps and samples."""
        c = self._counters
        if pkt.specific_force_mps2 is None or pkt.angular_rate_radps is None:
            self._reject("no_imu_data")
            return None
        self.last_packet = pkt
        fx, fy, fz = pkt.specific_force_mps2
        wx, wy, wz = pkt.angular_rate_radps
        fields = {_FX: fx, _FY: fy, _FZ: fz, _WX: wx, _WY: wy, _WZ: wz}  # F_FIELDS, W_FIELDS
        if pkt.packet_counter is not None:
            fields["seq_counter"] = float(pkt.packet_counter)
            if self._last_counter is not None:
                gap = (pkt.packet_counter - self._last_counter - 1) & 0xFFFF
                if gap and gap < 0x8000:
                    c["seq_gaps"] += gap
            self._last_counter = pkt.packet_counter
        c["samples"] += 1
        return fields
