"""Tests of codecs.imu_mtdata2 (Xsens MTi MTData2): round trips, a real MTi-300 payload, the
number formats, bandwidth at 1 kHz, axis mapping, and the one-struct fast path against the
general parser.
"""

from __future__ import annotations

import struct
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.bus.samples import FIELDS
from vdps_hil.codecs.framing import BITS_PER_BYTE_8N1
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.imu_mtdata2 import (
    DEFAULT_BAUD, IMU_RATE_HZ, PACKET_BYTES, decode_mtdata2, encode_imu_packet, link_utilisation,
    vnimu_ascii_sentence,
)

from imu_checks import fields_of, xbus


f32 = st.floats(-160.0, 160.0, width=32)
w32 = st.floats(-35.0, 35.0, width=32)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(t_ns=st.integers(0, 10**15), f=st.tuples(f32, f32, f32), w=st.tuples(w32, w32, w32),
       seq=st.integers(0, 10**6))
def test_round_trip_is_exact_in_float32(t_ns, f, w, seq):
    pkt = encode_imu_packet(t_ns, f, w, seq)
    assert len(pkt) == PACKET_BYTES
    dec = ImuDecoder("imu")
    out = dec.feed(t_ns, pkt)
    assert len(out) == 1
    s = out[0]
    assert s.kind == "imu" and s.source == "imu" and s.valid
    assert set(s.fields) <= set(FIELDS)
    assert fields_of(s) == [*f, *w]  # float32 inputs come back bit-exact
    assert s.fields["seq_counter"] == seq % 65536
    # device time in 100 us ticks, to the nearest tick, modulo 2^32
    stf = dec.last_packet.sample_time_fine
    d = (Fraction(stf) - Fraction(t_ns, 100_000)) % 2**32
    assert min(d, 2**32 - d) <= Fraction(1, 2)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(f=st.tuples(*[st.floats(-160.0, 160.0)] * 3), w=st.tuples(*[st.floats(-35.0, 35.0)] * 3))
def test_round_trip_within_float32_quantisation(f, w):
    s = ImuDecoder().feed(0, encode_imu_packet(0, f, w, 1))[0]
    for got, want in zip(fields_of(s), [*f, *w]):
        assert abs(got - want) <= abs(want) * 2.0**-24 + 1e-45  # half an ulp of float32


def test_packet_layout_and_bandwidth_at_1khz():
    # header FA FF 36 LEN, then (XDI 2 + size 1 + payload) for counter, sample time, acc, gyro
    assert PACKET_BYTES == 4 + (3 + 2) + (3 + 4) + (3 + 12) + (3 + 12) + 1 == 47
    u = link_utilisation(PACKET_BYTES, IMU_RATE_HZ, DEFAULT_BAUD)
    assert u == pytest.approx(47 * BITS_PER_BYTE_8N1 * 1000 / 921600)
    assert 0.5 < u < 0.52  # fits 921600 baud with room for the other traffic
    assert link_utilisation(PACKET_BYTES, IMU_RATE_HZ, 115200) > 4.0  # why 921600 is needed
    vn = vnimu_ascii_sentence((-2.0841, 0.6045, 2.8911), (0.381, -0.154, -9.657),
                              (-0.005683, 0.002103, 0.000216), 21.6, 99.761)
    assert vn.startswith(b"$VNIMU,") and vn.endswith(b"\r\n") and len(vn) == 110
    assert link_utilisation(len(vn), 1000, 921600) > 1.15  # ASCII $VNIMU does not fit


# A real MTData2 payload from an Xsens MTi-300 (firmware 1.8.2), as captured from the device with
# Xsens MT Manager, and the values MT Manager printed for it (public capture, "packet example 3").
MTI300_PAYLOAD = bytes.fromhex(
    "10200 28D90 10600 40054DBF1 2010103F7F8911BC111DFA3BA0CEF0BD732573"
    " 40200CBDDCF9D0BE3C8619411D0B47 40100CB98DB000B9F148003CC90430"
    " 40300CBCB9892EBB098C003CA70800 80200CBA63BC01BC04D63FBB6DE3FE"
    " 8030103F800001B591C000B72A0800B6984000 E0200400400003".replace(" ", ""))


