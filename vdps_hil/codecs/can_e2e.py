"""End-to-end protection of the vdps chassis bus: the rolling counters of every frame and the
CRC-8/SAE-J1850 of every protected frame (the receiver's rules; ``codecs.can_decode`` applies
them per frame, ``codecs.can_encode`` and ``sim.wire`` write the CRC).

CRC and counter of each frame (layout 2, ``dbc/vdps.dbc``)
---------------------------------------------------------
In the spirit of AUTOSAR E2E profile 1 (CRC-8/SAE-J1850 in byte 0, 4-bit counter, a data ID
per protected message): a sensor frame's ``e2e_crc`` is the CRC of the data ID (its 11-bit CAN
ID; low byte, then high byte: profile 1's "both bytes" mode) followed by bytes 1..DLC-1
(:func:`e2e_crc`), so a payload under another ID fails too; ``VDPS_Warning``'s ``warning_crc``
covers bytes 1..7 only (no data ID, its layout is unchanged since version 1). The CRC is checked
first: a corrupted frame is rejected (``crc_mismatch``) before its counter is read, so it leaves
the counter history as it was and the next valid frame is accepted. Layout 1 (``dbc/vdps_v1.dbc``)
has no sensor CRC and 8-bit sensor counters; the rules below take the counter width from the DBC.

Sequence counters
-----------------
Every frame carries a rolling counter (``seq_counter`` on sensor frames, ``warning_counter`` on
the warning: 4 bits each in layout 2), +1 per frame. Per message the decoder computes
``delta = (c - c_last) mod 2^bits``:

* sensor frames: ``delta = 0`` -> reject (``counter_repeat``: duplicated or stale frame);
  ``delta >= 1`` -> accept, ``lost_frames += delta - 1``. Once the frame period T has been
  learned (running mean of the plausible gaps, dt < 4 T, between consecutive frames), a gap dt
  longer than half a counter cycle suggests ``W = round((dt / T - delta) / 2^bits)`` whole
  wraps, so a silence of several wraps is still counted frame by frame. The ``W 2^bits`` frames
  are counted only when the next frame comes at the frame pace (its dt >= T / 4): frames a
  stalled reader delivers in one burst carry the burst's receive time, so a long dt followed by
  a burst (dt ~ 0) is the reader's stall, not a loss (``stall_gaps`` counts those).
* VDPS_Warning (AUTOSAR-E2E-like): ``warning_crc`` (byte 0) must equal CRC-8/SAE-J1850 of bytes
  1..7, else reject (``crc_mismatch``; the counter of a corrupted frame is not trusted and not
  stored). Then ``delta = 0`` -> reject (``counter_repeat``); ``1 <= delta <= 3`` -> accept,
  ``lost_frames += delta - 1``; ``delta > 3`` -> reject (``counter_jump``), resynchronise on
  this counter, ``lost_frames += delta - 1`` (a lower bound).
* CRC-8/SAE-J1850: poly x^8+x^4+x^3+x^2+1 (0x1D), init 0xFF, no reflection, xorout 0xFF;
  check value over ASCII ``123456789`` = 0x4B (SAE J1850, AUTOSAR SWS CRC Library
  ``Crc_CalculateCRC8``, reveng catalogue CRC-8/SAE-J1850). Over the 8-byte frame it detects
  every 1- and 2-bit error (exhaustively tested); other corruptions pass with probability
  about 1/256 (3-bit errors: 198 of 41,664 patterns), so the counter and range checks stay.
"""

from __future__ import annotations

import numpy as np

WARNING_MAX_DELTA_COUNTER = 3
"""Largest accepted warning counter step (2 frames lost); larger jumps are rejected."""


# ---------------------------------------------------------------------------------------------
# CRC-8/SAE-J1850
# ---------------------------------------------------------------------------------------------
CRC8_POLY = 0x1D
CRC8_INIT = 0xFF
CRC8_XOROUT = 0xFF


def _crc8_table(poly: int) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        reg = byte
        for _ in range(8):
            reg = ((reg << 1) ^ poly) & 0xFF if reg & 0x80 else (reg << 1) & 0xFF
        table.append(reg)
    return tuple(table)


_CRC8_TABLE = _crc8_table(CRC8_POLY)


def _crc8_update(reg: int, data) -> int:
    """The CRC-8/SAE-J1850 register after ``data`` (bytes or ints) from ``reg`` (no xorout)."""
    table = _CRC8_TABLE
    for b in bytes(data):
        reg = table[reg ^ b]
    return reg


def crc8_j1850(data: bytes | bytearray | memoryview) -> int:
    """CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, MSB first, xorout 0xFF); ``b"123456789"`` -> 0x4B."""
    return _crc8_update(CRC8_INIT, data) ^ CRC8_XOROUT


def e2e_register(data_id: int | None) -> int:
    """The CRC register after the data ID (low, high byte) from the initial value; ``CRC8_INIT``
    for None (no data ID). A receiver computes it once per message."""
    if data_id is None:
        return CRC8_INIT
    return _crc8_update(CRC8_INIT, (data_id & 0xFF, (data_id >> 8) & 0xFF))


def e2e_crc(payload: bytes | bytearray | memoryview, data_id: int | None, reg: int | None = None) -> int:
    """The CRC of byte 0 of a protected frame: CRC-8/SAE-J1850 over ``data_id`` (low, high byte;
    None: no data ID, VDPS_Warning) followed by ``payload[1:]`` (module docstring). ``reg``:
    :func:`e2e_register` of ``data_id`` when the caller has it."""
    reg = e2e_register(data_id) if reg is None else reg
    return _crc8_update(reg, payload[1:]) ^ CRC8_XOROUT


