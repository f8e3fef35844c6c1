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


def _counters(steps, bits):
    c, t, cs, ts = 0, 0, [], []
    for dc, dt in steps:
        c, t = c + dc, t + dt * 100_000
        cs.append(c % (1 << bits))
        ts.append(t)
    return cs, ts


def _check_many_against_check(cs, ts, cuts, bits, protected):
    from vdps_hil.codecs.can_e2e import SequenceState

    one, many = SequenceState(), SequenceState()
    ca = {"lost_frames": 0}
    cb = {"lost_frames": 0}
    ref = [one.check(x, y, 1 << bits, protected, 3, ca) for x, y in zip(cs, ts)]
    got, k = [], 0
    for cut in sorted(cuts) + [len(cs)]:
        got += many.check_many(cs[k:max(cut, k)], ts[k:max(cut, k)], 1 << bits, protected, 3, cb)
        k = max(cut, k)
    assert got == ref and ca == cb and list(ca) == list(cb)
    assert (one.last, one.t_ns, one.pending) == (many.last, many.t_ns, many.pending)
    assert (one.period_ns is None and many.period_ns is None) or one.period_ns.hex() == many.period_ns.hex()


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 40), st.sampled_from([0, 1, 1, 1, 2, 50, 400, 3000])), max_size=80),
       st.lists(st.integers(0, 80), max_size=3), st.sampled_from([4, 8]), st.booleans())
def test_check_many_equals_check_frame_by_frame(steps, cuts, bits, protected):
    """``SequenceState.check_many`` (the bulk decoder's loop) against ``check`` per counter:
    the same reasons, counts (lost frames, stall gaps) and state, across splits into calls;
    steps of repeats, jumps, wraps, long silences and bursts."""
    _check_many_against_check(*_counters(steps, bits), cuts, bits, protected)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([1, 1, 1, 1, 1, 1, 1, 0, 2]),
                          st.sampled_from([10, 10, 10, 9, 11, 12, 8, 3, 39, 41, 80, 170, 0])), max_size=300),
       st.lists(st.integers(0, 300), max_size=6), st.sampled_from([4, 8]))
def test_check_many_paced_runs_equal_check(steps, cuts, bits):
    """Mostly paced streams (counter +1, a jittered period, now and then a repeat, a loss, a
    burst or a gap near the 4-period and half-cycle limits) in many calls: the whole-run
    shortcut of check_many is taken and leaves the same state as check frame by frame."""
    _check_many_against_check(*_counters(steps, bits), cuts, bits, False)


def test_check_many_takes_the_paced_shortcut():
    from vdps_hil.codecs.can_e2e import SequenceState

    s = SequenceState()
    s.check_many([0, 1, 2], [0, 10, 20], 16, False, 3, {"lost_frames": 0})
    assert s._paced([3, 4, 5], [31, 40, 50], 16) and s.last == 5 and s.t_ns == 50
    assert not s._paced([7], [60], 16) and not s._paced([6], [50], 16) and not s._paced([6], [200], 16)
