"""Applying signal maps (adapters.signalmap_decoder): DBC loading and its errors, decoding real
recordings (RAV4 candump against comma's own decoded values; CANedge MF4) plus the project's
DBC, fuzzing, and the compiled layouts against cantools."""

import math

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap
from vdps_hil.adapters.signalmap_decoder import SignalMapDecoder, build_decoder, load_dbc


RAV4 = "comma2k19_rav4_2018-08-02_seg40"


def rav4_decoder(real_data):
    sm = load_signalmap("toyota_rav4_2017")
    dec, info = build_decoder(sm, "pt", real_data / RAV4 / "toyota_new_mc_pt_generated.dbc")
    return dec, info


def test_map_against_wrong_dbc_is_one_line(real_data):
    sm = load_signalmap("toyota_rav4_2017")
    with pytest.raises(SignalMapError) as e:
        build_decoder(sm, "pt", real_data / "css_canedge_gnss_imu_mf4" / "gnss.dbc")
    assert "is not in the DBC" in str(e.value)


def test_strict_dbc_failure_suggests_the_map_switch(real_data):
    with pytest.raises(SignalMapError) as e:
        load_dbc(real_data / RAV4 / "toyota_new_mc_pt_generated.dbc", strict=True)
    assert "dbc_strict = false" in str(e.value)


def test_a_lax_dbc_is_announced_once_per_file(real_data, caplog):
    """``strict=False`` is logged, once per file and process (a diagnosis with ``--add`` loaded
    the RAV4's DBC five times and said so five times)."""
    from vdps_hil.adapters import signalmap_decoder as SD

    p = real_data / RAV4 / "toyota_new_mc_pt_generated.dbc"
    SD._LAX_LOGGED.discard(p.resolve())
    with caplog.at_level("WARNING", logger=SD.__name__):
        for _ in range(3):
            load_dbc(p, strict=False)
    said = [r for r in caplog.records if "strict=False" in r.getMessage()]
    assert len(said) == 1 and str(p.resolve()) in said[0].getMessage()


def test_unreadable_dbc(tmp_path):
    bad = tmp_path / "bad.dbc"
    bad.write_bytes(b"BO_ this is not a dbc \xff\xfe")
    with pytest.raises(SignalMapError):
        load_dbc(bad)
    with pytest.raises(SignalMapError, match="no such file"):
        load_dbc(tmp_path / "missing.dbc")


def test_rav4_candump_zero_decode_errors_and_wheel_speeds_equal_comma(real_data):
    """Acceptance: every DBC-defined ID of the powertrain bus decodes (unknown IDs and DLC
    mismatches counted apart); wheel speeds equal comma's processed_log/CAN/wheel_speed to
    the DBC resolution (0.01 km/h); steering equals processed_log/CAN/steering_angle."""
    dec, info = rav4_decoder(real_data)
    assert not info["dbc_strict"]
    wheel, steer = [], []
    for msg in can.LogReader(real_data / RAV4 / "rav4_seg40.candump.log"):
        if msg.channel != "can0":
            continue
        for s in dec.decode(int(round(msg.timestamp * 1e9)), msg.arbitration_id,
                            bytes(msg.data), msg.is_extended_id):
            assert s.valid
            if s.kind == "wheel_speed":
                wheel.append(s)
            elif s.kind == "steer":
                steer.append(s)
    c = dec.counters
    assert c["undecodable"] == 0 and c["checksum_mismatch"] == 0
    assert c["unknown_id"] > 0  # IDs the DBC does not define: counted, not errors
    assert c["frames"] == c["decoded"] + c["unmapped"] + c["unknown_id"]

    base = real_data / RAV4 / "processed_log" / "CAN"
    ws, ws_t = np.load(base / "wheel_speed" / "value"), np.load(base / "wheel_speed" / "t")
    assert len(wheel) == len(ws)
    t = np.array([s.t_ns for s in wheel]) / 1e9
    assert np.max(np.abs(t - ws_t)) < 1e-5
    r = 0.35  # the map's rolling radius: omega * r is the car's linear speed
    ours = np.array([[s.fields[f"wheel_speed_radps_{i}"] * r for i in range(1, 5)]
                     for s in wheel])
    comma = ws[:, [0, 1, 3, 2]]  # comma's columns are FL FR RL RR; ours FL FR RR RL
    assert np.max(np.abs(ours - comma)) <= 0.01 / 3.6 / 2 + 1e-9

    sa = np.load(base / "steering_angle" / "value")
    assert len(steer) == len(sa)
    ours_deg = np.degrees([s.fields["steer_wheel_angle_rad"] for s in steer])
    assert np.max(np.abs(ours_deg - sa)) < 1e-9