# ---------------------------------------------------------------------------------------------
# Rolling counters
# ---------------------------------------------------------------------------------------------
class SequenceState:
    """The rolling counter of one message as last accepted: counter ``last``, its time ``t_ns``,
    the learned frame period ``period_ns`` (None until two consecutive frames came) and the
    wrapped frames ``pending`` that the next frame's pace confirms (module docstring)."""

    __slots__ = ("last", "t_ns", "period_ns", "pending")

    def __init__(self):
        self.last: int | None = None
        self.t_ns: int | None = None
        self.period_ns: float | None = None
        self.pending = 0

    def check(self, c: int, t_ns: int, modulus: int, protected: bool, max_delta: int,
              counts: dict) -> str | None:
        """Apply the counter rule (module docstring) to counter ``c`` received at ``t_ns``:
        the reject reason, or None (accepted); ``counts["lost_frames"]`` grows by the frames
        missed. ``protected``: the E2E rule of VDPS_Warning (``max_delta``) instead of the
        sensor rule; ``modulus``: 2^bits of the counter."""
        if self.last is None:
            self.last, self.t_ns = c, t_ns
            return None
        delta = (c - self.last) % modulus
        dt = t_ns - self.t_ns
        if protected:  # E2E-protected: repeat and big jumps are rejected
            if delta == 0:
                return "counter_repeat"
            counts["lost_frames"] += delta - 1
            self.last, self.t_ns = c, t_ns
            return "counter_jump" if delta > max_delta else None
        p = self.period_ns
        wrapped = 0
        if p and dt > 0 and dt / p > modulus / 2:
            wrapped = modulus * max(round((dt / p - delta) / modulus), 0)
        if delta == 0 and not wrapped:
            return "counter_repeat"
        if self.pending:  # the previous frame followed a long gap: a loss if this one is paced
            if p and dt * 4 >= p:
                counts["lost_frames"] += self.pending
            else:
                counts["stall_gaps"] = counts.get("stall_gaps", 0) + 1
            self.pending = 0
        if delta == 1 and dt > 0 and (p is None or dt < 4 * p):
            self.period_ns = float(dt) if p is None else p + (dt - p) / 16
        counts["lost_frames"] += max(delta - 1, 0)
        self.pending = wrapped - (1 if delta == 0 else 0)
        self.last, self.t_ns = c, t_ns
        return None

    def check_many(self, cs: list[int], ts: list[int], modulus: int, protected: bool, max_delta: int,
                   counts: dict) -> list[str | None]:
        """:meth:`check` of each counter ``cs[k]`` received at ``ts[k]``, in order: the same
        reasons, state and counts (the sensor rule written out with local variables for the
        bulk decoder; ``tests/test_can_e2e.py`` holds it equal to :meth:`check`)."""
        if protected or not cs:
            return [self.check(c, t, modulus, True, max_delta, counts) for c, t in zip(cs, ts)]
        out: list[str | None] = []
        k0 = 0
        if self.last is None:
            self.last, self.t_ns = cs[0], ts[0]
            out.append(None)
            k0 = 1
        if self._paced(cs[k0:], ts[k0:], modulus):
            return out + [None] * (len(cs) - k0)
        last, t_last, p, pending = self.last, self.t_ns, self.period_ns, self.pending
        lost, stalls, half = 0, 0, modulus / 2
        for c, t in zip(cs[k0:], ts[k0:]):
            delta = (c - last) % modulus
            dt = t - t_last
            wrapped = 0
            if p and dt > 0 and dt / p > half:
                wrapped = modulus * max(round((dt / p - delta) / modulus), 0)
            if delta == 0 and not wrapped:
                out.append("counter_repeat")
                continue
            if pending:
                if p and dt * 4 >= p:
                    lost += pending
                else:
                    stalls += 1
                pending = 0
            if delta == 1 and dt > 0 and (p is None or dt < 4 * p):
                p = float(dt) if p is None else p + (dt - p) / 16
            if delta > 1:
                lost += delta - 1
            pending = wrapped - (1 if delta == 0 else 0)
            last, t_last = c, t
            out.append(None)
        self.last, self.t_ns, self.period_ns, self.pending = last, t_last, p, pending
        counts["lost_frames"] += lost
        if stalls:
            counts["stall_gaps"] = counts.get("stall_gaps", 0) + stalls
        return out

    def _paced(self, cs: list[int], ts: list[int], modulus: int) -> bool:
        """The common run of a sensor's frames taken at once when it is one: every counter +1,
        every gap dt > 0, a learned period p and nothing pending. The period then stays between
        its smallest and largest value so far (each step p + (dt - p) / 16 lies between p and
        dt, also rounded), so when the largest gap is below 4 times that smallest value and at
        most ``modulus / 2`` times it, every frame is accepted, none is lost, no wrap is
        suspected and only the period runs on (the same float steps as :meth:`check`).
        False, nothing changed: not such a run."""
        p = self.period_ns
        if not cs or not p or self.pending:
            return False
        try:
            c = np.asarray([self.last] + cs, dtype=np.int64)
            dts = np.diff(np.asarray([self.t_ns] + ts, dtype=np.int64))
        except OverflowError:  # times beyond int64: the loop in check_many
            return False
        if not (np.all(np.diff(c) % modulus == 1) and dts.min() > 0):
            return False
        lo, hi = min(p, float(dts.min())), float(dts.max())
        if not (hi < 4 * lo and hi / lo <= modulus / 2):
            return False
        for dt in dts.tolist():
            p = p + (dt - p) / 16
        self.last, self.t_ns, self.period_ns = cs[-1], ts[-1], p
        return True
