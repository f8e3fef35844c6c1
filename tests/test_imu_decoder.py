"""Tests of codecs.imu_decoder (the MTi byte stream): rejects counted by reason, the receive-time
rule, false headers and packets cut short, and fuzzing with garbage and corrupted packets.
"""

from __future__ import annotations

import struct
from fractions import Fraction

import numpy as np

from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.imu_mtdata2 import encode_imu_packet

from imu_checks import fields_of, xbus


def test_rejects_are_counted_by_reason():
    good = encode_imu_packet(0, (0, 0, 9.8), (0, 0, 0), 1)
    bad_cs = good[:-1] + bytes([(good[-1] + 1) & 0xFF])
    no_imu = xbus(0x36, struct.pack(">HBH", 0x1020, 2, 5))
    fp1632 = xbus(0x36, struct.pack(">HB", 0x4022, 18) + bytes(18)
                  + struct.pack(">HB", 0x8020, 12) + bytes(12))
    overrun = xbus(0x36, struct.pack(">HB", 0x4020, 40) + bytes(12))
    ack = xbus(0x31, b"")  # GoToConfigAck: a valid message of another kind
    dec = ImuDecoder()
    out = dec.feed(0, bad_cs + no_imu + fp1632 + overrun + ack + good)
    c = dec.counters
    assert len(out) == 1 and out[0].fields["seq_counter"] == 1
    assert c["reject_bad_checksum"] >= 1
    assert c["reject_no_imu_data"] == 1
    assert c["reject_unsupported_format"] == 1
    assert c["reject_malformed_payload"] == 1
    assert c["other_messages"] == 1


def test_receive_time_rule_and_sequence_gaps():
    # a 1 kHz stream at 921600 baud read in random chunks, each stamped with the arrival of its
    # last byte: every packet gets the arrival time of its own last byte (+-1 ns rounding)
    rng = np.random.default_rng(7)
    packets = [encode_imu_packet(k * 1_000_000, (0, 0, 9.8), (0, 0, 0.01 * k), k)
               for k in range(200)]
    del packets[50]  # one packet lost on the way
    stream = b"".join(packets)
    byte_ns = Fraction(10 * 10**9, 921600)
    cuts = sorted(set(rng.integers(1, len(stream), 150).tolist()))
    dec = ImuDecoder(baud=921600)
    out = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)]):
        out += dec.feed(round(1000 + b * byte_ns), stream[a:b])
    assert len(out) == 199
    ends = np.cumsum([len(p) for p in packets])
    for s, e in zip(out, ends):
        assert abs(Fraction(s.t_ns) - (1000 + e * byte_ns)) <= 1
    assert dec.counters["seq_gaps"] == 1


def test_false_header_does_not_hold_back_a_complete_packet():
    good = encode_imu_packet(0, (0, 0, 9.8), (0, 0, 0), 4)
    dec = ImuDecoder(baud=921600)
    # a false header claims 128 bytes; the good packet inside that span is complete, which shows
    # the header is false: the packet comes out at once, with its own chunk's time
    out = dec.feed(5_000_000, b"\xfa\xff\x36\x80" + good)
    assert len(out) == 1 and out[0].t_ns == 5_000_000
    assert dec.counters["reject_overlapped"] == 1


def test_packet_ending_in_a_header_lookalike_waits_then_flush_releases_it():
    # gyro z printed as the float whose bytes are FA FF 36 10: the packet ends with what looks
    # like the start of a 16-byte message, so the decoder waits for those bytes before deciding
    wz = struct.unpack(">f", b"\xfa\xff\x36\x10")[0]
    pkt = encode_imu_packet(0, (0, 0, 9.8), (0, 0, wz), 9)
    dec = ImuDecoder(baud=921600)
    assert dec.feed(1_000, pkt) == []
    out = dec.flush()
    assert len(out) == 1 and out[0].fields["angular_rate_radps_z"] == wz and out[0].t_ns == 1_000
    # the same packet followed by more traffic is decoded without a flush
    dec2 = ImuDecoder(baud=921600)
    nxt = encode_imu_packet(0, (0, 0, 9.8), (0, 0, 0), 10)
    got = dec2.feed(1_000, pkt) + dec2.feed(2_000, nxt)
    assert [s.fields["seq_counter"] for s in got] == [9.0, 10.0]


def test_packet_cut_before_its_checksum_does_not_swallow_the_next():
    # Find a packet whose checksum byte is FA: cut off that byte and the next packet's preamble
    # (FA) completes a message that passes the 8-bit checksum. The next packet must survive.
    for seq in range(10_000):
        cut = encode_imu_packet(0, (0, 0, 9.8), (0, 0, 0), seq)
        if cut[-1] == 0xFA:
            break
    nxt = encode_imu_packet(0, (1, 2, 3), (4, 5, 6), 60000)
    dec = ImuDecoder()
    out = dec.feed(0, cut[:-1] + nxt)
    assert [s.fields["seq_counter"] for s in out] == [60000.0]
    assert dec.counters["reject_overlapped"] == 1


def _corrupt(rng, pkt: bytes) -> bytes:
    op = rng.integers(3)
    if op == 0:  # substitute one byte by a different value: an additive checksum always sees it
        i = int(rng.integers(len(pkt)))
        v = (pkt[i] + int(rng.integers(1, 256))) & 0xFF
        return pkt[:i] + bytes([v]) + pkt[i + 1:]
    if op == 1:  # cut short
        return pkt[:int(rng.integers(1, len(pkt)))]
    return pkt[:4] + rng.bytes(len(pkt) - 4)  # header kept, body replaced


def test_fuzz_garbage_and_corrupted_packets_interleaved(rng):
    # every valid packet is decoded, in order, bit-exact; corrupted ones and garbage give nothing
    n = 2000
    f = rng.uniform(-50, 50, (n, 3)).astype(np.float32)
    w = rng.uniform(-5, 5, (n, 3)).astype(np.float32)
    valid = [encode_imu_packet(k * 1_000_000, f[k], w[k], k) for k in range(n)]
    stream = bytearray()
    n_corrupt = 0
    for k, p in enumerate(valid):
        r = rng.random()
        if r < 0.15:
            stream += rng.bytes(int(rng.integers(1, 120)))
        elif r < 0.25:  # garbage that looks like the start of a message
            stream += b"\xfa\xff\x36" + bytes([int(rng.integers(0, 256))])
            stream += rng.bytes(int(rng.integers(0, 60)))
        elif r < 0.40:
            stream += _corrupt(rng, valid[int(rng.integers(n))])
            n_corrupt += 1
        stream += p
    stream = bytes(stream)
    cuts = np.sort(rng.choice(len(stream), size=len(stream) // 30, replace=False))
    dec = ImuDecoder()
    out = []
    for k, (a, b) in enumerate(zip([0, *cuts], [*cuts, len(stream)])):
        out += dec.feed(k * 10_000, stream[a:b])
    assert [int(s.fields["seq_counter"]) for s in out] == list(range(n))
    assert np.array_equal(np.array([fields_of(s) for s in out]), np.hstack([f, w]).astype(float))
    c = dec.counters
    assert c["samples"] == n and n_corrupt > 200
    assert c["rejected"] > n_corrupt // 2
    assert c["garbage_bytes"] > 0
    # fully random bytes on their own: nothing decoded, nothing raised
    noise = ImuDecoder()
    for _ in range(200):
        assert noise.feed(0, rng.bytes(int(rng.integers(0, 500)))) == []