def test_toyota_checksum_rejects_a_flipped_bit(real_data):
    dec, _ = rav4_decoder(real_data)
    # a real SPEED frame (0xB4) from the log, then the same frame with one bit flipped
    frame = next(m for m in can.LogReader(real_data / RAV4 / "rav4_seg40.candump.log")
                 if m.arbitration_id == 0xB4)
    good = bytes(frame.data)
    [s] = dec.decode(0, 0xB4, good, False)
    assert s.valid and s.fields["vehicle_speed_mps"] == pytest.approx(29.38 / 3.6, abs=1e-6)
    bad = bytearray(good)
    bad[5] ^= 0x01
    [s_bad] = dec.decode(1, 0xB4, bytes(bad), False)
    assert not s_bad.valid and dec.counters["checksum_mismatch"] == 1


def test_dlc_mismatch_is_counted_not_a_decode_error(real_data):
    dec, _ = rav4_decoder(real_data)
    longer = dec.decode(0, 0xAA, bytes(8) + b"\x01", False)  # 9 bytes: extra ignored
    shorter = dec.decode(1, 0xAA, bytes(4), False)  # FR and FL only
    assert dec.counters["dlc_mismatch"] == 2 and dec.counters["undecodable"] == 0
    assert len(longer) == 1 and set(longer[0].fields) == {f"wheel_speed_radps_{i}"
                                                          for i in range(1, 5)}
    assert set(shorter[0].fields) == {"wheel_speed_radps_1", "wheel_speed_radps_2"}


def test_canedge_mf4_decodes_gnss_and_imu(real_data):
    folder = real_data / "css_canedge_gnss_imu_mf4"
    sm = load_signalmap("canedge_gnss_imu")
    dec, _ = build_decoder(sm, "gnss", folder / "gnss.dbc")
    kinds = {}
    for msg in can.LogReader(folder / "gnss1.MF4"):
        for s in dec.decode(0, msg.arbitration_id, bytes(msg.data), msg.is_extended_id):
            kinds.setdefault(s.kind, []).append(s)
    assert len(kinds["imu"]) == 1669 and len(kinds["gnss_pos"]) == 168
    assert dec.counters["undecodable"] == 0
    # at rest and level-ish: z specific force about +g (z up)
    assert np.median([s.fields["specific_force_mps2_z"] for s in kinds["imu"]]) == \
        pytest.approx(9.81, abs=0.5)
    # Denmark (Aarhus area)
    lat = np.median([s.fields["gnss_lat_deg"] for s in kinds["gnss_pos"]])
    assert 55.5 < lat < 56.5
    # yaw = wrap(pi/2 - heading)
    att = kinds["gnss_att"][0]
    assert -math.pi <= att.fields["gnss_yaw_rad"] < math.pi


def _vdps_frames(rng, n):
    from vdps_hil.codecs.can_encode import encode_steer, encode_suspension, encode_wheel_speeds

    out = []
    for i in range(n):
        k = i % 3
        if k == 0:
            out.append(encode_wheel_speeds(rng.uniform(-300, 300, 4), i % 256))
        elif k == 1:
            out.append([encode_steer(float(rng.uniform(-12, 12)), i % 256)])
        else:
            out.append([encode_suspension(rng.uniform(-0.15, 0.15, 4), i % 256)])
    return [m for group in out for m in group]


def test_vdps_map_generic_decoder_equals_vdps_codec(rng):
    """The message list of configs/signalmaps/vdps.toml is the same mapping VdpsCanDecoder
    applies: same fields, same values."""
    from vdps_hil.codecs.can_decode import VdpsCanDecoder

    sm = load_signalmap("vdps")
    bm = sm.buses["vdps"]
    generic = SignalMapDecoder(bm, load_dbc(bm.dbc), source="can.vdps")
    codec = VdpsCanDecoder(bm.dbc)
    for i, m in enumerate(_vdps_frames(rng, 300)):
        a = generic.decode(i, m.arbitration_id, bytes(m.data), False)
        b = codec.decode(i, m.arbitration_id, bytes(m.data), False)
        assert len(a) == len(b) == 1
        assert a[0].kind == b[0].kind
        assert a[0].fields.keys() == b[0].fields.keys()
        for k, v in b[0].fields.items():
            assert a[0].fields[k] == pytest.approx(v, abs=1e-12)


