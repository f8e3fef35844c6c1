"""Wire side of the simulated sensors: vectorised DBC packing, vectorised Xsens MTData2 packets,
CAN frame timing on the bus and the serial line (UART queue + read chunks).

Everything here produces exactly the bytes the foundation codecs produce (``codecs.can_encode``
``encode_fields``, ``codecs.imu_mtdata2.encode_imu_packet``; checked byte for byte in
``tests/test_wire.py``), only for whole arrays of samples at once: per-frame cantools encoding
costs about 9 us, which at 3-4 frames per millisecond would dominate a simulated drive.

CAN packing (DBC linear conversion, Intel byte order)
-----------------------------------------------------
::

    raw_k   = clip(floor((clip(x_k, lo_k, hi_k) - offset_k) / scale_k + 1/2), raw_min_k, raw_max_k)
    payload = sum_k (raw_k mod 2^len_k) << start_k          (64-bit little-endian word)
    data    = payload bytes 0 .. DLC-1

``lo/hi`` = the raw range widened by one step (keeps the division finite, changes no clamped
result), the same arithmetic as ``can_encode.quantize``. The rolling counter enters as
``(counter mod 2^len) << start``; a protected frame then gets byte 0 = ``codecs.can_e2e.e2e_crc``
(CRC-8/SAE-J1850 over the data ID and bytes 1..DLC-1, a table look-up per byte for all rows at
once). VDPS_Warning is not a simulated sensor and is refused here.

CAN timing
----------
All sensor messages sampled at one instant t_m contend for the bus; the lowest ID wins
arbitration and the frames go out back to back. A receiver stamps a frame when its last bit has
arrived (SocketCAN RX time)::

    t_rx,i = t_m + latency + sum_{j: id_j <= id_i, sent at t_m} C_j / R
    C_j = 47 + 8 DLC_j  [bit]   (frame without stuff bits, interframe space included)

Stuff bits (up to 24 per 8-byte frame) are neglected: the time stamps are early by at most
24 us. Contention between different instants is not modelled (the bus is below 40 % load and a
1 kHz burst ends 0.6 ms after it starts).

Serial line (8N1, ``codecs.framing``)
-------------------------------------
A message is handed to the UART at t_ready (measurement time + latency) and starts when the
previous one has left: s_k = max(t_ready,k, s_{k-1} + T(L_{k-1})), vectorised as
``s = C + cummax(t_ready - C)`` with C the running sum of message durations. Byte j (0-based) of
message k has fully arrived at::

    t_byte = s_k + T(j + 1),     T(n) = round(n * 10 * 1e9 / baud)  [ns]  (framing.transmission_time_ns)

The host reads in windows of ``read_period`` (default 5 ms, a USB-serial adapter's latency
timer): the bytes that finished arriving in ((w) P, (w+1) P] form one read chunk, stamped with the
arrival time of its last byte (a low-latency read: the framing module's assumption "the last
byte of the chunk arrived at about t_c"). The receive-time rule then gives each message the
arrival time of its own last byte when messages are back to back, and an upper bound otherwise
(packets earlier in a chunk than an idle gap appear late by that gap; the IMU packet counter and
SampleTimeFine give the exact instants).

Symbols: x physical value [SI], raw integer on the wire, t_m measurement time [ns], R bit rate
[bit/s], C frame length [bit], L message length [byte], P read period [ns].
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from vdps_hil.codecs import can_e2e
from vdps_hil.codecs import imu_mtdata2 as imu_codec
from vdps_hil.codecs.can_busload import frame_bits
from vdps_hil.codecs.can_dbc import MessageSpec, SignalSpec, VdpsDbc, load_dbc
from vdps_hil.codecs.framing import BITS_PER_BYTE_8N1, NS_PER_S

__all__ = ["CanPacker", "can_packers", "pack_imu_packets", "frame_time_ns", "bus_offsets_ns",
           "SerialLink", "raw_values"]


# ---------------------------------------------------------------------------------------------
# CAN
# ---------------------------------------------------------------------------------------------
def raw_values(sig: SignalSpec, values: np.ndarray) -> np.ndarray:
    """Physical values -> clamped raw integers (int64), the arithmetic of ``can_encode``'s
    encoder (NaN raises ValueError, as the encoder does)."""
    v = np.asarray(values, dtype=float)
    if np.isnan(v).any():
        raise ValueError(f"{sig.name}: cannot encode NaN")
    lo, hi = _physical_range(sig)
    raw = np.floor((np.clip(v, lo, hi) - sig.offset) / sig.scale + 0.5)
    return np.clip(raw, sig.raw_min, sig.raw_max).astype(np.int64)


def _physical_range(sig: SignalSpec) -> tuple[float, float]:
    """(lo, hi): the raw range in physical units widened by one step (module docstring)."""
    a = sig.raw_min * sig.scale + sig.offset
    b = sig.raw_max * sig.scale + sig.offset
    step = abs(sig.scale)
    return min(a, b) - step, max(a, b) + step


class CanPacker:
    """Vectorised encoder of one DBC sensor message (Intel byte order, E2E CRC if it has one).

    ``pack(values, counters)``: values (N, k) in the order of ``field_names``, counters (N,)
    -> (N, DLC) uint8 payloads, byte-identical to ``can_encode.encode_fields``.
    ``quantize(values)`` -> what a decoder reads back (same shape)."""

    def __init__(self, spec: MessageSpec):
        if not spec.is_sensor:
            raise ValueError(f"{spec.name}: not a sensor message")
        for s in (*spec.values, spec.counter):
            if getattr(s.signal, "byte_order", "little_endian") != "little_endian":
                raise ValueError(f"{spec.name}.{s.name}: only Intel (little endian) signals")
            if s.start_bit + s.length_bits > 64:
                raise ValueError(f"{spec.name}.{s.name}: signal beyond 64 bits")
        self.spec = spec
        self.name = spec.name
        self.frame_id = spec.frame_id
        self.dlc = spec.dlc
        self.field_names: tuple[str, ...] = spec.field_names
        self.resolution = tuple(s.resolution for s in spec.values)
        # per-signal constants as rows, so that all signals are converted at once (raw_values' arithmetic)
        sigs = spec.values
        self._lo, self._hi = (np.array(r, dtype=float) for r in zip(*map(_physical_range, sigs)))
        self._offset = np.array([s.offset for s in sigs], dtype=float)
        self._scale = np.array([s.scale for s in sigs], dtype=float)
        self._raw_min = np.array([s.raw_min for s in sigs], dtype=float)
        self._raw_max = np.array([s.raw_max for s in sigs], dtype=float)
        self._masks = np.array([(1 << s.length_bits) - 1 for s in sigs], dtype=np.int64)
        self._shifts = np.array([s.start_bit for s in sigs], dtype=np.uint64)

    def raw(self, values: np.ndarray) -> np.ndarray:
        """(N, k) physical values -> raw integers, ``raw_values`` of every column at once."""
        values = np.asarray(values, dtype=float).reshape(-1, len(self.field_names))
        nan = np.isnan(values).any(axis=0)
        if nan.any():
            raise ValueError(f"{self.spec.values[int(np.argmax(nan))].name}: cannot encode NaN")
        raw = np.floor((np.clip(values, self._lo, self._hi) - self._offset) / self._scale + 0.5)
        return np.clip(raw, self._raw_min, self._raw_max).astype(np.int64)

    def quantize(self, values: np.ndarray) -> np.ndarray:
        raw = self.raw(values)
        return np.stack([raw[:, i] * s.scale + s.offset for i, s in enumerate(self.spec.values)], axis=1)

    def pack(self, values: np.ndarray, counters: np.ndarray) -> np.ndarray:
        raw = self.raw(values)
        word = np.bitwise_or.reduce((raw & self._masks).astype(np.uint64) << self._shifts, axis=1)
        c = self.spec.counter
        cnt = np.asarray(counters, dtype=np.int64) & np.int64((1 << c.length_bits) - 1)
        word |= cnt.astype(np.uint64) << np.uint64(c.start_bit)
        data = word.astype("<u8").view(np.uint8).reshape(-1, 8)[:, :self.dlc]
        if self.spec.crc is not None:
            data = np.ascontiguousarray(data)
            data[:, 0] = _e2e_crc_rows(data, self.spec.data_id)
        return data


_CRC8_TABLE = np.array(can_e2e._CRC8_TABLE, dtype=np.uint8)


def _e2e_crc_rows(data: np.ndarray, data_id: int | None) -> np.ndarray:
    """``can_e2e.e2e_crc`` of every row of ``data`` (N, DLC) uint8 (byte 0 is not covered)."""
    reg = np.full(data.shape[0], can_e2e.e2e_register(data_id), dtype=np.uint8)
    for j in range(1, data.shape[1]):
        reg = _CRC8_TABLE[reg ^ data[:, j]]
    return reg ^ np.uint8(can_e2e.CRC8_XOROUT)


def can_packers(dbc: VdpsDbc | None = None) -> dict[str, CanPacker]:
    """A packer for every sensor message of the DBC, by message name."""
    dbc = dbc or load_dbc()
    return {name: CanPacker(spec) for name, spec in dbc.messages.items() if spec.is_sensor}


def frame_time_ns(dlc: int, bitrate_bps: int) -> int:
    """Duration of a classic frame without stuff bits (interframe space included) [ns]."""
    return (frame_bits(dlc, stuffing="none") * NS_PER_S + bitrate_bps // 2) // bitrate_bps


def bus_offsets_ns(t_meas_ns: np.ndarray, frame_ids: np.ndarray, durations_ns: np.ndarray) -> np.ndarray:
    """Receive-time offsets t_rx - t_m of frames queued at instants ``t_meas_ns``: frames of one
    instant go out in ID order back to back; each offset is the sum of the durations of the
    frames before it at that instant plus its own (module docstring)."""
    t = np.asarray(t_meas_ns, dtype=np.int64)
    if t.size == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.lexsort((np.asarray(frame_ids), t))
    d = np.asarray(durations_ns, dtype=np.int64)[order]
    ts = t[order]
    csum = np.cumsum(d)
    start = np.ones(ts.size, dtype=bool)
    start[1:] = ts[1:] != ts[:-1]
    group_first = np.maximum.accumulate(np.where(start, np.arange(ts.size), 0))
    before = csum[group_first] - d[group_first]
    out = np.empty_like(csum)
    out[order] = csum - before
    return out


# ---------------------------------------------------------------------------------------------
# IMU: Xsens MTData2 (PacketCounter, SampleTimeFine, Acceleration, RateOfTurn; float32)
# ---------------------------------------------------------------------------------------------
_MTDATA2_DTYPE = np.dtype([
    ("pre", "u1"), ("bid", "u1"), ("mid", "u1"), ("len", "u1"),
    ("xdi_c", ">u2"), ("sz_c", "u1"), ("counter", ">u2"),
    ("xdi_t", ">u2"), ("sz_t", "u1"), ("stf", ">u4"),
    ("xdi_a", ">u2"), ("sz_a", "u1"), ("acc", ">f4", (3,)),
    ("xdi_w", ">u2"), ("sz_w", "u1"), ("gyr", ">f4", (3,)),
    ("cs", "u1"),
])
assert _MTDATA2_DTYPE.itemsize == imu_codec.PACKET_BYTES == 47


def pack_imu_packets(t_device_ns: np.ndarray, counters: np.ndarray, specific_force_mps2: np.ndarray,
                     angular_rate_radps: np.ndarray) -> np.ndarray:
    """(N, 47) uint8: one MTData2 message per row, byte-identical to
    ``codecs.imu_mtdata2.encode_imu_packet(t, f, w, seq)`` with the identity ``sensor_to_body`` (the
    values given are already in sensor axes). SampleTimeFine = nearest 100 us tick of the device
    time, modulo 2^32; PacketCounter = counter mod 65536."""
    n = len(counters)
    a = np.zeros(n, dtype=_MTDATA2_DTYPE)
    a["pre"], a["bid"], a["mid"], a["len"] = imu_codec.PREAMBLE, imu_codec.BID_MASTER, imu_codec.MID_MTDATA2, 42
    a["xdi_c"], a["sz_c"] = imu_codec.XDI_PACKET_COUNTER, 2
    a["counter"] = np.asarray(counters, dtype=np.int64) & 0xFFFF
    a["xdi_t"], a["sz_t"] = imu_codec.XDI_SAMPLE_TIME_FINE, 4
    tick = imu_codec.NS_PER_FINE_TICK
    a["stf"] = ((np.asarray(t_device_ns, dtype=np.int64) + tick // 2) // tick) & 0xFFFFFFFF
    a["xdi_a"], a["sz_a"] = imu_codec.XDI_ACCELERATION, 12
    a["acc"] = _codec_axes(specific_force_mps2)
    a["xdi_w"], a["sz_w"] = imu_codec.XDI_RATE_OF_TURN, 12
    a["gyr"] = _codec_axes(angular_rate_radps)
    b = a.view(np.uint8).reshape(n, 47)
    b[:, 46] = (-b[:, 1:46].sum(axis=1, dtype=np.int64)) & 0xFF
    return b


def _codec_axes(v) -> np.ndarray:
    """(N, 3) values through the codec's own r^T v (``imu_mtdata2.apply_transpose``) with its
    default ``SENSOR_TO_BODY`` (the identity): the same doubles, signed zeros included (1 (-0.0)
    + 0 (+0.0) is +0.0, while -0.0 with negative other components stays -0.0)."""
    v = np.asarray(v, dtype=float).reshape(-1, 3)
    return np.stack(imu_codec.apply_transpose(imu_codec.SENSOR_TO_BODY, v.T), axis=1)


# ---------------------------------------------------------------------------------------------
# Serial line
# ---------------------------------------------------------------------------------------------
class SerialLink:
    """One serial device's UART and the host's reads (module docstring).

    ``send(t_ready_ns, messages)`` queues messages (an (N, L) uint8 array of equal-length
    messages, or a list of bytes); ``chunks(until_ns)`` returns the read chunks
    ``[(t_ns, bytes)]`` of every read window that has ended by ``until_ns``;
    ``chunks(until_ns, final=True)`` also returns the bytes of the window in progress that
    arrived by ``until_ns`` and forgets the rest (the logger stopped). ``keep(arrival_ns) ->
    bool mask`` drops bytes that never arrive (a disconnected cable)."""

    def __init__(self, device: str, baud: int, read_period_ns: int = 5_000_000,
                 keep: Callable[[np.ndarray], np.ndarray] | None = None,
                 bits_per_byte: int = BITS_PER_BYTE_8N1):
        if baud <= 0 or read_period_ns <= 0:
            raise ValueError("baud and read period must be positive")
        self.device = device
        self.baud = int(baud)
        self.bits_per_byte = int(bits_per_byte)
        self.read_period_ns = int(read_period_ns)
        self.keep = keep
        self.busy_until_ns = 0
        self._t = np.zeros(0, dtype=np.int64)
        self._b = np.zeros(0, dtype=np.uint8)
        self._ttab = self._tt_table(64)
        self.bytes_sent = 0
        self.bytes_lost = 0

    def _tt_table(self, n: int) -> np.ndarray:
        """T(j) for j = 0..n (framing.transmission_time_ns, vectorised)."""
        j = np.arange(n + 1, dtype=np.int64)
        num = j * self.bits_per_byte * NS_PER_S
        return (2 * num + self.baud) // (2 * self.baud)

    def _tt(self, n: int) -> np.ndarray:
        if n >= len(self._ttab):
            self._ttab = self._tt_table(max(n, 2 * len(self._ttab)))
        return self._ttab[:n + 1]

    def _starts(self, t_ready: np.ndarray, durations: np.ndarray) -> np.ndarray:
        t_ready = np.asarray(t_ready, dtype=np.int64)
        c = np.concatenate(([0], np.cumsum(durations[:-1]))) if len(durations) else np.zeros(0, np.int64)
        s = c + np.maximum.accumulate(np.maximum(t_ready - c, self.busy_until_ns))
        if len(s):
            self.busy_until_ns = int(s[-1] + durations[-1])
        return s

    def send(self, t_ready_ns: Sequence[int] | np.ndarray, messages) -> None:
        if isinstance(messages, np.ndarray):
            n, length = messages.shape
            if n == 0:
                return
            tt = self._tt(length)
            dur = np.full(n, tt[length], dtype=np.int64)
            s = self._starts(t_ready_ns, dur)
            arrival = (s[:, None] + tt[None, 1:]).ravel()
            data = messages.reshape(-1)
        else:
            msgs = [bytes(m) for m in messages]
            if not msgs:
                return
            lens = np.array([len(m) for m in msgs], dtype=np.int64)
            tt = self._tt(int(lens.max()))
            s = self._starts(t_ready_ns, tt[lens])
            arrival = np.concatenate([s[k] + tt[1:lens[k] + 1] for k in range(len(msgs))])
            data = np.frombuffer(b"".join(msgs), dtype=np.uint8)
        self.bytes_sent += data.size
        if self.keep is not None:
            m = self.keep(arrival)
            if not m.all():
                self.bytes_lost += int(data.size - m.sum())
                arrival, data = arrival[m], data[m]
        if self._t.size and arrival.size and arrival[0] < self._t[-1]:
            # never happens with one UART; keep the stream ordered if a caller interleaves
            t = np.concatenate((self._t, arrival))
            b = np.concatenate((self._b, data))
            o = np.argsort(t, kind="stable")
            self._t, self._b = t[o], b[o]
        else:
            self._t = np.concatenate((self._t, arrival))
            self._b = np.concatenate((self._b, data))

    def chunks(self, until_ns: int, final: bool = False) -> list[tuple[int, bytes]]:
        t = self._t
        if t.size == 0:
            return []
        p = self.read_period_ns
        w = (t - 1) // p
        if final:
            n = int(np.searchsorted(t, until_ns, side="right"))
        else:
            n = int(np.searchsorted(w, until_ns // p, side="left"))
        if n == 0:
            if final:
                self._t, self._b = t[:0], self._b[:0]
            return []
        ws = w[:n]
        cuts = np.flatnonzero(ws[1:] != ws[:-1]) + 1
        starts = np.concatenate(([0], cuts))
        ends = np.concatenate((cuts, [n]))
        raw = self._b[:n].tobytes()
        out = [(int(t[e - 1]), raw[a:e]) for a, e in zip(starts.tolist(), ends.tolist())]
        if final:
            self._t, self._b = t[:0], self._b[:0]
        else:
            self._t, self._b = t[n:], self._b[n:]
        return out

    @property
    def pending_bytes(self) -> int:
        return int(self._t.size)
