"""tools/convert_comma2k19.py on the real comma2k19 segment: the converted NMEA text, MTi capture
and shifted candump log import with `vdps import`'s own code (no errors), and what comes back
equals comma's arrays (u-blox fixes to the printed precision, phone IMU to float32 and one byte
time, CAN wheel speeds equal comma's own decoded values on the shifted clock)."""

from __future__ import annotations

import importlib.util
import json
import math

import numpy as np
import pytest

from vdps_hil.adapters.health import ERROR_COUNTERS
from vdps_hil.realdata.comma2k19 import COMMA_SEGMENT, read_comma_phone_imu, read_comma_ublox
from vdps_hil.realdata.runs import load_samples
from vdps_hil.record.importer import CanSource, SerialSource, import_logs
from vdps_hil.units import wrap_pi

from conftest import REAL_DATA, REPO

SEG = REAL_DATA / COMMA_SEGMENT
DBC = SEG / "toyota_new_mc_pt_generated.dbc"


def _tool():
    spec = importlib.util.spec_from_file_location("convert_comma2k19", REPO / "tools" / "convert_comma2k19.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    if not SEG.is_dir():
        pytest.skip(f"real data not present: {SEG}")
    out = tmp_path_factory.mktemp("comma")
    doc = _tool().convert(SEG, out)
    samples, status = load_samples([CanSource("pt", str(out / "pt.candump.log"), "can0")],
                                   [SerialSource("gnss", str(out / "gnss.nmea")),
                                    SerialSource("imu", str(out / "imu.mti"), 115200)],
                                   signalmap="toyota_rav4_2017", dbc={"*": str(DBC)})
    return out, doc, samples, status


def test_clock_and_counts(converted):
    out, doc, samples, status = converted
    fixes = read_comma_ublox(SEG)
    imu = read_comma_phone_imu(SEG)
    t0 = doc["t0_s"]
    assert t0 == math.floor(min(fixes.t_s[0], imu.t_s[0])) - 1.0
    assert json.loads((out / "convert.json").read_text())["t0_s"] == t0
    kinds = {}
    for s in samples:
        kinds[s.kind] = kinds.get(s.kind, 0) + 1
    errors = {k: sum(v["counters"].get(e, 0) for e in ERROR_COUNTERS) for k, v in status.items()}
    print("\ncomma2k19 converted + imported:", kinds, "errors", errors)
    assert kinds["gnss_pos"] == kinds["gnss_vel"] == len(fixes) == 579
    assert kinds["imu"] == imu.t_s.shape[0] == 6256
    assert kinds["wheel_speed"] == 4974
    assert errors == {"can.pt": 0, "gnss": 0, "imu": 0}
    assert doc["imu"]["delayed"] == 0 and doc["imu"]["max_time_error_s"] <= 10.0 / 115200


def test_gnss_values_round_trip(converted):
    out, doc, samples, _ = converted
    fixes = read_comma_ublox(SEG)
    pos = [s for s in samples if s.kind == "gnss_pos"]
    vel = [s for s in samples if s.kind == "gnss_vel"]
    t = np.array([s.t_ns for s in pos]) / 1e9
    assert np.max(np.abs(t - (fixes.t_s - doc["t0_s"]))) < 1e-6  # stamps to the microsecond
    lat = np.array([s.fields["gnss_lat_deg"] for s in pos])
    lon = np.array([s.fields["gnss_lon_deg"] for s in pos])
    h = np.array([s.fields["gnss_alt_m"] + s.fields["gnss_geoid_sep_m"] for s in pos])
    assert np.max(np.abs(lat - fixes.lat_deg)) < 1e-6 / 60 + 1e-12  # 1e-6 minute
    assert np.max(np.abs(lon - fixes.lon_deg)) < 1e-6 / 60 + 1e-12
    assert np.max(np.abs(h - fixes.h_m)) <= 0.0005 + 1e-9
    sp = np.array([s.fields["gnss_speed_mps"] for s in vel])
    crs = np.array([s.fields["gnss_course_rad"] for s in vel])
    assert np.max(np.abs(sp - fixes.speed_mps)) <= 0.0005 * 1852 / 3600 + 1e-9  # 0.001 kn printed
    assert np.max(np.abs(wrap_pi(crs - fixes.course_rad))) <= math.radians(0.0005) + 1e-9
    assert all(s.fields["gnss_fix_quality"] == 1.0 for s in pos)


def test_phone_imu_axes_and_times(converted):
    out, doc, samples, _ = converted
    imu = read_comma_phone_imu(SEG)
    got = [s for s in samples if s.kind == "imu"]
    t = np.array([s.t_ns for s in got]) / 1e9
    assert np.max(np.abs(t - (imu.t_s - doc["t0_s"]))) <= 10.0 / 115200 + 1e-9  # one byte time
    f = np.array([[s.fields[f"specific_force_mps2_{a}"] for a in "xyz"] for s in got])
    assert np.allclose(f, imu.specific_force_mps2, rtol=1e-6, atol=1e-6)  # float32 on the wire
    raw = np.load(SEG / "processed_log" / "IMU" / "accelerometer" / "value")
    assert np.allclose(f[:, 1], -raw[:, 1], atol=1e-5) and np.allclose(f[:, 2], -raw[:, 2], atol=1e-5)
    # z up: the mean specific force over the segment points up (+g), as the bus convention wants
    assert 9.0 < f[:, 2].mean() < 10.6


def test_can_on_the_shifted_clock_equals_comma_decoding(converted):
    out, doc, samples, _ = converted
    ws = [s for s in samples if s.kind == "wheel_speed"]
    t = np.array([s.t_ns for s in ws]) / 1e9 + doc["t0_s"]
    fl = np.array([s.fields["wheel_speed_radps_1"] for s in ws]) * 0.35
    ct = np.load(SEG / "processed_log" / "CAN" / "wheel_speed" / "t")
    cv = np.load(SEG / "processed_log" / "CAN" / "wheel_speed" / "value")
    assert np.allclose(t, ct, atol=1e-6)
    assert np.allclose(fl, cv[:, 0], atol=1e-9)  # comma: [FL, FR, RL, RR] in m/s


def test_vdps_import_writes_the_recording(converted, tmp_path):
    out, doc, _, _ = converted
    rep = import_logs(tmp_path / "rav4.mcap", [CanSource("pt", str(out / "pt.candump.log"), "can0")],
                      [SerialSource("gnss", str(out / "gnss.nmea")), SerialSource("imu", str(out / "imu.mti"), 115200)],
                      signalmap="toyota_rav4_2017", dbc={"*": str(DBC)})
    assert rep["write_errors"] == 0
    assert rep["sources"]["imu"]["kinds"]["imu"]["count"] == 6256
    assert rep["sources"]["gnss"]["counters"].get("rejected", 0) == 0


def test_shift_candump_is_exact_and_keeps_odd_lines(tmp_path):
    src = tmp_path / "a.log"
    src.write_bytes(b"(46408.584930) can0 260#08FFFB0000001884\n# comment\n(0.000001) can1 0AA#00\n")
    n, k = _tool().shift_candump(src, tmp_path / "b.log", 46407.0)
    assert (n, k) == (3, 2)
    assert (tmp_path / "b.log").read_bytes() == (b"(1.584930) can0 260#08FFFB0000001884\n# comment\n"
                                                 b"(-46406.999999) can1 0AA#00\n")


def test_cli_errors_are_one_line(tmp_path, capsys):
    assert _tool().main([str(tmp_path / "missing"), str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("convert_comma2k19:") and "\n" not in err
