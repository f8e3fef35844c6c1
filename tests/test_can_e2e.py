"""Tests of vdps_hil.codecs.can_e2e: CRC-8/SAE-J1850 (published check value, the table against
the bit-by-bit definition), the VDPS_Warning CRC and counter rules, and the sensor frames'
rolling counters (lost frames across wraps, repeats).
"""

from __future__ import annotations

import itertools

from hypothesis import given, settings, strategies as st

from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_e2e import crc8_j1850
from vdps_hil.codecs.can_encode import encode_steer, encode_suspension, encode_warning

from can_checks import crc8_bitwise


# ---------------------------------------------------------------------------------------------
# CRC-8/SAE-J1850
# ---------------------------------------------------------------------------------------------
def test_crc8_check_value_published():
    # CRC-8/SAE-J1850 check value over ASCII "123456789" (reveng catalogue, AUTOSAR SWS CRC)
    assert crc8_j1850(b"123456789") == 0x4B
    assert crc8_bitwise(b"123456789") == 0x4B


@given(st.binary(max_size=16))
def test_crc8_table_equals_bitwise_definition(data):
    assert crc8_j1850(data) == crc8_bitwise(data)


# ---------------------------------------------------------------------------------------------
# VDPS_Warning: CRC and counter enforced
# ---------------------------------------------------------------------------------------------
def test_warning_every_single_and_double_bit_flip_is_rejected_and_counted():
    dec = VdpsCanDecoder()
    good0 = encode_warning(1, 2.5, 0.2, 0.6, 0, 0)
    assert len(dec.decode(0, 0x080, bytes(good0.data))) == 1
    good1 = bytes(encode_warning(2, 1.25, 0.3, 0.8, 0, 1).data)
    n = 0
    for k in (1, 2):
        for bits in itertools.combinations(range(64), k):
            bad = bytearray(good1)
            for b in bits:
                bad[b // 8] ^= 1 << (b % 8)
            assert dec.decode(n + 1, 0x080, bytes(bad)) == []
            n += 1
    c = dec.counters["VDPS_Warning"]
    assert c["crc_mismatch"] == n == 64 + 2016 and c["accepted"] == 1
    # the corrupted frames did not disturb the sequence: the intact frame 1 is accepted
    out = dec.decode(10**9, 0x080, good1)
    assert len(out) == 1 and out[0].fields["warning_counter"] == 1
    assert dec.counters["VDPS_Warning"]["lost_frames"] == 0


@settings(max_examples=200, deadline=None)
@given(level=st.integers(0, 3), status=st.integers(0, 3), ctr=st.integers(0, 15),
       ttr=st.floats(0, 60), roll=st.floats(-3, 3), ltr=st.floats(-1, 1),
       bit=st.integers(0, 63))
def test_warning_random_bit_flip_never_decoded(level, status, ctr, ttr, roll, ltr, bit):
    data = bytearray(encode_warning(level, ttr, roll, ltr, status, ctr).data)
    data[bit // 8] ^= 1 << (bit % 8)
    dec = VdpsCanDecoder()
    assert dec.decode(0, 0x080, bytes(data)) == []
    assert dec.counters["VDPS_Warning"]["crc_mismatch"] == 1
    assert dec.total_rejected == 1


def test_warning_counter_rules():
    dec = VdpsCanDecoder()

    def send(ctr):
        return dec.decode(0, 0x080, bytes(encode_warning(0, None, 0.0, 0.0, 0, ctr).data))

    assert len(send(14)) == 1
    assert len(send(15)) == 1
    assert len(send(0)) == 1          # wrap 15 -> 0
    assert send(0) == []              # repeated: stale or duplicated frame
    assert len(send(3)) == 1          # delta 3: two frames lost, accepted
    assert send(8) == []              # delta 5 > 3: rejected, resynchronised
    assert len(send(9)) == 1          # next in sequence accepted again
    c = dec.counters["VDPS_Warning"]
    assert (c["accepted"], c["counter_repeat"], c["counter_jump"]) == (5, 1, 1)
    assert c["lost_frames"] == 2 + 4


# ---------------------------------------------------------------------------------------------
# sensor frames: counters, lost frames
# ---------------------------------------------------------------------------------------------
def test_sensor_lost_frames_counted_including_wraps():
    dec = VdpsCanDecoder()
    period = 1_000_000  # 1 kHz
    sent = list(range(0, 50)) + list(range(53, 400)) + list(range(1400, 1450))  # 3 + 1000 lost
    for k in sent:
        m = encode_steer(0.01 * (k % 100), k)
        assert len(dec.decode(k * period, m.arbitration_id, bytes(m.data))) == 1
    c = dec.counters["VDPS_SteerAngle"]
    assert c["accepted"] == len(sent) and c["lost_frames"] == 3 + 1000


def test_sensor_repeat_rejected_and_counted():
    dec = VdpsCanDecoder()
    m = encode_suspension([0.01, 0.02, -0.03, 0.0], 5)
    assert len(dec.decode(0, m.arbitration_id, bytes(m.data))) == 1
    assert dec.decode(1000, m.arbitration_id, bytes(m.data)) == []
    assert dec.counters["VDPS_Suspension"]["counter_repeat"] == 1


def test_a_stalled_reader_is_not_a_loss_of_whole_counter_cycles():
    """A reader that stalls 0.5 s and then reads the backlog in one burst stamps the burst with
    one receive time: a long gap (500 periods at 1 kHz, ~2 counter cycles) with counter +1,
    then frames 0 ns apart. Nothing was lost; a real silence followed by paced frames is."""
    dec = VdpsCanDecoder()
    period = 1_000_000
    t, k = 0, 0
    for _ in range(300):  # paced: the period is learned
        m = encode_steer(0.0, k % 256)
        dec.decode(t, m.arbitration_id, bytes(m.data))
        t, k = t + period, k + 1
    t += 500 * period  # the stall: the backlog of 500 frames arrives at once
    for _ in range(500):
        m = encode_steer(0.0, k % 256)
        assert len(dec.decode(t, m.arbitration_id, bytes(m.data))) == 1
        k += 1
    for _ in range(50):  # paced again
        t += period
        m = encode_steer(0.0, k % 256)
        dec.decode(t, m.arbitration_id, bytes(m.data))
        k += 1
    c = dec.counters["VDPS_SteerAngle"]
    assert c["lost_frames"] == 0 and c["stall_gaps"] == 1
    assert c["accepted"] == 850
