"""Tests of sim.wire: the vectorised encoders give the foundation codecs' bytes exactly, CAN
bus timing, and the serial line's UART queue and read chunks (with the receive-time rule)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.codecs.can_busload import frame_bits
from vdps_hil.codecs.can_dbc import load_dbc
from vdps_hil.codecs.can_encode import encode_fields, quantize
from vdps_hil.codecs.framing import LineFramer, transmission_time_ns
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.imu_mtdata2 import encode_imu_packet
from vdps_hil.sim.wire import (CanPacker, SerialLink, bus_offsets_ns, can_packers, frame_time_ns,
                               pack_imu_packets)

DBC = load_dbc()
PACKERS = can_packers(DBC)
values = st.floats(-1e4, 1e4, allow_nan=False)


def test_packers_cover_every_sensor_message_and_refuse_the_warning():
    assert set(PACKERS) == {n for n in DBC.messages if n != "VDPS_Warning"}
    with pytest.raises(ValueError):
        CanPacker(DBC.messages["VDPS_Warning"])


@settings(max_examples=150, deadline=None, derandomize=True)
@given(name=st.sampled_from(sorted(PACKERS)), data=st.data())
def test_can_pack_equals_cantools_encoder(name, data):
    pk = PACKERS[name]
    n = data.draw(st.integers(1, 6))
    vals = np.array([[data.draw(st.one_of(values, st.floats(-1e9, 1e9, allow_nan=False)))
                      for _ in pk.field_names] for _ in range(n)])
    counters = np.array([data.draw(st.integers(0, 10**6)) for _ in range(n)])
    got = pk.pack(vals, counters)
    assert got.shape == (n, pk.dlc) and got.dtype == np.uint8
    for i in range(n):
        ref = encode_fields(name, dict(zip(pk.field_names, vals[i])), int(counters[i]), dbc=DBC)
        assert got[i].tobytes() == bytes(ref.data)
    q = pk.quantize(vals)
    for j, f in enumerate(pk.field_names):
        np.testing.assert_array_equal(q[:, j], quantize(f, vals[:, j], DBC))


def test_can_pack_rejects_nan():
    pk = PACKERS["VDPS_SteerAngle"]
    with pytest.raises(ValueError):
        pk.pack(np.array([[np.nan]]), np.array([0]))


@settings(max_examples=100, deadline=None, derandomize=True)
@given(t=st.integers(0, 10**15), c=st.integers(0, 10**6),
       f=st.lists(st.floats(-200, 200, allow_nan=False), min_size=3, max_size=3),
       w=st.lists(st.floats(-40, 40, allow_nan=False), min_size=3, max_size=3))
def test_imu_pack_equals_codec(t, c, f, w):
    got = pack_imu_packets(np.array([t]), np.array([c]), np.array([f]), np.array([w]))
    assert got[0].tobytes() == encode_imu_packet(t, f, w, c)


def test_imu_packets_decode_back(rng):
    n = 50
    t = np.arange(n, dtype=np.int64) * 1_000_000
    f, w = rng.normal(0, 5, (n, 3)), rng.normal(0, 1, (n, 3))
    b = pack_imu_packets(t, np.arange(n), f, w)
    dec = ImuDecoder()
    out = dec.feed(0, b.tobytes()) + dec.flush()
    assert len(out) == n and dec.counters["rejected"] == 0
    got = np.array([[s.fields[k] for k in ("specific_force_mps2_x", "specific_force_mps2_y",
                                           "specific_force_mps2_z")] for s in out])
    np.testing.assert_allclose(got, f, rtol=1e-7, atol=1e-6)  # float32 on the wire


def test_frame_time_is_the_unstuffed_frame_length():
    assert frame_time_ns(8, 1_000_000) == frame_bits(8, stuffing="none") * 1000 == 111_000
    assert frame_time_ns(3, 500_000) == 2 * 71_000


def test_bus_offsets_follow_id_order_within_an_instant():
    t = np.array([0, 0, 0, 1_000_000, 1_000_000], dtype=np.int64)
    ids = np.array([0x101, 0x100, 0x110, 0x130, 0x100])
    dur = np.array([87_000, 87_000, 111_000, 71_000, 87_000])
    off = bus_offsets_ns(t, ids, dur)
    # instant 0: 0x100 first, then 0x101, then 0x110; instant 1 ms: 0x100 then 0x130
    assert off.tolist() == [174_000, 87_000, 285_000, 158_000, 87_000]
    assert bus_offsets_ns(np.zeros(0, np.int64), np.zeros(0), np.zeros(0)).size == 0


def _lines(n_lines, rng):
    return [b"$" + bytes(rng.integers(65, 90, rng.integers(5, 60)).astype(np.uint8)) + b"\r\n"
            for _ in range(n_lines)]


def test_serial_bytes_arrive_at_start_plus_wire_time_and_queue():
    link = SerialLink("gnss", 115200, read_period_ns=5_000_000)
    msgs = [b"A" * 10, b"B" * 20]
    link.send(np.array([1_000_000, 1_000_000]), msgs)  # second waits for the first
    t_first_end = 1_000_000 + transmission_time_ns(10, 115200)
    t_second_end = t_first_end + transmission_time_ns(20, 115200)
    assert link.busy_until_ns == t_second_end
    chunks = link.chunks(10**10, final=True)
    assert b"".join(c for _, c in chunks) == b"A" * 10 + b"B" * 20
    assert chunks[-1][0] == t_second_end
    # a message ready after the line is free starts at its ready time
    link.send(np.array([t_second_end + 10**7]), [b"C"])
    (t, c), = link.chunks(10**12, final=True)
    assert (c, t) == (b"C", t_second_end + 10**7 + transmission_time_ns(1, 115200))


def test_serial_chunks_are_read_windows_stamped_by_their_last_byte(rng):
    p = 5_000_000
    link = SerialLink("gnss", 115200, read_period_ns=p)
    msgs = _lines(40, rng)
    ready = np.sort(rng.integers(0, 200_000_000, len(msgs)))
    link.send(ready, msgs)
    got = link.chunks(100_000_000) + link.chunks(10**12, final=True)
    assert b"".join(c for _, c in got) == b"".join(msgs)
    ts = [t for t, _ in got]
    assert ts == sorted(ts)
    assert len({(t - 1) // p for t in ts}) == len(ts)  # one chunk per window at most
    # every line time from the receive-time rule is >= the true arrival of its last byte (up to
    # the 1 ns rounding of each wire time summed over the chunk), and exact for the line that
    # ends its chunk
    ends, t_line_true = [], []
    busy = 0
    for r, m in zip(ready.tolist(), msgs):
        start = max(r, busy)
        busy = start + transmission_time_ns(len(m), 115200)
        t_line_true.append(busy)
    framer = LineFramer(115200)
    times = []
    for t, c in got:
        lines = framer.feed(t, c)
        times += [tl for tl, _ in lines]
        if c.endswith(b"\n"):
            ends.append((lines[-1][0], t))
    assert len(times) == len(msgs)
    assert all(a >= b - 3 for a, b in zip(times, t_line_true))
    for tl, tc in ends:
        assert tl == tc and tl in t_line_true


def test_serial_chunks_wait_for_their_window_and_keep_drops_bytes():
    link = SerialLink("imu", 921600, read_period_ns=5_000_000,
                      keep=lambda a: (a < 2_000_000) | (a >= 3_000_000))
    pk = pack_imu_packets(np.arange(5) * 1_000_000, np.arange(5), np.zeros((5, 3)), np.zeros((5, 3)))
    link.send(np.arange(5) * 1_000_000, pk)
    assert link.chunks(4_999_999) == []  # the first window has not ended
    (t, c), = link.chunks(5_000_000)
    assert len(c) == 4 * 47 and link.bytes_lost == 47 and link.pending_bytes == 0
    dec = ImuDecoder()
    out = dec.feed(t, c)
    assert [int(s.fields["seq_counter"]) for s in out] == [0, 1, 3, 4]


@settings(max_examples=100, deadline=None, derandomize=True)
@given(name=st.sampled_from(sorted(PACKERS)), data=st.data())
def test_can_raw_of_all_signals_at_once_equals_raw_values_per_signal(name, data):
    """CanPacker.raw (every signal's column at once) = raw_values of each signal, the reference,
    inside and far outside the signals' ranges."""
    from vdps_hil.sim.wire import raw_values

    pk = PACKERS[name]
    n = data.draw(st.integers(1, 8))
    vals = np.array([[data.draw(st.one_of(values, st.floats(-1e12, 1e12, allow_nan=False)))
                      for _ in pk.field_names] for _ in range(n)])
    ref = np.stack([raw_values(s, vals[:, i]) for i, s in enumerate(pk.spec.values)], axis=1)
    got = pk.raw(vals)
    assert got.dtype == ref.dtype and np.array_equal(got, ref)


def test_signed_zeros_are_packed_as_the_codec_writes_them():
    """Every combination of -0.0, +0.0 and signed values in the three axes: the packer's bytes
    are the codec's (r^T v term by term: -0.0 survives only when the other terms are -0.0)."""
    import itertools

    vals = (-0.0, 0.0, -1.5, 2.0)
    combos = np.array(list(itertools.product(vals, repeat=3)))
    got = pack_imu_packets(np.zeros(len(combos), dtype=np.int64), np.arange(len(combos)), combos, combos[::-1])
    for i, (f, w) in enumerate(zip(combos, combos[::-1])):
        assert got[i].tobytes() == encode_imu_packet(0, list(f), list(w), i)