MTI300_DECODED = {"counter": 36240, "stf": 5561329,
                  "acc": (-0.10789835, -0.18410529, 9.81525326),
                  "gyr": (-0.00086874, -0.00810772, -0.00362992)}


def test_real_mti300_payload_decodes_to_mt_manager_values():
    pkt = decode_mtdata2(MTI300_PAYLOAD)
    assert pkt.packet_counter == MTI300_DECODED["counter"]
    assert pkt.sample_time_fine == MTI300_DECODED["stf"]
    assert pkt.specific_force_mps2 == pytest.approx(MTI300_DECODED["acc"], abs=5e-9)
    assert pkt.angular_rate_radps == pytest.approx(MTI300_DECODED["gyr"], abs=5e-9)
    # the same payload as a whole message through the streaming decoder; the quaternion,
    # delta-v, free acceleration, delta-q and status items are skipped
    dec = ImuDecoder()
    out = dec.feed(7, b"\x00\x13" + xbus(0x36, MTI300_PAYLOAD))
    assert len(out) == 1 and out[0].fields["seq_counter"] == 36240
    # at rest and level the accelerometer reads about +g on z: specific force, z up
    assert out[0].fields["specific_force_mps2_z"] == pytest.approx(9.81, abs=0.02)


def test_float64_and_fixed_point_formats():
    acc, gyr = (1.5, -2.25, 9.75), (0.125, -0.5, 0.0625)
    data = (struct.pack(">HBH", 0x1020, 2, 9) + struct.pack(">HB3d", 0x4023, 24, *acc)
            + struct.pack(">HB3i", 0x8021, 12, *[int(v * 2**20) for v in gyr]))
    s = ImuDecoder().feed(0, xbus(0x36, data))[0]
    assert fields_of(s) == [*acc, *gyr]


def test_axis_mapping_at_the_boundary():
    f, w = (1.0, 2.0, 9.0), (0.1, 0.2, 0.3)
    upside_down = ((1, 0, 0), (0, -1, 0), (0, 0, -1))  # casing x forward, z down
    pkt = encode_imu_packet(0, f, w, 3, sensor_to_body=upside_down)
    raw = ImuDecoder().feed(0, pkt)[0]  # decoded as if mounted upright: the sensor-frame values
    assert fields_of(raw) == pytest.approx([1.0, -2.0, -9.0, 0.1, -0.2, -0.3])
    body = ImuDecoder(sensor_to_body=upside_down).feed(0, pkt)[0]
    assert fields_of(body) == pytest.approx([*f, *w])
    for bad in (((1, 0, 0), (0, 1, 0), (0, 0, -1)),   # a reflection
                ((1, 0, 0), (1, 0, 0), (0, 0, 1)),    # not a permutation
                ((0.5, 0, 0), (0, 1, 0), (0, 0, 1))):
        with pytest.raises(ValueError):
            ImuDecoder(sensor_to_body=bad)


@settings(max_examples=300, deadline=None)
@given(raw=st.binary(min_size=24, max_size=24), seq=st.integers(0, 0xFFFF), stf=st.integers(0, 0xFFFFFFFF),
       rot=st.sampled_from([((1, 0, 0), (0, 1, 0), (0, 0, 1)), ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
                            ((-1, 0, 0), (0, -1, 0), (0, 0, 1))]))
def test_standard_layout_fast_path_equals_the_general_parser(raw, seq, stf, rot):
    """decode_mtdata2 reads the standard 4-XDI layout with one struct call; the same items
    followed by an (ignored) unknown zero-length XDI go through the general loop: same packet,
    same rejects, for any float32 bit patterns (NaN, inf, -0.0, subnormals)."""
    from vdps_hil.codecs.imu_mtdata2 import decode_mtdata2

    data = (struct.pack(">HBH", 0x1020, 2, seq) + struct.pack(">HBI", 0x1060, 4, stf)
            + struct.pack(">HB", 0x4020, 12) + raw[:12] + struct.pack(">HB", 0x8020, 12) + raw[12:])
    results = []
    for d in (data, data + struct.pack(">HB", 0x7F00, 0)):
        try:
            results.append(decode_mtdata2(d, rot))
        except Exception as e:  # noqa: BLE001 - the codec's reject exception (ImuDecoder counts it)
            results.append(("rejected", type(e).__name__, getattr(e, "reason", None)))
    assert repr(results[0]) == repr(results[1])
