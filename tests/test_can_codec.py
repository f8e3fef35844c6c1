"""Tests of vdps_hil.codecs.can_codec and dbc/vdps.dbc.

The layout the module docstring claims is written out again below (LAYOUT) and checked three
ways: against cantools' reading of the DBC, against an independent bit-level unpacker written
here (int.from_bytes / struct), and through the codec's own encoders and decoder.
"""

from __future__ import annotations

import itertools
import math
import struct

import can
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from vdps_hil.bus.samples import FIELDS, Sample
from vdps_hil.codecs import can_codec as cc

# name: (id, dlc, cycle ms, {signal: (start, length, signed, scale, minimum, maximum, unit)})
LAYOUT = {
    "VDPS_Warning": (0x080, 8, 20, {
        "warning_crc": (0, 8, False, 1, 0, 255, ""),
        "warning_counter": (8, 4, False, 1, 0, 15, ""),
        "warning_level": (12, 2, False, 1, 0, 3, ""),
        "warning_status": (14, 2, False, 1, 0, 3, ""),
        "warning_time_to_rollover_s": (16, 16, False, 0.001, 0, 65.535, "s"),
        "warning_peak_roll_rad": (32, 16, True, 0.0001, -3.1416, 3.1416, "rad"),
        "warning_ltr": (48, 16, True, 0.0001, -1, 1, ""),
    }),
    "VDPS_WheelSpeedFront": (0x100, 5, 1, {
        "wheel_speed_radps_1": (0, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "wheel_speed_radps_2": (16, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "seq_counter": (32, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_WheelSpeedRear": (0x101, 5, 1, {
        "wheel_speed_radps_3": (0, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "wheel_speed_radps_4": (16, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "seq_counter": (32, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_Suspension": (0x110, 8, 1, {
        **{f"susp_deflection_m_{i + 1}": (14 * i, 14, True, 2e-5, -0.16384, 0.16382, "m")
           for i in range(4)},
        "seq_counter": (56, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_WheelTorque": (0x120, 8, 10, {
        **{f"wheel_torque_nm_{i + 1}": (14 * i, 14, True, 1, -8192, 8191, "N m") for i in range(4)},
        "seq_counter": (56, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_SteerAngle": (0x130, 3, 10, {
        "steer_wheel_angle_rad": (0, 16, True, 0.001, -12.567, 12.567, "rad"),
        "seq_counter": (16, 8, False, 1, 0, 255, ""),
    }),
}
KINDS = {"VDPS_Warning": "warning", "VDPS_WheelSpeedFront": "wheel_speed",
         "VDPS_WheelSpeedRear": "wheel_speed", "VDPS_Suspension": "suspension",
         "VDPS_WheelTorque": "wheel_torque", "VDPS_SteerAngle": "steer"}
COUNTER_NAMES = ("seq_counter", "warning_counter")
FP_EPS = 1e-9  # floating-point slack on top of half a resolution step


def unpack_independent(name: str, data: bytes) -> dict[str, int]:
    """Raw integers of every signal by plain bit arithmetic on the little-endian payload."""
    v = int.from_bytes(data, "little")
    out = {}
    for sig, (start, length, signed, *_rest) in LAYOUT[name][3].items():
        raw = (v >> start) & ((1 << length) - 1)
        if signed and raw >= 1 << (length - 1):
            raw -= 1 << length
        out[sig] = raw
    return out


def crc8_bitwise(data: bytes) -> int:
    """CRC-8/SAE-J1850 written bit by bit from its definition (independent of the table)."""
    reg = 0xFF
    for byte in data:
        for i in range(7, -1, -1):
            top = ((reg >> 7) & 1) ^ ((byte >> i) & 1)
            reg = (reg << 1) & 0xFF
            if top:
                reg ^= 0x1D
    return reg ^ 0xFF


def value_fields(name):
    return [s for s in LAYOUT[name][3] if s not in COUNTER_NAMES and s != "warning_crc"]


# ---------------------------------------------------------------------------------------------
# the DBC says what the docstring says
# ---------------------------------------------------------------------------------------------
def test_dbc_layout_matches_claimed_table():
    dbc = cc.load_dbc()
    assert set(dbc.messages) == set(LAYOUT)
    for name, (fid, dlc, cycle_ms, sigs) in LAYOUT.items():
        m = dbc.db.get_message_by_name(name)
        assert (m.frame_id, m.length, m.cycle_time, m.is_extended_frame) == (fid, dlc, cycle_ms, False)
        assert dbc.messages[name].kind == KINDS[name]
        assert m.comment, f"{name} has no CM_"
        assert {s.name for s in m.signals} == set(sigs)
        for s in m.signals:
            start, length, signed, scale, lo, hi, unit = sigs[s.name]
            assert (s.start, s.length, s.is_signed, s.byte_order) == (start, length, signed, "little_endian")
            assert s.scale == pytest.approx(scale, rel=1e-12) and s.offset == 0
            assert (s.minimum, s.maximum) == pytest.approx((lo, hi), rel=1e-12)
            assert (s.unit or "") == unit
            assert s.comment, f"{name}.{s.name} has no CM_"
            if s.name not in COUNTER_NAMES and s.name != "warning_crc":
                assert s.name in FIELDS
    assert dbc.bitrate_bps == 1_000_000


def test_dbc_meets_the_requirements_of_the_issue():
    dbc = cc.load_dbc()
    sig = {f: s for f, (_, s) in dbc.field_signal.items()}
    for i in range(1, 5):
        w = sig[f"wheel_speed_radps_{i}"]
        assert w.resolution < math.radians(2.0) and w.minimum <= -200 and w.maximum >= 200
        t = sig[f"wheel_torque_nm_{i}"]
        assert t.resolution <= 1.0 and t.minimum <= -5000 and t.maximum >= 5000
        h = sig[f"susp_deflection_m_{i}"]
        assert h.resolution <= 1e-4 and h.minimum <= -0.15 and h.maximum >= 0.15
    s = sig["steer_wheel_angle_rad"]
    assert s.resolution <= 1e-3 and s.minimum <= -4 * math.pi and s.maximum >= 4 * math.pi
    warning_id = dbc.messages["VDPS_Warning"].frame_id
    assert all(warning_id < m.frame_id for n, m in dbc.messages.items() if n != "VDPS_Warning")
    # every sensor frame has an 8-bit counter, the warning a 4-bit counter and a CRC at byte 0
    for name, spec in dbc.messages.items():
        assert spec.counter.length_bits == (4 if name == "VDPS_Warning" else 8)
    assert dbc.messages["VDPS_Warning"].crc.start_bit == 0


def test_bad_dbc_gives_one_line_error(tmp_path):
    p = tmp_path / "bad.dbc"
    p.write_text("this is not a dbc\n")
    with pytest.raises(cc.DbcError) as e:
        cc.VdpsDbc(p)
    assert "\n" not in str(e.value) and "bad.dbc" in str(e.value)
    text = cc.DEFAULT_DBC_PATH.read_text().replace("wheel_speed_radps_1", "wheel_rpm_1")
    p.write_text(text)
    with pytest.raises(cc.DbcError, match="wheel_rpm_1: not a bus field"):
        cc.VdpsDbc(p)


# ---------------------------------------------------------------------------------------------
# CRCs
# ---------------------------------------------------------------------------------------------
def test_crc8_check_value_published():
    # CRC-8/SAE-J1850 check value over ASCII "123456789" (reveng catalogue, AUTOSAR SWS CRC)
    assert cc.crc8_j1850(b"123456789") == 0x4B
    assert crc8_bitwise(b"123456789") == 0x4B


@given(st.binary(max_size=16))
def test_crc8_table_equals_bitwise_definition(data):
    assert cc.crc8_j1850(data) == crc8_bitwise(data)


def test_can_crc15_check_value_published():
    # CRC-15/CAN check value over ASCII "123456789" is 0x059E (reveng catalogue)
    bits = [(b >> (7 - i)) & 1 for b in b"123456789" for i in range(8)]
    assert cc._can_crc15(bits) == 0x059E


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
        msg = cc.encode_fields(name, fields, counter, t_ns=t_ns)
        assert msg.arbitration_id == LAYOUT[name][0] and not msg.is_extended_id
        assert msg.dlc == len(msg.data) == LAYOUT[name][1]
        assert msg.timestamp == pytest.approx(t_ns / 1e9, rel=1e-15)
        dec = cc.VdpsCanDecoder()
        out = dec.decode(t_ns, msg.arbitration_id, bytes(msg.data))
        assert len(out) == 1, dec.counters[name]
        s = out[0]
        assert s.t_ns == t_ns and s.kind == KINDS[name]
        assert s.valid == (fields.get("warning_status", 0) == 0)
        ctr_name = "warning_counter" if name == "VDPS_Warning" else "seq_counter"
        assert s.fields[ctr_name] == counter % (16 if name == "VDPS_Warning" else 256)
        for f, x in fields.items():
            scale = LAYOUT[name][3][f][3]
            got = s.fields[f]
            if f == "warning_time_to_rollover_s" and (x is None or math.isinf(x)):
                assert got == math.inf
            else:
                assert abs(got - x) <= scale / 2 + FP_EPS * max(1.0, abs(x))
            assert got == cc.quantize(f, x)  # quantize is exactly decode(encode(x))
    check()


@pytest.mark.parametrize("field", sorted(f for f in FIELDS if f in cc.load_dbc().field_signal
                                         and not f.startswith("warning_")))
@settings(max_examples=60, deadline=None)
@given(x=st.one_of(st.floats(allow_nan=False), st.floats(-1e3, 1e3)))
def test_sensor_values_clamped_outside_range_and_quantize_matches(field, x):
    spec, sig = cc.load_dbc().field_signal[field]
    fields = {f: 0.0 for f in spec.field_names}
    fields[field] = x
    msg = cc.encode_fields(spec.name, fields, 0)
    got = cc.VdpsCanDecoder().decode(0, msg.arbitration_id, bytes(msg.data))[0].fields[field]
    lo, hi = sig.raw_min * sig.scale, sig.raw_max * sig.scale
    if x <= sig.minimum:
        assert got == pytest.approx(lo, abs=1e-12)
    elif x >= sig.maximum:
        assert got == pytest.approx(hi, abs=1e-12)
    else:
        assert abs(got - x) <= sig.scale / 2 + FP_EPS * max(1.0, abs(x))
    assert cc.quantize(field, x) == got
    assert cc.quantize(field, np.array([x, x]))[1] == got  # array path, same arithmetic


def test_nan_is_refused_by_encoders_and_quantize():
    with pytest.raises(ValueError):
        cc.encode_steer(math.nan, 0)
    with pytest.raises(ValueError):
        cc.quantize("wheel_speed_radps_1", np.array([1.0, math.nan]))
    with pytest.raises(ValueError):
        cc.encode_warning(4, None, 0.0, 0.0, 0, 0)
    with pytest.raises(ValueError):
        cc.encode_warning(1, -0.5, 0.0, 0.0, 0, 0)
    with pytest.raises(KeyError):
        cc.quantize("gnss_lat_deg", 1.0)


def test_warning_out_of_range_inputs_clamped_as_documented():
    m = cc.encode_warning(3, 100.0, 4.0, -2.0, 2, 17)
    s = cc.VdpsCanDecoder().decode(0, m.arbitration_id, bytes(m.data))[0]
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
    dbc = cc.load_dbc()
    fid, dlc, _, sigs = LAYOUT[name]
    for k in range(200):
        fields = {}
        for f in value_fields(name):
            start, length, signed, scale, lo, hi, unit = sigs[f]
            fields[f] = int(rng.integers(0, 4)) if f in ("warning_level", "warning_status") \
                else float(rng.uniform(lo, hi))
        msg = cc.encode_fields(name, fields, k)
        data = bytes(msg.data)
        raw = unpack_independent(name, data)
        by_cantools = dbc.db.decode_message(fid, data, decode_choices=False, scaling=False)
        assert by_cantools == raw
        sample = cc.VdpsCanDecoder().decode(0, fid, data)[0]
        for f in value_fields(name):
            phys = raw[f] * sigs[f][3]
            if f == "warning_time_to_rollover_s" and raw[f] == 65535:
                phys = math.inf
            assert sample.fields[f] == pytest.approx(phys, rel=1e-12, abs=1e-15)
        if name == "VDPS_Warning":
            assert raw["warning_crc"] == crc8_bitwise(data[1:])


def test_struct_view_of_two_frames():
    # wheel speeds: two little-endian int16 at 0.01 rad/s and a uint8 counter
    m = cc.encode_wheel_speed_front(83.33, -1.5, 300)
    assert struct.unpack("<hhB", bytes(m.data)) == (8333, -150, 300 % 256)
    # warning: crc u8, counter|level<<4|status<<6 u8, ttr u16 (ms), roll i16, ltr i16 (1e-4)
    w = cc.encode_warning(level=2, time_to_rollover_s=0.75, peak_roll_rad=-0.25, ltr=0.9,
                          status=1, counter=9)
    crc, b1, ttr, roll, ltr = struct.unpack("<BBHhh", bytes(w.data))
    assert (b1 & 0xF, (b1 >> 4) & 3, b1 >> 6) == (9, 2, 1)
    assert (ttr, roll, ltr) == (750, -2500, 9000)
    assert crc == crc8_bitwise(bytes(w.data)[1:])
    assert struct.pack("<hB", 1234, 7) == bytes(cc.encode_steer(1.234, 7).data)


# ---------------------------------------------------------------------------------------------
# VDPS_Warning: CRC and counter enforced
# ---------------------------------------------------------------------------------------------
def test_warning_every_single_and_double_bit_flip_is_rejected_and_counted():
    dec = cc.VdpsCanDecoder()
    good0 = cc.encode_warning(1, 2.5, 0.2, 0.6, 0, 0)
    assert len(dec.decode(0, 0x080, bytes(good0.data))) == 1
    good1 = bytes(cc.encode_warning(2, 1.25, 0.3, 0.8, 0, 1).data)
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
    data = bytearray(cc.encode_warning(level, ttr, roll, ltr, status, ctr).data)
    data[bit // 8] ^= 1 << (bit % 8)
    dec = cc.VdpsCanDecoder()
    assert dec.decode(0, 0x080, bytes(data)) == []
    assert dec.counters["VDPS_Warning"]["crc_mismatch"] == 1
    assert dec.total_rejected == 1


def test_warning_counter_rules():
    dec = cc.VdpsCanDecoder()

    def send(ctr):
        return dec.decode(0, 0x080, bytes(cc.encode_warning(0, None, 0.0, 0.0, 0, ctr).data))

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
# sensor frames: counters, lost frames, rejects
# ---------------------------------------------------------------------------------------------
def test_sensor_lost_frames_counted_including_wraps():
    dec = cc.VdpsCanDecoder()
    period = 1_000_000  # 1 kHz
    sent = list(range(0, 50)) + list(range(53, 400)) + list(range(1400, 1450))  # 3 + 1000 lost
    for k in sent:
        m = cc.encode_steer(0.01 * (k % 100), k)
        assert len(dec.decode(k * period, m.arbitration_id, bytes(m.data))) == 1
    c = dec.counters["VDPS_SteerAngle"]
    assert c["accepted"] == len(sent) and c["lost_frames"] == 3 + 1000


def test_sensor_repeat_rejected_and_counted():
    dec = cc.VdpsCanDecoder()
    m = cc.encode_suspension([0.01, 0.02, -0.03, 0.0], 5)
    assert len(dec.decode(0, m.arbitration_id, bytes(m.data))) == 1
    assert dec.decode(1000, m.arbitration_id, bytes(m.data)) == []
    assert dec.counters["VDPS_Suspension"]["counter_repeat"] == 1


def test_rejects_counted_never_raised():
    dec = cc.VdpsCanDecoder()
    steer = bytes(cc.encode_steer(1.0, 0).data)
    assert dec.decode(0, 0x130, steer[:2]) == []                      # DLC 2 != 3
    assert dec.decode(0, 0x130, steer + b"\0") == []                  # DLC 4 != 3
    assert dec.decode(0, 0x130, struct.pack("<hB", 20000, 1)) == []   # 20 rad > 12.567
    assert dec.decode(0, 0x080, bytes(8)) == []                       # CRC of zeros is not 0
    assert dec.decode(0, 0x7FF, b"\1\2") == []                        # unknown standard ID
    assert dec.decode(0, 0x130, steer, is_extended_id=True) == []     # our ID, but 29-bit
    assert dec.decode(0, 0x130, None) == []                           # not bytes
    assert dec.decode(0, "x", steer) == []                            # not an ID
    c = dec.counters
    assert c["VDPS_SteerAngle"]["dlc_mismatch"] == 2
    assert c["VDPS_SteerAngle"]["out_of_range"] == 1
    assert c["VDPS_Warning"]["crc_mismatch"] == 1
    assert dict(c["bus"]) == {"unknown_id": 1, "unknown_id_extended": 1, "malformed": 2}
    assert dec.total_rejected == 8
    with pytest.raises(TypeError):
        c["bus"]["unknown_id"] = 0  # read-only view


def test_decode_message_and_encoder_class_route_samples():
    enc = cc.VdpsCanEncoder()
    dec = cc.VdpsCanDecoder(source="can.test")
    w = {f"wheel_speed_radps_{i}": 80.0 + i for i in range(1, 5)}
    for k in range(3):
        frames = enc.frames(Sample(t_ns=k * 1_000_000, source="sim", kind="wheel_speed", fields=w))
        assert [f.arbitration_id for f in frames] == [0x100, 0x101]
        out = [s for f in frames for s in dec.decode_message(f)]
        assert [s.fields["seq_counter"] for s in out] == [k, k]
        merged = {n: v for s in out for n, v in s.fields.items() if n != "seq_counter"}
        assert merged == {n: cc.quantize(n, v) for n, v in w.items()}
        assert all(s.source == "can.test" and s.t_ns == k * 1_000_000 for s in out)
    with pytest.raises(ValueError):
        enc.frames(Sample(t_ns=0, source="sim", kind="imu", fields={"angular_rate_radps_x": 0.0}))
    a, b = enc.warning(1, 3.0, 0.1, 0.5, 0), enc.warning(1, 3.0, 0.1, 0.5, 0)
    assert [s.fields["warning_counter"] for m in (a, b) for s in dec.decode_message(m)] == [0, 1]
    err = can.Message(arbitration_id=0x100, is_error_frame=True)
    assert dec.decode_message(err) == [] and dec.counters["bus"]["malformed"] == 1


# ---------------------------------------------------------------------------------------------
# fuzz: garbage interleaved with a valid stream
# ---------------------------------------------------------------------------------------------
def test_fuzz_garbage_interleaved_with_valid_frames(rng):
    dbc = cc.load_dbc()
    ours = {s.frame_id: s for s in dbc.messages.values()}
    enc = cc.VdpsCanEncoder()
    dec = cc.VdpsCanDecoder()
    expected = {"unknown_id": 0, "unknown_id_extended": 0, "dlc_mismatch": 0, "crc_mismatch": 0}
    n_valid = n_decoded = 0
    t_ns = 0
    for k in range(3000):
        t_ns += 100_000
        # a valid frame from a sensor or the warning, in sequence
        if k % 10 == 0:
            fields = {"warning_level": int(rng.integers(0, 4)),
                      "warning_time_to_rollover_s": float(rng.uniform(0, 10)),
                      "warning_peak_roll_rad": float(rng.uniform(-1, 1)),
                      "warning_ltr": float(rng.uniform(-1, 1)), "warning_status": 0}
            m = enc.warning(*(fields[f] for f in ("warning_level", "warning_time_to_rollover_s",
                                                  "warning_peak_roll_rad", "warning_ltr",
                                                  "warning_status")), t_ns=t_ns)
        else:
            spec = list(dbc.messages.values())[1 + k % 5]
            fields = {f: float(rng.uniform(s.minimum, s.maximum))
                      for f, s in zip(spec.field_names, spec.values)}
            m = enc.frames(Sample(t_ns=t_ns, source="sim", kind=spec.kind, fields=fields))[0]
        out = dec.decode(t_ns, m.arbitration_id, bytes(m.data))
        n_valid += 1
        n_decoded += len(out)
        assert len(out) == 1
        got = {n: v for n, v in out[0].fields.items() if n not in ("seq_counter", "warning_counter")}
        assert got == {n: cc.quantize(n, v) for n, v in fields.items()}
        assert set(got) == set(fields)
        # 1..3 garbage frames that cannot pass as valid
        for _ in range(int(rng.integers(1, 4))):
            choice = rng.integers(0, 4)
            data = rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8).tobytes()
            if choice == 0:  # unknown standard ID
                aid = int(rng.integers(0, 0x800))
                while aid in ours:
                    aid = int(rng.integers(0, 0x800))
                dec.decode(t_ns, aid, data)
                expected["unknown_id"] += 1
            elif choice == 1:  # any 29-bit ID
                dec.decode(t_ns, int(rng.integers(0, 1 << 29)), data, is_extended_id=True)
                expected["unknown_id_extended"] += 1
            elif choice == 2:  # one of our IDs with a wrong DLC
                spec = ours[list(ours)[int(rng.integers(0, len(ours)))]]
                while len(data) == spec.dlc:
                    data = rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8).tobytes()
                dec.decode(t_ns, spec.frame_id, data)
                expected["dlc_mismatch"] += 1
            else:  # a warning-sized frame with a wrong CRC
                data = bytearray(rng.integers(0, 256, 8, dtype=np.uint8).tobytes())
                if cc.crc8_j1850(data[1:]) == data[0]:
                    data[0] ^= 0x01
                dec.decode(t_ns, 0x080, bytes(data))
                expected["crc_mismatch"] += 1
    c = dec.counters
    assert n_decoded == n_valid == sum(c[n]["accepted"] for n in dbc.messages)
    assert c["bus"]["unknown_id"] == expected["unknown_id"]
    assert c["bus"]["unknown_id_extended"] == expected["unknown_id_extended"]
    assert sum(c[n]["dlc_mismatch"] for n in dbc.messages) == expected["dlc_mismatch"]
    assert c["VDPS_Warning"]["crc_mismatch"] == expected["crc_mismatch"]
    assert dec.total_rejected == sum(expected.values())
    assert all(c[n]["lost_frames"] == 0 for n in dbc.messages)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.one_of(st.sampled_from([0x080, 0x100, 0x101, 0x110, 0x120, 0x130]),
                                    st.integers(0, (1 << 29) - 1)),
                          st.booleans(), st.binary(max_size=12)), max_size=60))
def test_fuzz_arbitrary_frames_each_counted_exactly_once(frames):
    dec = cc.VdpsCanDecoder()
    accepted = 0
    for t, (aid, ext, data) in enumerate(frames):
        out = dec.decode(t * 1000, aid, data, is_extended_id=ext)
        assert len(out) <= 1
        accepted += len(out)
        for s in out:
            assert all(math.isfinite(v) or n == "warning_time_to_rollover_s"
                       for n, v in s.fields.items())
    c = dec.counters
    assert accepted == sum(c[n]["accepted"] for n in LAYOUT)
    assert accepted + dec.total_rejected == len(frames)


# ---------------------------------------------------------------------------------------------
# frame length and bus load
# ---------------------------------------------------------------------------------------------
def test_frame_bits_published_lengths():
    # classic CAN, 11-bit ID, 3-bit interframe space: 8 data bytes -> 111 bits unstuffed and
    # 135 bits worst case (Davis et al. 2007); 0 bytes -> 47 and 55
    assert (cc.frame_bits(8, stuffing="none"), cc.frame_bits(8)) == (111, 135)
    assert (cc.frame_bits(0, stuffing="none"), cc.frame_bits(0)) == (47, 55)
    # all-zero frame (ID 0, DLC 0, CRC 0): 34 dominant bits get a stuff bit after every 5
    assert cc.frame_bits_stuffed(0, b"") == 47 + 6


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 0x7FF), st.binary(max_size=8))
def test_exact_stuffing_within_bounds(aid, data):
    n = cc.frame_bits_stuffed(aid, data)
    assert cc.frame_bits(len(data), stuffing="none") <= n <= cc.frame_bits(len(data))


def test_bus_load_at_table1_rates_well_below_capacity():
    worst = {p: cc.bus_load(r)["total"] for p, r in cc.RATE_PROFILES.items()}
    # independent sum with the published frame lengths (n=8: 135, n=5: 105, n=3: 85 bits)
    c = {"VDPS_Warning": 135, "VDPS_WheelSpeedFront": 105, "VDPS_WheelSpeedRear": 105,
         "VDPS_Suspension": 135, "VDPS_WheelTorque": 135, "VDPS_SteerAngle": 85}
    for p, rates in cc.RATE_PROFILES.items():
        assert worst[p] == pytest.approx(sum(rates[n] * c[n] for n in c) / 1e6, rel=1e-12)
    assert worst["table1-susp1k"] < 0.5 and worst["table1"] < worst["table1-susp1k"]
    assert cc.RATE_PROFILES["table1"]["VDPS_Suspension"] == 1.0
    assert cc.RATE_PROFILES["table1-susp1k"]["VDPS_Suspension"] == 1000.0
