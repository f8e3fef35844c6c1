"""The real RAV4 drive (comma2k19 segment 40) converted and imported as README "Real cars" says:
the car's powertrain bus through the shipped signal map and opendbc's DBC, the u-blox fixes as
NMEA and the comma device's phone IMU as an Xsens stream (``tools/convert_comma2k19.py``, then
``vdps import``). The recording holds two IMUs: the car's ESC cluster (kind ``esc_imu``) and the
phone's (kind ``imu``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from conftest import REAL_DATA, REPO


def import_rav4(tmp_path: Path) -> Path:
    """The imported recording (``tmp_path/rav4.mcap``); skips when the real data is absent."""
    from vdps_hil.realdata.comma2k19 import COMMA_SEGMENT
    from vdps_hil.record.importer import CanSource, SerialSource, import_logs

    seg = REAL_DATA / COMMA_SEGMENT
    if not seg.is_dir():
        pytest.skip(f"real data not present: {seg}")
    spec = importlib.util.spec_from_file_location("convert_comma2k19", REPO / "tools" / "convert_comma2k19.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    conv = tmp_path / "conv"
    tool.convert(seg, conv)
    rec = tmp_path / "rav4.mcap"
    rep = import_logs(rec, [CanSource("pt", str(conv / "pt.candump.log"), "can0")],
                      [SerialSource("gnss", str(conv / "gnss.nmea")),
                       SerialSource("imu", str(conv / "imu.mti"), 115200)],
                      signalmap="toyota_rav4_2017", dbc={"*": str(seg / "toyota_new_mc_pt_generated.dbc")})
    assert rep["write_errors"] == 0
    return rec
