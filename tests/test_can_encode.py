"""Tests of vdps_hil.codecs.can_encode: round trips of every signal over its range, clamping
and ``quantize`` (exactly decode(encode(x))), NaN refused, and the encoded bytes read by
cantools and by an independent bit-level unpacker (tests/can_checks.py).
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from vdps_hil.bus.samples import FIELDS
from vdps_hil.codecs.can_dbc import load_dbc
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_encode import (
    encode_fields, encode_steer, encode_warning, encode_wheel_speed_front, quantize,
)

from can_checks import FP_EPS, KINDS, LAYOUT, crc8_bitwise, e2e_crc_bitwise, unpack_independent, value_fields


# ---------------------------------------------------------------------------------------------
# round trips of every signal over its range
# ---------------------------------------------------------------------------------------------
def _value_strategy(name, sig):
    start, length, signed, scale, lo, hi, unit = LAYOUT[name][3][sig]
    if sig in ("warning_level", "warning_status"):
        return st.integers(0, 3)
    if sig == "warning_time_to_rollover_s":
        return st.one_of(st.floats(0.0, 65.534), st.just(math.inf), st.none())
    return st.floats(lo, hi, allow_nan=False)


def _message_strategy(name):
    sigs = value_fields(name)
    return st.tuples(st.fixed_dictionaries({s: _value_strategy(name, s) for s in sigs}),
                     st.integers(0, 10**6))


@pytest.mark.parametrize("name", sorted(LAYOUT))
def test_round_trip_every_signal_over_its_range(name):
    @settings(max_examples=150, deadline=None)
    @given(_message_strategy(name), st.integers(0, 2**62))
    def check(args, t_ns):
        fields, counter = args
        msg = encode_fields(name, fields, counter, t_ns=t_ns)
        assert msg.arbitration_id == LAYOUT[name][0] and not msg.is_extended_id
        assert msg.dlc == len(msg.data) == LAYOUT[name][1]
        assert msg.timestamp == pytest.approx(t_ns / 1e9, rel=1e-15)
        s = _decode_alone(name, bytes(msg.data), t_ns)
        assert s.t_ns == t_ns and s.kind == KINDS[name]
        assert s.valid == (fields.get("warning_status", 0) == 0)
        ctr_name = "warning_counter" if name == "VDPS_Warning" else "seq_counter"
        if name != "VDPS_WheelTorqueFront":  # a torque sample carries the rear frame's counter
            assert s.fields[ctr_name] == counter % 16
        for f, x in fields.items():
            scale = LAYOUT[name][3][f][3]
            got = s.fields[f]
            if f == "warning_time_to_rollover_s" and (x is None or math.isinf(x)):
                assert got == math.inf
            else:
                assert abs(got - x) <= scale / 2 + FP_EPS * max(1.0, abs(x))
            assert got == quantize(f, x)  # quantize is exactly decode(encode(x))
    check()


@pytest.mark.parametrize("field", sorted(f for f in FIELDS if f in load_dbc().field_signal
                                         and not f.startswith("warning_")))
@settings(max_examples=60, deadline=None)
@given(x=st.one_of(st.floats(allow_nan=False), st.floats(-1e3, 1e3)))
def test_sensor_values_clamped_outside_range_and_quantize_matches(field, x):
    spec, sig = load_dbc().field_signal[field]
    fields = {f: 0.0 for f in spec.field_names}
    fields[field] = x
    msg = encode_fields(spec.name, fields, 0)
    got = _decode_alone(spec.name, bytes(msg.data)).fields[field]
    lo, hi = sig.raw_min * sig.scale, sig.raw_max * sig.scale
    if x <= sig.minimum:
        assert got == pytest.approx(lo, abs=1e-12)
    elif x >= sig.maximum:
        assert got == pytest.approx(hi, abs=1e-12)
    else:
        assert abs(got - x) <= sig.scale / 2 + FP_EPS * max(1.0, abs(x))
    assert quantize(field, x) == got
    assert quantize(field, np.array([x, x]))[1] == got  # array path, same arithmetic


def test_nan_is_refused_by_encoders_and_quantize():
    with pytest.raises(ValueError):
        encode_steer(math.nan, 0)
    with pytest.raises(ValueError):
        quantize("wheel_speed_radps_1", np.array([1.0, math.nan]))
    with pytest.raises(ValueError):
        encode_warning(4, None, 0.0, 0.0, 0, 0)
    with pytest.raises(ValueError):
        encode_warning(1, -0.5, 0.0, 0.0, 0, 0)
    with pytest.raises(KeyError):
        quantize("gnss_lat_deg", 1.0)


def test_warning_out_of_range_inputs_clamped_as_documented():
    m = encode_warning(3, 100.0, 4.0, -2.0, 2, 17)
    s = VdpsCanDecoder().decode(0, m.arbitration_id, bytes(m.data))[0]
    assert s.fields["warning_time_to_rollover_s"] == math.inf  # beyond 65.534 s: none
    assert s.fields["warning_peak_roll_rad"] == pytest.approx(3.1416, abs=1e-12)
    assert s.fields["warning_ltr"] == pytest.approx(-1.0, abs=1e-12)
    assert s.fields["warning_counter"] == 1 and s.fields["warning_level"] == 3
    assert s.valid is False  # status 2 (sensor missing)


# ---------------------------------------------------------------------------------------------
# independent parse: cantools' own decode_message and the bit-level unpacker agree
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(LAYOUT))
def test_independent_parsers_agree(name, rng):
    dbc = load_dbc()
    fid, dlc, _, sigs = LAYOUT[name]
    for k in range(200):
        fields = {}
        for f in value_fields(name):
            start, length, signed, scale, lo, hi, unit = sigs[f]
            fields[f] = int(rng.integers(0, 4)) if f in ("warning_level", "warning_status") \
                else float(rng.uniform(lo, hi))
        msg = encode_fields(name, fields, k)
        data = bytes(msg.data)
        raw = unpack_independent(name, data)
        by_cantools = dbc.db.decode_message(fid, data, decode_choices=False, scaling=False)
        assert by_cantools == raw
        sample = _decode_alone(name, data)
        for f in value_fields(name):
            phys = raw[f] * sigs[f][3]
            if f == "warning_time_to_rollover_s" and raw[f] == 65535:
                phys = math.inf
            assert sample.fields[f] == pytest.approx(phys, rel=1e-12, abs=1e-15)
        if name == "VDPS_Warning":
            assert raw["warning_crc"] == crc8_bitwise(data[1:])
        else:
            assert raw["e2e_crc"] == e2e_crc_bitwise(fid, data)


def _decode_alone(name, data, t_ns=0):
    """The decoded sample of one frame (exactly one); a torque frame with its partner of the
    same instant (zeros) so that the decoder emits the group's sample."""
    dec = VdpsCanDecoder()
    fid = LAYOUT[name][0]
    if name == "VDPS_WheelTorqueFront":
        assert dec.decode(t_ns, fid, data) == []
        out = dec.decode(t_ns, 0x121, bytes(encode_fields("VDPS_WheelTorqueRear", {
            "wheel_torque_nm_3": 0.0, "wheel_torque_nm_4": 0.0}, 0).data))
    else:
        if name == "VDPS_WheelTorqueRear":
            assert dec.decode(t_ns, 0x120, bytes(encode_fields("VDPS_WheelTorqueFront", {
                "wheel_torque_nm_1": 0.0, "wheel_torque_nm_2": 0.0}, 0).data)) == []
        out = dec.decode(t_ns, fid, data)
    assert len(out) == 1, dec.counters[name]
    return out[0]


