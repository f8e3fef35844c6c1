"""Tests of vdps_hil.codecs.can_dbc and dbc/vdps.dbc: the DBC says what the module docstring
says (LAYOUT of tests/can_checks.py, checked against cantools' reading of the DBC), it meets
the resolution and range requirements, and a bad DBC gives a one-line error.
"""

from __future__ import annotations

import math

import pytest

from vdps_hil.bus.samples import FIELDS
from vdps_hil.codecs.can_dbc import DEFAULT_DBC_PATH, DbcError, VdpsDbc, load_dbc

from can_checks import COUNTER_NAMES, KINDS, LAYOUT


def test_dbc_layout_matches_claimed_table():
    dbc = load_dbc()
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
            if s.name not in COUNTER_NAMES and not s.name.endswith("_crc"):
                assert s.name in FIELDS
    assert dbc.bitrate_bps == 1_000_000


def test_dbc_meets_the_requirements_of_the_issue():
    dbc = load_dbc()
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
    # issue 20: every frame has a 4-bit counter and a CRC at byte 0; a sensor frame's CRC covers
    # its CAN ID as the data ID, the warning's none (its layout is unchanged)
    for name, spec in dbc.messages.items():
        assert spec.counter.length_bits == 4 and spec.crc.start_bit == 0 and spec.crc.length_bits == 8
        assert spec.data_id == (None if name == "VDPS_Warning" else spec.frame_id)
    # the two torque frames form one sample group
    assert {n for n, s in dbc.messages.items() if s.group} == {"VDPS_WheelTorqueFront", "VDPS_WheelTorqueRear"}


def test_legacy_layout_1_is_kept_and_found_by_a_recordings_hash():
    """Layout 1 (no sensor CRC, 8-bit counters, one torque frame) still loads, and the DBC hash a
    recording names selects it; the current layout's hash (or none) selects nothing."""
    from vdps_hil.codecs.can_dbc import LEGACY_DBC_PATHS, recorded_vdps_dbc
    from vdps_hil.record.schemas import content_hash

    v1 = VdpsDbc(LEGACY_DBC_PATHS[0])
    assert v1.messages["VDPS_WheelTorque"].dlc == 8 and v1.messages["VDPS_WheelTorque"].crc is None
    assert v1.messages["VDPS_SteerAngle"].counter.length_bits == 8
    assert recorded_vdps_dbc({"hash.dbc.vdps": content_hash(LEGACY_DBC_PATHS[0])}) == LEGACY_DBC_PATHS[0]
    assert recorded_vdps_dbc({"hash.dbc.vdps": content_hash(DEFAULT_DBC_PATH)}) is None
    assert recorded_vdps_dbc({}) is None


def test_bad_dbc_gives_one_line_error(tmp_path):
    p = tmp_path / "bad.dbc"
    p.write_text("this is not a dbc\n")
    with pytest.raises(DbcError) as e:
        VdpsDbc(p)
    assert "\n" not in str(e.value) and "bad.dbc" in str(e.value)
    text = DEFAULT_DBC_PATH.read_text().replace("wheel_speed_radps_1", "wheel_rpm_1")
    p.write_text(text)
    with pytest.raises(DbcError, match="wheel_rpm_1: not a bus field"):
        VdpsDbc(p)


@pytest.mark.parametrize("edit,msg", [
    (("wheel_speed_radps_1 : 16|16@1- (0.01,0)", "wheel_speed_radps_1 : 16|16@1- (0,0)"), "scale 0 "),
    (("BO_ 304 VDPS_SteerAngle: 4 SAS", "BO_ 304 VDPS_SteerAngle: 255 SAS"), "length 255"),
    (("BO_ 304 VDPS_SteerAngle: 4 SAS", "BO_ 304 VDPS_SteerAngle: 12 SAS"), "1-8 data bytes"),
], ids=["scale-0", "dlc-255", "dlc-12"])
def test_absurd_numbers_in_the_dbc_give_one_line_error(tmp_path, edit, msg):
    """Issue 20, finding 6: a scale of 0 was a ZeroDivisionError, DLC 255 was accepted."""
    p = tmp_path / "bad.dbc"
    p.write_text(DEFAULT_DBC_PATH.read_text().replace(*edit))
    with pytest.raises(DbcError, match=msg) as e:
        VdpsDbc(p)
    assert "\n" not in str(e.value) and "bad.dbc" in str(e.value)