def test_remote_and_fd_frames_of_classic_messages_are_counted_not_decoded(rng):
    sm = load_signalmap("vdps")
    bm = sm.buses["vdps"]
    dec = SignalMapDecoder(bm, load_dbc(bm.dbc), source="can.vdps")
    m = _vdps_frames(rng, 1)[0]
    assert dec.decode(0, m.arbitration_id, bytes(m.data), False, is_fd=True) == []
    assert dec.decode(0, m.arbitration_id, b"", False, is_remote_frame=True) == []
    assert len(dec.decode(0, m.arbitration_id, bytes(m.data), False)) == 1
    assert dec.counters["fd_mismatch"] == 1 and dec.counters["remote_frame"] == 1
    assert dec.counters["decoded"] == 1


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 0x7FF), st.binary(max_size=12)), max_size=60),
       st.integers(0, 2**32 - 1))
def test_fuzz_random_frames_between_valid_ones(noise, seed):
    """Random frames (any ID, any length) interleaved with valid ones: no exception, every
    valid frame decoded to the value it encodes."""
    from vdps_hil.codecs.can_encode import encode_steer

    sm = load_signalmap("vdps")
    bm = sm.buses["vdps"]
    dec = SignalMapDecoder(bm, _dbc_cached(bm.dbc))
    r = np.random.default_rng(seed)
    for k, (aid, data) in enumerate(noise):
        dec.decode(k, aid, data, bool(r.integers(2)))
        x = float(r.uniform(-12, 12))
        [m] = [encode_steer(x, k % 256)]
        out = dec.decode(k, m.arbitration_id, bytes(m.data), False)
        assert len(out) == 1
        assert out[0].fields["steer_wheel_angle_rad"] == pytest.approx(x, abs=0.0005 + 1e-12)


_DBC = {}


def _dbc_cached(path):
    if path not in _DBC:
        _DBC[path] = load_dbc(path)
    return _DBC[path]


def _cantools_only(dec: SignalMapDecoder) -> SignalMapDecoder:
    """The same decoder with every compiled layout switched off (cantools decodes everything)."""
    for key in dec._dbc_msgs:
        dec._fast[key] = None
    return dec


@settings(max_examples=40, deadline=None)
@given(frames=st.lists(st.tuples(st.sampled_from([0x080, 0x100, 0x101, 0x110, 0x120, 0x130, 0x7FF]),
                                 st.binary(min_size=0, max_size=9)), min_size=1, max_size=80))
def test_compiled_layouts_decode_as_cantools_vdps_map(frames):
    """The generic decoder on the vdps map: compiled layouts and cantools give the same samples
    and counters for frames of any length (wrong lengths go through cantools either way)."""
    sm = load_signalmap("vdps")
    bm = sm.buses["vdps"]
    fast = SignalMapDecoder(bm, _dbc_cached(bm.dbc))
    slow = _cantools_only(SignalMapDecoder(bm, _dbc_cached(bm.dbc)))
    for k, (aid, data) in enumerate(frames):
        assert fast.decode(k, aid, data) == slow.decode(k, aid, data)
    assert dict(fast.counters) == dict(slow.counters)


def test_compiled_layouts_decode_as_cantools_rav4(real_data):
    """The RAV4 map (opendbc, non-strict DBC, Motorola signals): every message of its DBC on
    random payloads of its length gives the same values compiled as through cantools; the
    messages that do not compile (overlapping or float signals) stay with cantools."""
    fast, _ = rav4_decoder(real_data)
    slow = _cantools_only(rav4_decoder(real_data)[0])
    rng = np.random.default_rng(11)
    compiled = 0
    for key, m in fast._dbc_msgs.items():
        for _ in range(30):
            data = rng.integers(0, 256, m.length, dtype=np.uint8).tobytes()
            assert fast._try_decode(m, data, key) == slow._try_decode(m, data, key)
        compiled += fast._fast[key] is not None
    assert compiled > 0.5 * len(fast._dbc_msgs)