def test_struct_view_of_two_frames():
    # wheel speeds: E2E CRC u8, 4-bit counter in a u8, two little-endian int16 at 0.01 rad/s
    m = encode_wheel_speed_front(83.33, -1.5, 300)
    crc, cnt, w1, w2 = struct.unpack("<BBhh", bytes(m.data))
    assert (cnt, w1, w2) == (300 % 16, 8333, -150)
    assert crc == crc8_bitwise(bytes((0x00, 0x01)) + bytes(m.data)[1:])  # data ID 0x0100
    # warning: crc u8, counter|level<<4|status<<6 u8, ttr u16 (ms), roll i16, ltr i16 (1e-4)
    w = encode_warning(level=2, time_to_rollover_s=0.75, peak_roll_rad=-0.25, ltr=0.9,
                       status=1, counter=9)
    crc, b1, ttr, roll, ltr = struct.unpack("<BBHhh", bytes(w.data))
    assert (b1 & 0xF, (b1 >> 4) & 3, b1 >> 6) == (9, 2, 1)
    assert (ttr, roll, ltr) == (750, -2500, 9000)
    assert crc == crc8_bitwise(bytes(w.data)[1:])
    steer = bytes(encode_steer(1.234, 7).data)
    assert struct.pack("<Bh", 7, 1234) == steer[1:] and steer[0] == crc8_bitwise(b"\x30\x01" + steer[1:])


