"""Tests of vdps_hil.codecs.can_bulk through ``VdpsCanDecoder.decode_many``: decoding the frames of
one message as a block gives exactly what the per-frame decoder (the reference, which the live
adapters use) gives -- the same samples in the same order, bit for bit, the same counters
(accepted, lost frames, every reject) and the same counter state afterwards -- on simulated
drives, a drive with faults, malformed frames and arbitrary frames, in calls of any size."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from vdps_hil.codecs.can_bulk import crc_column, payload_block, raw_columns, scaled_column
from vdps_hil.codecs.can_dbc import TTR_NONE_RAW, load_dbc
from vdps_hil.codecs.can_decode import BULK_MIN_FRAMES, VdpsCanDecoder
from vdps_hil.codecs.can_e2e import e2e_crc
from vdps_hil.codecs.dbc_compile import compile_message
from vdps_hil.sim.drive import Drive

from can_checks import messages, recording_frames, sample_key



def _state(dec: VdpsCanDecoder) -> tuple:
    seq = {n: (s.last, s.t_ns, None if s.period_ns is None else s.period_ns.hex(), s.pending)
           for n, s in dec._seq.items()}
    return dict(dec.counters["bus"]), {n: dict(c) for n, c in dec.counters.items() if n != "bus"}, seq


def _per_frame(frames, dbc=None):
    dec = VdpsCanDecoder(dbc)
    out = [[sample_key(s) for s in dec.decode_frame(*f)] for f in frames]
    return out, _state(dec)


def _bulk(frames, sizes, dbc=None):
    """decode_many over consecutive calls of the given sizes (cycled)."""
    dec = VdpsCanDecoder(dbc)
    out, k, i = [], 0, 0
    while k < len(frames):
        n = sizes[i % len(sizes)]
        out += [[] if s is None else [sample_key(s)] for s in dec.decode_many(frames[k:k + n])]
        k, i = k + n, i + 1
    return out, _state(dec)


def _assert_equal(frames, sizes=(4096,), dbc=None):
    ref_out, ref_state = _per_frame(frames, dbc)
    got_out, got_state = _bulk(frames, sizes, dbc)
    assert len(got_out) == len(ref_out)
    for k, (a, b) in enumerate(zip(ref_out, got_out)):
        assert a == b, f"frame {k}: {frames[k]}"
    assert got_state == ref_state
    assert list(got_state[1]["VDPS_SteerAngle"]) == list(ref_state[1]["VDPS_SteerAngle"])  # key order
    return ref_out, ref_state


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    d = tmp_path_factory.mktemp("bulk")
    out = {}
    for name, kw in (("table1", {"profile": "table1"}), ("table1-susp1k", {"profile": "table1-susp1k"}),
                     ("faults", {"profile": "table1-susp1k", "faults": [
                         "dropped_frames:fraction=0.05", "clock_jump:device=can,t_s=1.5,jump_s=-0.3",
                         "frozen_can_signal:signal=steer_wheel_angle_rad,t_s=1,duration_s=1"]})):
        p = d / f"{name}.mcap"
        Drive("paper", seed=3, duration_s=3.0, **kw).run(p)
        out[name] = recording_frames(p)
    return out


@pytest.mark.parametrize("name", ["table1", "table1-susp1k", "faults"])
def test_drives_decode_identically_in_bulk_and_per_frame(drives, name):
    frames = drives[name]
    out, (bus, counts, _) = _assert_equal(frames)
    assert sum(map(len, out)) > 1000
    if name == "faults":  # the faults reach the counters that must agree
        assert sum(c["lost_frames"] for c in counts.values()) > 0


@pytest.mark.parametrize("sizes", [(1,), (7, 3), (BULK_MIN_FRAMES,), (100, 250), (1000, 5, 2048)])
def test_any_call_size_gives_the_same_as_one_frame_at_a_time(drives, sizes):
    _assert_equal(drives["faults"], sizes)


def _sensor(frame_id: int, body: bytes) -> bytes:
    return bytes((e2e_crc(b"\0" + body, frame_id),)) + body


def _steer(counter: int, raw: int) -> bytes:
    return _sensor(0x130, bytes((counter & 0xF,)) + int(raw).to_bytes(2, "little", signed=True))


def _warning(counter: int, status: int = 0, ttr_raw: int = 1000, roll: int = 10, ltr: int = -5) -> bytes:
    body = bytes(((counter & 0xF) | (1 << 4) | (status << 6),)) + ttr_raw.to_bytes(2, "little") + \
        roll.to_bytes(2, "little", signed=True) + ltr.to_bytes(2, "little", signed=True)
    return bytes((e2e_crc(b"\0" + body, None),)) + body


def _malformed_stream(rng, n=6000):
    """Valid drive-like frames of every message with every kind of fault mixed in: wrong DLCs,
    bad CRCs, repeated and jumping counters, out-of-range raw values, unknown and extended IDs,
    warnings with a status or the TTR sentinel, time gaps of several counter wraps and bursts."""
    frames, t = [], 0
    ctr = {0x130: 0, 0x080: 0}
    for k in range(n):
        t += int(rng.choice([1_000_000, 1_000_000, 1_000_000, 37_000_000, 0, 250_000]))
        aid = int(rng.choice([0x130, 0x130, 0x080]))
        ctr[aid] += int(rng.choice([1, 1, 1, 1, 0, 2, 5, 16]))
        if aid == 0x130:
            raw = int(rng.choice([100, -200, 12567, -12567, 12568, 20000, -30000]))
            data = _steer(ctr[aid], raw)
        else:
            data = _warning(ctr[aid], status=int(rng.integers(0, 4)) if rng.random() < 0.2 else 0,
                            ttr_raw=TTR_NONE_RAW if rng.random() < 0.3 else int(rng.integers(0, 65535)))
        r = rng.random()
        if r < 0.05:
            data = bytearray(data)
            data[int(rng.integers(0, len(data)))] ^= 1 << int(rng.integers(0, 8))  # a bad CRC (or a caught flip)
            data = bytes(data)
        elif r < 0.08:
            data = data[:-1] if rng.random() < 0.5 else data + b"\0"  # wrong DLC
        elif r < 0.10:
            aid = int(rng.integers(0, 0x800))  # unknown (or a known ID with a foreign payload)
        frames.append((t, aid, data, bool(r > 0.995)))  # a few extended IDs
    return frames


def test_malformed_frames_are_counted_identically(rng):
    frames = _malformed_stream(rng)
    out, (bus, counts, _) = _assert_equal(frames, sizes=(4096, 17, 3))
    steer, warn = counts["VDPS_SteerAngle"], counts["VDPS_Warning"]
    for reason in ("crc_mismatch", "counter_repeat", "out_of_range", "dlc_mismatch"):
        assert steer[reason] > 0, reason
    assert warn["counter_jump"] > 0 and warn["crc_mismatch"] > 0 and steer["lost_frames"] > 0
    assert bus["unknown_id"] > 0 and bus["unknown_id_extended"] > 0
    assert any(s[5] is False for got in out for s in got)  # a warning with a status: valid=False
    assert any(f == ("warning_time_to_rollover_s", "float", "inf") for got in out for s in got for f in s[3])


def test_torque_groups_merge_across_calls_and_lost_members(drives, rng):
    frames = [f for f in drives["table1"] if f[1] in (0x120, 0x121)]
    keep = [f for f in frames if rng.random() > 0.1]  # members lost: group_incomplete
    out, (_, counts, _) = _assert_equal(keep, sizes=(33, 64))
    assert counts["VDPS_WheelTorqueRear"]["group_incomplete"] > 0


def test_layout_1_recordings_decode_identically():
    from pathlib import Path

    v1 = Path(__file__).resolve().parents[1] / "dbc" / "vdps_v1.dbc"
    dec = load_dbc(v1)
    rng = np.random.default_rng(7)
    frames = []
    for k in range(400):
        for spec in dec.messages.values():
            if spec.is_sensor:
                frames.append((k * 1_000_000, spec.frame_id, rng.integers(0, 256, spec.dlc, dtype=np.uint8).tobytes(),
                               False))
    _assert_equal(frames, sizes=(500,), dbc=v1)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([0x080, 0x100, 0x101, 0x110, 0x120, 0x121, 0x130, 0x7FF]),
                          st.booleans(), st.binary(min_size=3, max_size=9), st.integers(0, 40)), max_size=200),
       st.integers(1, 64))
def test_fuzz_arbitrary_frames_decode_identically(frames, size):
    """Random payloads of every length under every ID (most fail their CRC; the rest walk the
    counter and range rules), with random time steps, in calls of a random size."""
    t, typed = 0, []
    for aid, ext, data, dt in frames:
        t += dt * 250_000
        typed.append((t, aid, data, ext and aid == 0x7FF))
    _assert_equal(typed, sizes=(size,))


def test_block_kernels_equal_the_compiled_layout(rng):
    """The block helpers row by row against ``CompiledMessage.raw`` and ``e2e_crc`` on random
    payloads, and the scaled values against the per-frame arithmetic."""
    for spec in load_dbc().messages.values():
        comp = compile_message(spec.message)
        data = [rng.integers(0, 256, spec.dlc, dtype=np.uint8).tobytes() for _ in range(300)]
        block = payload_block(data, spec.dlc)
        cols = raw_columns(comp.extractors, len(comp.names), block)
        assert [list(r) for r in zip(*(c.tolist() for c in cols))] == [comp.raw(d) for d in data]
        assert crc_column(block, 0x5A).tolist() == [e2e_crc(d, None, 0x5A) for d in data]
    raw = np.array([-32768, -1, 0, 1, 12345, 32767, 65535])
    for scale, offset in ((0.01, 0), (1, 0), (4e-05, 0.5), (0.001, -3)):
        assert scaled_column(raw, scale, offset, None) == [float(r * scale + offset) for r in raw.tolist()]
    assert scaled_column(raw, 0.001, 0, 65535)[-1] == float("inf")
    big = np.array([(1 << 61) + 1, -(1 << 61) - 3])
    assert scaled_column(big, 3, 1, None) == [float(r * 3 + 1) for r in big.tolist()]


@settings(max_examples=200, deadline=None)
@given(m=messages(), data=st.data())
def test_block_raw_values_equal_the_compiled_layout_on_random_layouts(m, data):
    """Both byte orders, signed and unsigned signals of 1-32 bits anywhere in 1-8 bytes."""
    comp = compile_message(m)
    rows = data.draw(st.lists(st.binary(min_size=m.length, max_size=m.length), min_size=1, max_size=20))
    cols = raw_columns(comp.extractors, len(comp.names), payload_block(rows, m.length))
    assert [list(r) for r in zip(*(c.tolist() for c in cols))] == [comp.raw(d) for d in rows]
