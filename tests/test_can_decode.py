"""Tests of vdps_hil.codecs.can_decode: rejects counted and never raised, python-can messages
and the encoder class routed to samples, and fuzzing with garbage between valid frames.
"""

from __future__ import annotations

import math
import struct

import can
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.can_dbc import load_dbc
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_e2e import crc8_j1850
from vdps_hil.codecs.can_encode import VdpsCanEncoder, encode_steer, quantize

from can_checks import LAYOUT


def test_rejects_counted_never_raised():
    dec = VdpsCanDecoder()
    steer = bytes(encode_steer(1.0, 0).data)
    assert dec.decode(0, 0x130, steer[:2]) == []                      # DLC 2 != 3
    assert dec.decode(0, 0x130, steer + b"\0") == []                  # DLC 4 != 3
    assert dec.decode(0, 0x130, struct.pack("<hB", 20000, 1)) == []   # 20 rad > 12.567
    assert dec.decode(0, 0x080, bytes(8)) == []                       # CRC of zeros is not 0
    assert dec.decode(0, 0x7FF, b"\1\2") == []                        # unknown standard ID
    assert dec.decode(0, 0x130, steer, is_extended_id=True) == []     # our ID, but 29-bit
    assert dec.decode(0, 0x130, None) == []                           # not bytes
    assert dec.decode(0, "x", steer) == []                            # not an ID
    assert dec.decode(0, 0x130, steer, is_fd=True) == []              # our ID and DLC, but CAN FD
    assert dec.decode(0, 0x130, b"", is_remote_frame=True) == []      # a remote frame
    c = dec.counters
    assert c["VDPS_SteerAngle"]["dlc_mismatch"] == 2
    assert c["VDPS_SteerAngle"]["out_of_range"] == 1
    assert c["VDPS_Warning"]["crc_mismatch"] == 1
    assert dict(c["bus"]) == {"unknown_id": 1, "unknown_id_extended": 1, "malformed": 2,
                              "fd_frame": 1, "remote_frame": 1}
    assert dec.total_rejected == 10
    assert dec.decode(0, 0x130, steer) != []  # the counter was not taken from the FD frame
    with pytest.raises(TypeError):
        c["bus"]["unknown_id"] = 0  # read-only view


def test_decode_message_and_encoder_class_route_samples():
    enc = VdpsCanEncoder()
    dec = VdpsCanDecoder(source="can.test")
    w = {f"wheel_speed_radps_{i}": 80.0 + i for i in range(1, 5)}
    for k in range(3):
        frames = enc.frames(Sample(t_ns=k * 1_000_000, source="sim", kind="wheel_speed", fields=w))
        assert [f.arbitration_id for f in frames] == [0x100, 0x101]
        out = [s for f in frames for s in dec.decode_message(f)]
        assert [s.fields["seq_counter"] for s in out] == [k, k]
        merged = {n: v for s in out for n, v in s.fields.items() if n != "seq_counter"}
        assert merged == {n: quantize(n, v) for n, v in w.items()}
        assert all(s.source == "can.test" and s.t_ns == k * 1_000_000 for s in out)
    with pytest.raises(ValueError):
        enc.frames(Sample(t_ns=0, source="sim", kind="imu", fields={"angular_rate_radps_x": 0.0}))
    a, b = enc.warning(1, 3.0, 0.1, 0.5, 0), enc.warning(1, 3.0, 0.1, 0.5, 0)
    assert [s.fields["warning_counter"] for m in (a, b) for s in dec.decode_message(m)] == [0, 1]
    err = can.Message(arbitration_id=0x100, is_error_frame=True)
    assert dec.decode_message(err) == [] and dec.counters["bus"]["malformed"] == 1
    rtr = can.Message(arbitration_id=0x130, is_remote_frame=True, dlc=3, is_extended_id=False)
    fd = can.Message(arbitration_id=0x130, data=bytes(3), is_fd=True, is_extended_id=False)
    assert dec.decode_message(rtr) == [] and dec.decode_message(fd) == []
    assert dec.counters["bus"]["remote_frame"] == 1 and dec.counters["bus"]["fd_frame"] == 1


# ---------------------------------------------------------------------------------------------
# fuzz: garbage interleaved with a valid stream
# ---------------------------------------------------------------------------------------------
def test_fuzz_garbage_interleaved_with_valid_frames(rng):
    dbc = load_dbc()
    ours = {s.frame_id: s for s in dbc.messages.values()}
    enc = VdpsCanEncoder()
    dec = VdpsCanDecoder()
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
        assert got == {n: quantize(n, v) for n, v in fields.items()}
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
                if crc8_j1850(data[1:]) == data[0]:
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
    dec = VdpsCanDecoder()
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
