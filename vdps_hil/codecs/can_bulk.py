"""All frames of one message at once (numpy): raw signal values, E2E CRCs and scaled values of a
block of payloads, the bulk half of ``VdpsCanDecoder.decode_many`` (``codecs.can_decode``).

The layout is the compiled one (``codecs.dbc_compile``) applied to every row of an ``(n, L)``
``uint8`` block: each payload read as one integer, zero-padded to 8 bytes (classic CAN)::

    little endian:  x = uint64 of the payload, zeros appended   (int_le(data))
    big endian:     x = uint64 of the payload, zeros prepended  (int_be(data))
    u = (x >> shift) & mask,   raw = u - 2 sign  if sign and u >= sign  else u

which is ``CompiledMessage.raw`` per row. The CRC-8/SAE-J1850 of byte 0 runs its table over the
columns 1..L-1 from the register after the data ID (``codecs.can_e2e.e2e_crc``). A scaled value
is ``raw * scale + offset`` as two float64 operations (numpy does not fuse them), exactly
``float(r * scale + offset)`` of the per-frame path for raw values below 2^53; the TTR sentinel
raw 65535 gives +inf. Equality with the per-frame decoder, frame by frame and counter by
counter, is tested on recordings and malformed frames (``tests/test_can_bulk.py``).
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.codecs.can_e2e import _CRC8_TABLE, CRC8_XOROUT

__all__ = ["bulk_layout", "payload_block", "raw_columns", "crc_column", "scaled_column"]

_TABLE = np.array(_CRC8_TABLE, dtype=np.uint8)
MAX_BULK_BYTES = 8
"""Longest payload read as one uint64 (classic CAN); longer messages decode frame by frame."""


def bulk_layout(compiled, length: int) -> tuple | None:
    """``(little-endian extractors, big-endian extractors)`` of a compiled message, each a tuple
    of (signal index, shift, mask, sign) as ``CompiledMessage`` holds them, or None when the
    bulk path does not cover it (no compiled layout, over 8 bytes, a signal of 63 bits or more)."""
    if compiled is None or not 0 < length <= MAX_BULK_BYTES:
        return None
    le, be = compiled.extractors
    if any(mask.bit_length() > 62 for _, _, mask, _ in le + be):
        return None
    return le, be


def payload_block(payloads: list[bytes], length: int) -> np.ndarray:
    """The ``(n, length)`` uint8 block of ``n`` payloads of exactly ``length`` bytes each."""
    return np.frombuffer(b"".join(payloads), dtype=np.uint8).reshape(len(payloads), length)


def _as_uint64(block: np.ndarray, big: bool) -> np.ndarray:
    n, length = block.shape
    wide = np.zeros((n, 8), dtype=np.uint8)
    if big:
        wide[:, 8 - length:] = block
        return wide.view(">u8").ravel().astype(np.uint64)
    wide[:, :length] = block
    return wide.view("<u8").ravel().astype(np.uint64)


def raw_columns(layout: tuple, nsignals: int, block: np.ndarray) -> list[np.ndarray]:
    """The raw values (int64) of every signal of the message, one array per signal in the
    message's signal order, for each row of ``block`` (module docstring)."""
    cols: list[np.ndarray] = [None] * nsignals  # type: ignore[list-item]
    for extractors, big in ((layout[0], False), (layout[1], True)):
        if not extractors:
            continue
        x = _as_uint64(block, big)
        for i, shift, mask, sign in extractors:
            u = ((x >> np.uint64(shift)) & np.uint64(mask)).astype(np.int64)
            cols[i] = np.where(u >= sign, u - 2 * sign, u) if sign else u
    return cols


def crc_column(block: np.ndarray, reg: int) -> np.ndarray:
    """``e2e_crc`` of every row (bytes 1.. after the register ``reg`` of the data ID), int64."""
    r = np.full(block.shape[0], reg, dtype=np.uint8)
    for j in range(1, block.shape[1]):
        r = _TABLE[r ^ block[:, j]]
    return (r ^ np.uint8(CRC8_XOROUT)).astype(np.int64)


def scaled_column(raw: np.ndarray, scale, offset, ttr_raw: int | None) -> list[float]:
    """``float(r * scale + offset)`` of each raw value (``+inf`` for ``ttr_raw``), as Python floats.
    Integer arithmetic that could leave int64 (an integer scale or offset on a wide signal) is
    done per value in Python, as the per-frame path does."""
    if not (isinstance(scale, float) and isinstance(offset, float)) and raw.size and \
            int(np.abs(raw).max()) * abs(scale) + abs(offset) >= 2 ** 62:
        vals = [float(r * scale + offset) for r in raw.tolist()]
        return vals if ttr_raw is None else [math.inf if r == ttr_raw else x for r, x in zip(raw.tolist(), vals)]
    v = raw * scale + offset
    if v.dtype != np.float64:
        v = v.astype(np.float64)
    if ttr_raw is not None:
        v = np.where(raw == ttr_raw, math.inf, v)
    return v.tolist()
