"""tools/convert_rtklib.py on the rtklibexplorer drive 0708: the time-tag file, the publisher's IMU
time rule, the .pos solution as time-stamped NMEA (RTK quality and mode kept), the IMU as an MTi
capture in its own axes; everything imports through `vdps import`'s code with no errors and
equals the source files to the printed precision. Broken lines are skipped, missing files are
one-line errors."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from vdps_hil.adapters.health import ERROR_COUNTERS
from vdps_hil.realdata.rtklib import RTKLIB_DRIVE, read_rtklib_imu, read_rtklib_pos, read_timetag
from vdps_hil.realdata.runs import load_samples
from vdps_hil.record.importer import SerialSource
from vdps_hil.units import GRAVITY_MPS2, wrap_pi

from conftest import REAL_DATA, REPO

DRIVE = REAL_DATA / RTKLIB_DRIVE
POS = DRIVE / "gnss_1934_sf.pos"
CSV = DRIVE / "imu_1934.csv"
TAG = DRIVE / "imu_1934.csv.tag"


def _tool():
    spec = importlib.util.spec_from_file_location("convert_rtklib", REPO / "tools" / "convert_rtklib.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    if not DRIVE.is_dir():
        pytest.skip(f"real data not present: {DRIVE}")
    out = tmp_path_factory.mktemp("rtk")
    doc = _tool().convert(POS, CSV, out, tag_path=TAG)
    samples, status = load_samples([], [SerialSource("gnss", str(out / "gnss.nmea")),
                                        SerialSource("imu", str(out / "imu.mti"), 115200)])
    return out, doc, samples, status


def test_time_tag_file():
    if not DRIVE.is_dir():
        pytest.skip("real data not present")
    tag = read_timetag(TAG)
    assert tag.header == "TIMETAG RTKLIB demo5"
    import datetime as dt
    start = dt.datetime.fromtimestamp(tag.start_s, dt.timezone.utc)
    assert start.strftime("%Y-%m-%d %H:%M:%S.%f")[:23] == "2025-07-08 19:34:21.854"  # the README's GPST start
    assert np.all(np.diff(tag.ticks_ms) >= 0) and np.all(np.diff(tag.fpos) >= 0)
    assert 548.0 < tag.end_s - tag.start_s < 549.5


def test_counts_and_errors(converted):
    out, doc, samples, status = converted
    errors = {k: sum(v["counters"].get(e, 0) for e in ERROR_COUNTERS) for k, v in status.items()}
    kinds = {}
    for s in samples:
        kinds[s.kind] = kinds.get(s.kind, 0) + 1
    print(f"\nRTKLIB converted + imported: {kinds}, errors {errors}, t0 GPST {doc['t0_gpst_s']:.0f}, "
          f"RTK fixed {100 * doc['gnss']['rtk_fixed_fraction']:.1f} %")
    assert errors == {"gnss": 0, "imu": 0}
    assert kinds == {"gnss_pos": 2197, "gnss_vel": 2197, "imu": 54860}
    assert doc["gnss"]["rtk_fixed_fraction"] > 0.99  # README: 99.6 % fixed


def test_gnss_round_trip_and_quality(converted):
    out, doc, samples, _ = converted
    sol = read_rtklib_pos(POS)
    pos = [s for s in samples if s.kind == "gnss_pos"]
    vel = [s for s in samples if s.kind == "gnss_vel"]
    t = np.array([s.t_ns for s in pos]) / 1e9 + doc["t0_gpst_s"]
    assert np.max(np.abs(t - sol.t_gpst_s)) < 1e-6
    lat = np.array([s.fields["gnss_lat_deg"] for s in pos])
    assert np.max(np.abs(lat - sol.lat_deg)) < 1e-6 / 60 + 1e-12
    h = np.array([s.fields["gnss_alt_m"] + s.fields["gnss_geoid_sep_m"] for s in pos])
    assert np.max(np.abs(h - sol.h_m)) <= 0.0005 + 1e-9
    q = np.array([s.fields["gnss_fix_quality"] for s in pos])
    assert set(np.unique(q)) == {4.0, 5.0} and np.sum(q == 5.0) == int(np.sum(sol.q == 2))  # fix -> 4, float -> 5
    sp = np.array([s.fields["gnss_speed_mps"] for s in vel])
    assert np.max(np.abs(sp - np.hypot(sol.vel_neu_mps[:, 0], sol.vel_neu_mps[:, 1]))) <= 0.0005 * 1852 / 3600 + 1e-9
    crs = np.array([s.fields.get("gnss_course_rad", math.nan) for s in vel])
    moving = np.hypot(sol.vel_neu_mps[:, 0], sol.vel_neu_mps[:, 1]) > 0.05
    assert np.all(np.isnan(crs[~moving])) and np.all(np.isfinite(crs[moving]))
    ref = np.arctan2(sol.vel_neu_mps[moving, 0], sol.vel_neu_mps[moving, 1])
    assert np.max(np.abs(wrap_pi(crs[moving] - ref))) <= math.radians(0.0005) + 1e-9


def test_imu_times_follow_the_publishers_rule_and_axes_stay_raw(converted):
    out, doc, samples, _ = converted
    imu = [s for s in samples if s.kind == "imu"]
    t = np.array([s.t_ns for s in imu]) / 1e9 + doc["t0_gpst_s"]
    raw = np.loadtxt(CSV, delimiter=",")
    tag = read_timetag(TAG)
    sec = (raw[:, 6] - raw[0, 6]) / 1000.0
    expect = tag.start_s + sec * (tag.end_s - tag.start_s) / sec[-1]
    assert np.max(np.abs(t - expect)) <= 10.0 / 115200 + 1e-6
    f = np.array([[s.fields[f"specific_force_mps2_{a}"] for a in "xyz"] for s in imu])
    w = np.array([[s.fields[f"angular_rate_radps_{a}"] for a in "xyz"] for s in imu])
    assert np.allclose(f, raw[:, 0:3] * GRAVITY_MPS2, rtol=1e-6, atol=1e-6)
    assert np.allclose(w, np.radians(raw[:, 3:6]), rtol=1e-6, atol=1e-7)
    # IMU axes, not body axes: z reads about +1 g at rest, x about +0.12 g (the 6.8 deg misalignment)
    assert 9.7 < f[:1000, 2].mean() < 10.1 and 1.0 < f[:1000, 0].mean() < 1.3


def test_broken_lines_are_skipped(tmp_path):
    if not DRIVE.is_dir():
        pytest.skip("real data not present")
    lines = POS.read_text().splitlines(keepends=True)
    bad = tmp_path / "bad.pos"
    bad.write_text("".join(lines[:5]) + "garbage line\n2025/07/08 19:34:19.749 40.1 x\n" + "".join(lines[5:40]))
    sol = read_rtklib_pos(bad)
    assert sol.t_gpst_s.shape[0] == 39  # 4 + 35 solution lines; the header and the 2 broken lines skipped
    csv = tmp_path / "imu.csv"
    csv.write_text("0.1,0.2,1.0,0.0,0.0,0.0,100\nnot,a,row\n0.1,0.2,1.0,0.0,0.0,0.0,110\n")
    imu = read_rtklib_imu(csv)
    assert imu.t_s.tolist() == [0.0, 0.01]


def test_cli_errors_are_one_line(tmp_path, capsys):
    tool = _tool()
    assert tool.main([str(tmp_path), str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("convert_rtklib:") and "\n" not in err
    (tmp_path / "x.pos").write_text("% only a header\n")
    assert tool.main([str(tmp_path / "x.pos"), str(tmp_path / "out")]) == 2
    assert "no RTKLIB solution lines" in capsys.readouterr().err
