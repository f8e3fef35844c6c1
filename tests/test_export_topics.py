"""Tests of vdps_hil.app.export_topics and ``vdps export``: the CSV files read back hold every
message of the chosen topics with the values the mcap library reads (flattened dotted paths),
a /raw/can/ topic comes out decoded (the wheel speeds, 1 kHz, SI), shell patterns choose
topics, and a topic that is not there is one line with exit status 2."""

from __future__ import annotations

import csv
import json

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from replayed_drive import replayed_drive

from vdps_hil.app.export_topics import flatten, select_topics
from vdps_hil.cli.main import cli


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    return replayed_drive(tmp_path_factory.mktemp("export"), seed=6)


def _read(path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _mcap(path, topic) -> list[tuple[int, dict]]:
    with open(path, "rb") as f:
        return [(m.log_time, json.loads(m.data)) for _, _, m in make_reader(f).iter_messages(topics=[topic])]


def test_est_topics_read_back_equal(drive, tmp_path):
    r = CliRunner().invoke(cli, ["export", str(drive / "out.mcap"), "--csv", str(tmp_path / "csv"),
                                 "--topic", "/est/state", "--topic", "/est/tf"])
    assert r.exit_code == 0, r.output
    rows = _read(tmp_path / "csv" / "est.state.csv")
    want = _mcap(drive / "out.mcap", "/est/state")
    assert len(rows) == len(want) > 100
    got = sorted(float(r["values.phi_v_rad"]) for r in rows)
    assert got == pytest.approx(sorted(d["values"]["phi_v_rad"] for _, d in want), rel=1e-12, abs=0)
    t = [int(r["t_ns"]) for r in rows]
    assert t == sorted(t) and 1.9e9 < t[-1] - t[0] < 2.1e9
    tf = _read(tmp_path / "csv" / "est.tf.csv")
    assert sorted(float(r["translation.x"]) for r in tf) == \
        pytest.approx(sorted(d["translation"]["x"] for _, d in _mcap(drive / "out.mcap", "/est/tf")), rel=1e-12)


def test_raw_can_is_exported_decoded(drive, tmp_path):
    r = CliRunner().invoke(cli, ["export", str(drive / "paper.mcap"), "--csv", str(tmp_path), "--topic", "/raw/can/*"])
    assert r.exit_code == 0, r.output
    rows = _read(tmp_path / "raw.can.vdps.csv")
    ws = [float(r["fields.wheel_speed_radps_1"]) for r in rows if r["fields.wheel_speed_radps_1"]]
    assert 1900 < len(ws) < 2100  # 1 kHz for 2 s
    assert 70 < min(ws) and max(ws) < 90  # 25 m/s on a ~0.31 m wheel
    assert {r["source"] for r in rows} == {"can.vdps"}
    steer = [r for r in rows if r["fields.steer_wheel_angle_rad"]]
    assert 190 < len(steer) < 210 and all(r["fields.wheel_speed_radps_1"] == "" for r in steer)


def test_flatten_and_topic_choice():
    assert flatten({"a": {"b": 1, "c": [2, {"d": None}]}, "e": "x"}) == {"a.b": 1, "a.c.0": 2, "a.c.1.d": None, "e": "x"}
    topics = ["/est/state", "/est/tf", "/raw/can/vdps", "/truth/state"]
    assert select_topics(topics, []) == ["/est/state", "/est/tf", "/truth/state"]
    assert select_topics(topics, ["/est/*", "/est/tf"]) == ["/est/state", "/est/tf"]


def test_missing_topic_or_file_is_one_line(drive, tmp_path):
    for args in ([str(drive / "out.mcap"), "--csv", str(tmp_path), "--topic", "/est/nothing"],
                 [str(tmp_path / "missing.mcap"), "--csv", str(tmp_path)]):
        r = CliRunner().invoke(cli, ["export", *args])
        assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output
