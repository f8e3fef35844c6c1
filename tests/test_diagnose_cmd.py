"""``vdps diagnose``: one full run through the CLI registry, and the one-line errors."""

from __future__ import annotations

import json

import pytest

from vdps_hil.cli.main import main
from vdps_hil.experiments.workbench_study import HIDDEN, cached_drive


@pytest.fixture(scope="module")
def drive(drive_cache):
    man, spec = HIDDEN["low_pressure_tire"]
    return cached_drive(drive_cache, man, [spec], seed=21)


def test_full_run(drive, tmp_path, capsys):
    eff = tmp_path / "my_effect.py"
    eff.write_text("from vdps_hil.model.effects import DynamicsEffect, ParamSpec\n"
                   "class Push(DynamicsEffect):\n"
                   "    name = 'push'\n"
                   "    HOOKS = ('body_wrench',)\n"
                   "    PARAMS = (ParamSpec('force_n', 'N', 100.0, 'x force', 0.0, 1000.0),)\n"
                   "    def body_wrench(self, v, w, a):\n"
                   "        return (self.force_n, 0.0, 0.0, 0.0, 0.0, 0.0)\n")
    rc = main(["diagnose", str(drive), "--json", "-", "--report", str(tmp_path / "rep"), "--no-simulation",
               "--quiet", "--effect-file", str(eff), "--save-model", str(tmp_path / "m.toml")])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    assert doc["recommendation"] == "low_pressure_tire"
    assert "push" in [e["effect"] for e in doc["ranking"]]
    assert "under-inflated tire" in out.err and "rear left" in out.err  # human words on stderr with --json -
    assert (tmp_path / "rep" / "report.html").stat().st_size > 10_000
    assert (tmp_path / "m.toml").read_text().startswith("schema = \"vdps-model\"")


