"""Framing of raw serial chunks into lines, and the receive-time rule for framed messages.

A serial recording holds one message per read chunk: the bytes ``c`` that one ``read()``
returned and the host time ``t_c`` [ns] at which the read returned (``/raw/serial/<device>``).
The last byte of the chunk arrived at about ``t_c``; every byte before it arrived earlier by the
time the UART needed to shift out the bytes that follow it. For a message (a line, or a binary
packet) whose last byte sits at index ``e`` of the chunk (0-based)::

    t_msg = t_c - T_byte * (len(c) - 1 - e)                       (receive-time rule)
    T_byte = bits_per_byte / baud = 10 / baud  [s]                (8N1: start + 8 data + stop)

Symbols: ``t_c`` chunk receive time [ns]; ``len(c) - 1 - e`` the number of bytes after the
message's end in that chunk; ``baud`` [bit/s]; ``T_byte`` time on the wire of one byte [s].
The rule is exact for a continuously transmitting device (back-to-back frames) and otherwise an
upper bound on the age, which is what the estimator needs to order samples. A message split
across chunks takes the time of the chunk holding its last byte. Times are rounded to the
nearest integer nanosecond (``transmission_time_ns``).

``LineFramer`` splits chunks at ``\\n`` (CR LF or LF line ends; the CR is stripped), carries a
partial line over to the next chunk, and guards against garbage without line ends: a pending
line longer than ``max_line_bytes`` is dropped and counted (keeping its tail from the last start
byte such as ``$``, so a sentence that follows garbage without a newline is not lost).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

BITS_PER_BYTE_8N1 = 10
"""Bits on the wire per byte with 8 data bits, no parity, 1 stop bit (plus the start bit)."""

NS_PER_S = 1_000_000_000


def transmission_time_ns(n_bytes: int, baud: int, bits_per_byte: int = BITS_PER_BYTE_8N1) -> int:
    """Time on the wire of ``n_bytes`` bytes at ``baud`` bit/s, in integer nanoseconds (rounded to
    the nearest nanosecond, halves up): ``n_bytes * bits_per_byte * 1e9 / baud``."""
    if baud <= 0:
        raise ValueError(f"baud must be positive, got {baud}")
    if n_bytes < 0:
        raise ValueError(f"n_bytes must be >= 0, got {n_bytes}")
    num = n_bytes * bits_per_byte * NS_PER_S
    return (2 * num + baud) // (2 * baud)


def message_time_ns(t_chunk_ns: int, bytes_after: int, baud: int,
                    bits_per_byte: int = BITS_PER_BYTE_8N1) -> int:
    """Receive-time rule: the time of a message whose last byte is followed by ``bytes_after``
    bytes in the chunk received at ``t_chunk_ns``."""
    return t_chunk_ns - transmission_time_ns(bytes_after, baud, bits_per_byte)


class LineFramer:
    """Split raw serial chunks into lines, each stamped by the receive-time rule.

    ``feed(t_ns, chunk)`` returns ``[(t_line_ns, line_bytes), ...]`` for every line whose line end
    arrived in this chunk, in order; ``line_bytes`` excludes the CR LF. Empty lines are skipped
    (counted). Bytes after the last line end wait for the next chunk.

    ``max_line_bytes``: a pending line longer than this (garbage with no line end) is dropped and
    counted instead of accumulating forever; if ``start_bytes`` is given (``b"$!"`` for NMEA) the
    tail from the last start byte is kept when it is itself short enough.
    """

    def __init__(self, baud: int, *, max_line_bytes: int = 1024, start_bytes: bytes = b"$!",
                 bits_per_byte: int = BITS_PER_BYTE_8N1):
        if baud <= 0:
            raise ValueError(f"baud must be positive, got {baud}")
        if max_line_bytes < 1:
            raise ValueError("max_line_bytes must be >= 1")
        self.baud = int(baud)
        self.bits_per_byte = int(bits_per_byte)
        self.max_line_bytes = int(max_line_bytes)
        self.start_bytes = bytes(start_bytes)
        self._pending = bytearray()
        self._counters = {"chunks": 0, "bytes": 0, "lines": 0, "empty_lines": 0,
                          "overflows": 0, "overflow_dropped_bytes": 0}

    @property
    def counters(self) -> Mapping[str, int]:
        """Read-only live view: chunks, bytes, lines, empty_lines, overflows (pending lines dropped
        for exceeding ``max_line_bytes``) and overflow_dropped_bytes."""
        return MappingProxyType(self._counters)

    @property
    def pending_bytes(self) -> int:
        """Bytes of an unfinished line waiting for its line end."""
        return len(self._pending)

    def feed(self, t_ns: int, chunk: bytes) -> list[tuple[int, bytes]]:
        c = self._counters
        c["chunks"] += 1
        c["bytes"] += len(chunk)
        out: list[tuple[int, bytes]] = []
        n = len(chunk)
        start = 0
        while True:
            nl = chunk.find(b"\n", start)
            if nl < 0:
                break
            piece = chunk[start:nl]
            if self._pending:
                self._pending += piece
                line = bytes(self._pending)
                self._pending.clear()
            else:
                line = bytes(piece)
            if line.endswith(b"\r"):
                line = line[:-1]
            start = nl + 1
            if len(line) > self.max_line_bytes:
                line = self._trim_overlong(line)
                if not line:
                    continue
            if not line:
                c["empty_lines"] += 1
                continue
            t_line = message_time_ns(t_ns, n - 1 - nl, self.baud, self.bits_per_byte)
            c["lines"] += 1
            out.append((t_line, line))
        if start < n:
            self._pending += chunk[start:]
            if len(self._pending) > self.max_line_bytes:
                kept = self._trim_overlong(bytes(self._pending))
                self._pending = bytearray(kept)
        return out

    def _trim_overlong(self, data: bytes) -> bytes:
        """Drop an overlong pending line, keeping the tail from its last start byte if that tail
        fits; count what is dropped."""
        keep_from = -1
        for sb in self.start_bytes:
            keep_from = max(keep_from, data.rfind(bytes([sb])))
        if keep_from >= 0 and len(data) - keep_from <= self.max_line_bytes:
            kept = data[keep_from:]
        else:
            kept = b""
        self._counters["overflows"] += 1
        self._counters["overflow_dropped_bytes"] += len(data) - len(kept)
        return kept

    def flush(self) -> bytes:
        """Return and forget the pending partial line (end of a recording); not a line."""
        rest = bytes(self._pending)
        self._pending.clear()
        return rest
