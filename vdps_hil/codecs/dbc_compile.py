"""DBC bit layouts compiled once into integer operations (the decoders' hot path).

cantools decodes a frame by unpacking it twice with bitstruct (both byte orders), merging the
dicts and converting each signal: about 6 us per frame, most of a replay's CAN time. The layout
of a message is fixed, so each signal's raw value is one shift and one mask of the payload read
as an integer::

    little endian (Intel):    u = (int_le(data) >> start) & (2^len - 1)
    big endian (Motorola):    u = (int_be(data) >> (8 n - msb - len)) & (2^len - 1),
                              msb = 8 (start // 8) + 7 - start mod 8   (network bit number of
                              the DBC start bit, which is the signal's most significant bit)
    signed:                   raw = u - 2^len  if u >= 2^(len - 1)  else u

(n the message length in bytes; ``start``/``len`` the DBC start bit and length). Packing
(``CompiledMessage.pack``, the encoders) is the inverse: each raw value, taken modulo 2^len
(two's complement for a signed one), shifted into its integer of the payload, the two byte
orders' integers merged; bits no signal covers stay 0, as cantools' ``Message.encode`` leaves
them. Nothing is
generated or evaluated from the DBC's text: the layout becomes tuples of integers.
:func:`compile_message` refuses (``NotCompilable``) what this does not cover -- float signals,
multiplexed and container messages, signals outside the payload or overlapping each other (a
non-strict DBC) -- and the callers then keep cantools.
Equality with cantools' own decoding is tested on every message of the project's DBCs and on
random layouts of both byte orders (hypothesis, ``tests/test_dbc_compile.py``).
"""

from __future__ import annotations

__all__ = ["CompiledMessage", "NotCompilable", "compile_message", "signal_extractor"]


class NotCompilable(ValueError):
    """The message uses a feature the compiled path does not cover (float or multiplexed
    signals, a signal outside the payload): decode it with cantools."""


def signal_extractor(signal, length_bytes: int) -> tuple[bool, int, int, int]:
    """(big endian, shift, mask, sign bit or 0) of one cantools signal in a payload of
    ``length_bytes`` bytes (module docstring)."""
    if getattr(signal, "is_float", False) or signal.conversion.is_float:
        raise NotCompilable(f"{signal.name}: float signal")
    if signal.is_multiplexer or signal.multiplexer_ids:
        raise NotCompilable(f"{signal.name}: multiplexed signal")
    n, start = int(signal.length), int(signal.start)
    if n <= 0:
        raise NotCompilable(f"{signal.name}: length {n}")
    if signal.byte_order == "little_endian":
        big, shift = False, start
        if start < 0 or start + n > 8 * length_bytes:
            raise NotCompilable(f"{signal.name}: outside the payload")
    else:
        msb = 8 * (start // 8) + 7 - start % 8
        big, shift = True, 8 * length_bytes - msb - n
        if msb < 0 or shift < 0:
            raise NotCompilable(f"{signal.name}: outside the payload")
    return big, shift, (1 << n) - 1, (1 << (n - 1)) if signal.is_signed else 0


class CompiledMessage:
    """One cantools message compiled (module docstring). ``raw(data)``: the raw integers of
    all signals in ``names`` order for a payload of exactly ``length`` bytes (the caller checks
    the length)."""

    __slots__ = ("name", "length", "names", "_le", "_be")

    def __init__(self, message):
        if getattr(message, "is_multiplexed", lambda: False)():
            raise NotCompilable(f"{message.name}: multiplexed message")
        if getattr(message, "is_container", False):
            raise NotCompilable(f"{message.name}: container message")
        self.name = message.name
        self.length = int(message.length)
        self.names = tuple(s.name for s in message.signals)
        le, be = [], []
        used: set[tuple[int, int]] = set()  # (byte, bit) of every signal bit
        for i, s in enumerate(message.signals):
            big, shift, mask, sign = signal_extractor(s, self.length)
            (be if big else le).append((i, shift, mask, sign))
            bits = {((self.length - 1 - b // 8) if big else b // 8, b % 8)
                    for b in range(shift, shift + mask.bit_length())}
            if bits & used:  # a non-strict DBC: leave its overlapping layout to cantools
                raise NotCompilable(f"{message.name}.{s.name}: overlaps another signal")
            used |= bits
        self._le = tuple(le)
        self._be = tuple(be)

    @property
    def extractors(self) -> tuple[tuple, tuple]:
        """(little-endian, big-endian) extractors: tuples of (signal index, shift, mask, sign bit
        or 0), what ``raw`` applies (module docstring); ``codecs.can_bulk`` applies them to
        blocks of payloads."""
        return self._le, self._be

    def raw(self, data: bytes) -> list[int]:
        if not self._be:  # Intel only (the project's DBC): signals in order
            x = int.from_bytes(data, "little")
            vals = []
            for _, shift, mask, sign in self._le:
                u = (x >> shift) & mask
                vals.append(u - (sign << 1) if sign and u >= sign else u)
            return vals
        out = [0] * len(self.names)
        if self._le:
            x = int.from_bytes(data, "little")
            for i, shift, mask, sign in self._le:
                u = (x >> shift) & mask
                out[i] = u - (sign << 1) if sign and u >= sign else u
        if self._be:
            x = int.from_bytes(data, "big")
            for i, shift, mask, sign in self._be:
                u = (x >> shift) & mask
                out[i] = u - (sign << 1) if sign and u >= sign else u
        return out

    def pack(self, raws) -> bytes:
        """The payload (``length`` bytes) of the raw integers ``raws`` in ``names`` order, the
        inverse of :meth:`raw`: what cantools' ``Message.encode(..., scaling=False)`` writes.
        ``ValueError`` naming the signal when a raw value does not fit its bit field."""
        x = y = 0
        for group, big in ((self._le, False), (self._be, True)):
            for i, shift, mask, sign in group:
                r = raws[i]
                lo, hi = (-sign, sign - 1) if sign else (0, mask)
                if not lo <= r <= hi:
                    raise ValueError(f"{self.name}.{self.names[i]}: raw {r!r} does not fit {lo}..{hi}")
                if big:
                    y |= (r & mask) << shift
                else:
                    x |= (r & mask) << shift
        if y:
            x |= int.from_bytes(y.to_bytes(self.length, "big"), "little")
        return x.to_bytes(self.length, "little")

    def raw_dict(self, data: bytes) -> dict[str, int]:
        """``{signal: raw}`` as ``message.decode(data, decode_choices=False, scaling=False)``."""
        return dict(zip(self.names, self.raw(data)))


def compile_message(message) -> CompiledMessage:
    """A :class:`CompiledMessage`, or :class:`NotCompilable`."""
    return CompiledMessage(message)
