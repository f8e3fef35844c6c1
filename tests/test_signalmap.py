"""Signal maps (adapters.signalmap): the shipped maps load and name only catalogue fields, bad
maps give one-line errors, unit conversion."""

import math

import pytest

from vdps_hil.adapters.signalmap import SIGNALMAP_DIR, SignalMapError, convert_unit, load_signalmap
from vdps_hil.bus.samples import FIELDS


def write_map(tmp_path, text, name="m.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_shipped_maps_load_and_name_only_catalogue_fields():
    names = sorted(p.stem for p in SIGNALMAP_DIR.glob("*.toml"))
    assert {"vdps", "toyota_rav4_2017", "canedge_gnss_imu"} <= set(names)
    for n in names:
        sm = load_signalmap(n)
        for bus in sm.buses.values():
            assert bus.fields() <= set(FIELDS)
            assert bus.messages


@pytest.mark.parametrize("text,needle", [
    ("name = 'x'\n[bus.a\n", "malformed TOML"),
    ("name = 'x'\n", "no [bus.<name>]"),
    ("[bus.a]\nbogus = 1\n", "unknown key(s) bogus"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field='not_a_field'}]\n", "not in the bus catalogue"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field='wheel_speed_radps_1', unit='furlong'}]\n", "unknown unit"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field='wheel_speed_radps_1', unit='km/h'}]\n",
     "needs rolling_radius_m"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field='steer_wheel_angle_rad', unit='m/s'}]\n", "cannot convert"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\nchecksum='crc99'\n"
     "signals=[{signal='S', field='steer_wheel_angle_rad', unit='deg'}]\n", "unknown checksum"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field='steer_wheel_angle_rad', unit='deg', sign=2}]\n",
     "sign must be 1 or -1"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field='steer_wheel_angle_rad', unit='deg', scale=0}]\n",
     "scale must not be 0"),  # close/20.md: accepted, every value decoded as the offset
    # a list where a name belongs: each was an internal TypeError (unhashable type: 'list')
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field=['wheel_speed_radps_1', 'x']}]\n", "not in the bus catalogue"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\n"
     "signals=[{signal='S', field='steer_wheel_angle_rad', unit='deg', transform=[1, 2]}]\n", "unknown transform"),
    ("[bus.a]\n[[bus.a.message]]\nframe_id = 1\nkind='k'\nchecksum=[1, 2]\n"
     "signals=[{signal='S', field='steer_wheel_angle_rad', unit='deg'}]\n", "unknown checksum"),
    ("[bus.a]\ncodec = [1, 2]\n", "unknown codec"),
    ("[bus.a]\nmessage = 5\n", "'message' must be a list of tables"),
])
def test_bad_maps_give_one_line_errors(tmp_path, text, needle):
    p = write_map(tmp_path, text)
    with pytest.raises(SignalMapError) as e:
        load_signalmap(p)
    msg = str(e.value)
    assert needle in msg and "\n" not in msg and str(p) in msg


def test_unit_conversions():
    assert convert_unit("deg", "rad") == pytest.approx(math.pi / 180)
    assert convert_unit("km/h", "m/s") == pytest.approx(1 / 3.6)
    assert convert_unit("g", "m/s^2") == pytest.approx(9.80665)
    assert convert_unit("bar", "Pa") == pytest.approx(1e5)
    assert convert_unit("Nm", "N m") == 1.0
    assert convert_unit("deg", "deg") == 1.0  # gnss_lat_deg stays in degrees
    # wheel linear speed -> spin rate: omega = v / r
    assert convert_unit("km/h", "rad/s", 0.35) == pytest.approx(1 / 3.6 / 0.35)