# ---------------------------------------------------------------------------------------------
# the compiled packing against cantools' encoder
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(LAYOUT))
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_packed_payload_is_cantools_encoding_byte_for_byte(name, data):
    """pack_fields (compiled layout, no cantools) writes what cantools' Message.encode writes
    for the same raw values, on every message with values over the whole range, clamped ones
    and a wrapping counter; the CRC then covers the same bytes."""
    from vdps_hil.codecs import can_encode as ce
    from vdps_hil.codecs.can_e2e import e2e_crc

    fields, counter = data.draw(_message_strategy(name))
    dbc = load_dbc()
    spec = dbc.messages[name]
    raw = {sig.name: ce._to_raw(sig, fields[sig.name]) for sig in spec.values}
    raw[spec.counter.name] = counter % (1 << spec.counter.length_bits)
    if spec.crc is not None:
        raw[spec.crc.name] = 0
    ref = bytearray(dbc.db.get_message_by_name(name).encode(raw, scaling=False, strict=True))
    if spec.crc is not None:
        ref[0] = e2e_crc(ref, spec.data_id)
    assert ce.pack_fields(name, fields, counter, dbc=dbc) == bytes(ref)
    assert ce._compiled(spec.message) is not None  # the project's DBC takes the compiled path


def test_a_value_outside_the_range_or_a_missing_signal_goes_to_cantools_and_its_error():
    """What the compiled path cannot decide (a raw value out of the DBC range, which only a
    value table could allow; a signal missing) is left to cantools' strict encoder: its error."""
    import cantools

    from vdps_hil.codecs import can_encode as ce

    spec = load_dbc().messages["VDPS_SteerAngle"]
    raw = {s.name: 0 for s in (*spec.values, spec.counter)} | {spec.crc.name: 0}
    assert ce._pack(spec.message, raw) == bytes(spec.dlc)
    with pytest.raises(cantools.database.EncodeError):
        ce._pack(spec.message, raw | {spec.values[0].name: spec.values[0].raw_max + 10})
    with pytest.raises(cantools.database.EncodeError):
        ce._pack(spec.message, {k: v for k, v in raw.items() if k != spec.counter.name})
    # a range wider than the bit field (a DBC VdpsDbc refuses): in range, cantools' own error
    from cantools.database.can import Message, Signal

    narrow = Message(1, "M", 1, [Signal("s", 0, 4, "little_endian", False, minimum=0, maximum=100)], strict=False)
    assert ce._pack(narrow, {"s": 7}) == b"\x07"
    with pytest.raises(OverflowError):
        ce._pack(narrow, {"s": 20})


def test_warning_frames_carry_python_can_attributes_and_convert():
    from vdps_hil.codecs.can_encode import warning_frame

    f = warning_frame(2, 1.25, 0.3, 0.8, 0, 5, t_ns=1_500_000_000)
    m = encode_warning(2, 1.25, 0.3, 0.8, 0, 5, t_ns=1_500_000_000)
    assert (f.timestamp, f.arbitration_id, f.dlc, f.data, f.is_extended_id) == \
        (m.timestamp, m.arbitration_id, m.dlc, bytes(m.data), m.is_extended_id)
    assert not (f.is_fd or f.is_remote_frame or f.is_error_frame)
    assert f.to_message().equals(m)
    got = VdpsCanDecoder().decode_message(f, t_ns=0)
    assert got[0].fields["warning_level"] == 2 and got[0].fields["warning_time_to_rollover_s"] == 1.25