@pytest.mark.parametrize("args, msg", [
    (["nope.mcap"], "no such file"),
    (["."], "is a directory, not a file"),
    (["{drive}", "--vehicle", "sedan-truth"], "only model files"),
    (["{drive}", "--save-model", "m.yaml"], ".toml or .json"),
    (["{drive}", "--effect-file", "missing.py"], "no such file"),
    (["{drive}", "--dbc", "x.dbc"], "--signalmap"),
    (["{drive}", "--model", "bad.toml"], "cannot read model file"),
    (["{drive}", "--sensorset", "nosuch"], "cannot read sensor set"),
])
def test_errors_are_one_line(drive, capsys, args, msg):
    rc = main(["diagnose", *[a.replace("{drive}", str(drive)) for a in args], "--quiet", "--no-simulation"])
    err = capsys.readouterr().err
    assert rc == 2
    assert msg in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_drive_too_short_for_held_out_blocks_is_one_line(tmp_path, capsys):
    """2.5 s of the paper drive: past the estimator's settling and the row count, 3 blocks of
    0.5 s, too few to hold one out and fit on the rest (it was an IndexError)."""
    short = tmp_path / "short.mcap"
    assert main(["sim", "paper", "--duration", "2.5", "--quiet", "-o", str(short)]) == 0
    capsys.readouterr()
    rc = main(["diagnose", str(short), "--quiet", "--no-simulation"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "too short to judge an effect on held-out time blocks" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_an_error_on_a_damaged_recording_says_the_file_is_damaged(drive, tmp_path, capsys):
    with open(drive, "rb") as f:
        data = bytearray(f.read())
    for i in range(2000, len(data) - 2000, 4096):  # a byte flipped in every compressed chunk
        data[i] ^= 0xFF
    bad = tmp_path / "striped.mcap"
    bad.write_bytes(data)
    rc = main(["diagnose", str(bad), "--quiet", "--no-simulation"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "(the recording is damaged: " in err and f"`vdps info {bad}` lists them)" in err


def test_help_shows_an_example(capsys):
    assert main(["diagnose", "--help"]) == 0
    assert "vdps diagnose drive.mcap --add aero_drag" in capsys.readouterr().out


@pytest.fixture(scope="module")
def rav4(tmp_path_factory):
    from rav4_import import import_rav4

    return import_rav4(tmp_path_factory.mktemp("rav4"))


def test_the_real_rav4_drive_is_diagnosed_with_its_own_sensor_set(rav4, capsys):
    """Issue 18 item 4 on the real RAV4 (comma2k19, converted and imported as README "Real cars"
    says): the car has wheel speeds, steering, the ESC's yaw rate and accelerations, a phone IMU
    and u-blox GNSS, no wheel torques and no suspension. ``vdps diagnose`` exits 0, names both
    missing signal groups and what they prevent, ranks the candidates the remaining equations
    can judge, and prints no NaN and no implausible value as a recommendation."""
    rc = main(["diagnose", str(rav4), "--vehicle", "rav4-model", "--json", "-", "--quiet"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert "NaN" not in out.out and "nan" not in out.err.lower().replace("nanoseconds", "")
    doc = json.loads(out.out)
    msgs = doc["workbench"]["messages"]
    assert any(m.startswith("missing signals: wheel torques") and "cannot be judged" in m for m in msgs), msgs
    assert any(m.startswith("missing signals: suspension deflections") and "held at the model file" in m
               for m in msgs), msgs
    ranked = doc["ranking"]
    assert len(ranked) >= 5 and all(e["explained_fraction"] is not None for e in ranked[:3])
    # what the partial set can judge is judged (the lateral and yaw balances, the GNSS innovations)
    assert set(doc["before"]["residual_rms"]) >= {"lat", "yaw"}
    # the set it ran with, inferred (no --sensorset): single antenna, so the real-car rows (test_configure)
    sset = doc["workbench"]["sensor_set"]
    assert sset["source"] == "inferred from the recording" and sset["gnss"] == "single_antenna", sset
    if doc["recommendation"] is not None:
        top = next(e for e in ranked if e["effect"] == doc["recommendation"])
        assert top["plausible"] and top["excited"], top


def test_the_real_rav4_with_its_named_set_judges_the_esc_cluster_alone(rav4, capsys):
    """``--sensorset rav4-can-ublox``: the car's ESC cluster (a_x, a_y, yaw rate) is the IMU and the
    phone IMU of the import is left out (``sensorsets.KindMap``). The workbench substitutes the
    cluster's missing axes as the estimator does and evaluates only the equations that do not need
    them: the lateral and yaw balances are judged (finite), the vertical, roll and pitch ones are
    not, and both the substitution and the sensor left out are named."""
    rc = main(["diagnose", str(rav4), "--vehicle", "rav4-model", "--sensorset", "rav4-can-ublox", "--json", "-",
               "--quiet", "--no-simulation"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    doc = json.loads(out.out)
    sset = doc["workbench"]["sensor_set"]
    assert (sset["source"], sset["imu"]) == ("rav4-can-ublox", "esc3")
    assert set(sset["imu_substituted"]) == {"specific_force_mps2_z", "angular_rate_radps_x", "angular_rate_radps_y"}
    assert sset["not_used"]["imu/imu"] > 6000
    msgs = doc["workbench"]["messages"]
    assert any(m.startswith("missing signals: IMU axes") and "not evaluated" in m for m in msgs), msgs
    assert any(m.startswith("not used: imu/imu") for m in msgs), msgs
    rms = doc["before"]["residual_rms"]
    assert set(rms) == {"lat", "yaw"} and all(v is not None and v > 0 for v in rms.values()), rms
    assert len(doc["ranking"]) >= 5


def test_the_real_rav4_table_has_the_esc_yaw_rate_bias_out(rav4):
    """The ESC cluster's yaw rate reads -0.40 deg/s at rest (the estimator's gyro bias state finds
    it, ``tests/test_real_rav4.py``); the workbench's table takes the filter's final estimate out
    of its rates (``dataset``), so on this straight highway segment (its heading spans about 1 deg
    in 59 s: 0.02 deg/s) the table's mean yaw rate is within 0.1 deg/s of zero. Raw, it was
    -0.416 deg/s, and through the slip angles it put -246 N m into the mean yaw residual."""
    import math

    import numpy as np

    from vdps_hil.cli.common import recorded_decoding
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.workbench.dataset import DatasetConfig, load_drive

    dbc, sm = recorded_decoding(rav4)
    tab = load_drive(rav4, load_vehicle("rav4-model"), dbc=dbc, signalmap=sm,
                     config=DatasetConfig(sensorset="rav4-can-ublox"))
    mean_degps = math.degrees(float(np.nanmean(tab.columns["rate_b_radps_z"])))
    assert abs(mean_degps) < 0.1, mean_degps
