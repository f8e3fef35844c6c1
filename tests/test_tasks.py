"""Tests of vdps_hil.batch.tasks: drive naming, the streaming replay (estimates close to the
truth, counts equal to what was recorded), task builders
(keys, costs), and unsupported recordings as one-line errors."""

from __future__ import annotations

import math
import os

import pytest

from vdps_hil.batch.engine import execute
from vdps_hil.batch.keys import tool_version
from vdps_hil.batch.tasks import (UnsupportedRecording, diagnose_drive, drive_ids, replay_drive,
                                  replay_stream, replay_tasks, worker_info)
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.writer import RecordingWriter
from vdps_hil.sim.drive import Drive


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    p = tmp_path_factory.mktemp("tasks") / "paper.mcap"
    Drive("paper", seed=4, duration_s=2.0).run(p)
    return os.fspath(p)


def test_drive_ids_are_stems_made_unique_by_a_path_hash():
    ids = drive_ids(["a/x.mcap", "b/x.mcap", "c/my drive (1).mcap", "y.mcap"])
    assert ids[2] == "my_drive_1_.mcap".replace(".mcap", "") and ids[3] == "y"
    assert ids[0].startswith("x-") and ids[1].startswith("x-") and ids[0] != ids[1]
    assert len(ids[0]) == len("x-") + 8
    assert drive_ids(["a/x.mcap", "b/x.mcap"]) == ids[:2]  # stable


def test_streaming_replay_counts_what_was_recorded_and_tracks_the_truth(drive):
    doc = replay_stream(drive)
    with RecordingReader(drive) as r:
        topics = {t: i.count for t, i in r.topics().items()}
        truth = [d["values"] for _, _, d in r.iter_messages(["/truth/state"])]
    assert doc["recording"]["raw_topics"] == {t: n for t, n in topics.items() if t.startswith("/raw/")}
    assert doc["recording"]["problems"] == [] and not doc["recording"]["truncated"]
    # one IMU sample per IMU packet decoded, every CAN frame accepted (chassis samples)
    imu = doc["decoders"]["/raw/serial/imu"]
    assert doc["samples"]["imu"] == imu["messages"] > 0 and imu["rejected"] == 0
    can = doc["decoders"]["/raw/can/vdps"]
    accepted = sum(c["accepted"] for k, c in can.items() if k != "bus")
    assert accepted == topics["/raw/can/vdps"]
    # the estimate at the end against the truth at its time (the EKF's ENU origin is its first
    # fix, so positions are not compared; attitude accuracy is the estimator's tests' business):
    # speed within 0.3 m/s, course over ground within 0.05 rad
    est = doc["estimator"]["final"]
    assert est is not None and est["t_s"] > 1.5
    assert doc["span_s"] == pytest.approx(2.0, abs=0.1)
    near = min(truth, key=lambda v: abs(v["t_s"] - est["t_s"]))
    assert abs(near["t_s"] - est["t_s"]) < 0.03  # the last serial chunks arrive after the end
    course = math.atan2(est["state"]["ydot_g_mps"], est["state"]["xdot_g_mps"])
    assert abs(math.remainder(course - math.atan2(near["vel_g_mps_n"], near["vel_g_mps_e"]),
                              2 * math.pi)) < 0.05
    speed = math.hypot(est["state"]["xdot_g_mps"], est["state"]["ydot_g_mps"])
    assert speed == pytest.approx(math.hypot(near["vel_g_mps_e"], near["vel_g_mps_n"]), abs=0.3)


def test_unsupported_serial_format_and_missing_raw_topics_are_one_line_errors(tmp_path):
    p = tmp_path / "weird.mcap"
    with RecordingWriter(p) as w:
        w.write_serial("gadget", 1_000_000, b"\x01\x02", baud=9600, fmt="morse")
    with pytest.raises(UnsupportedRecording, match="unsupported format 'morse'"):
        replay_stream(p)
    q = tmp_path / "truth-only.mcap"
    with RecordingWriter(q) as w:
        w.write_truth("state", 0, {"t_s": 0.0})
    with pytest.raises(UnsupportedRecording, match="no /raw/ topics"):
        replay_stream(q)
    doc = execute("vdps_hil.batch.tasks:replay_drive", {"path": os.fspath(q), "engine": "internal"})
    assert doc["status"] == "failed" and "\n" not in doc["error"]["message"]


def test_replay_drive_internal_equals_replay_stream(drive):
    assert replay_drive(drive, engine="internal") == replay_stream(drive)


def test_replay_tasks_carry_keys_costs_and_inputs(drive, tmp_path):
    other = tmp_path / "copy.mcap"
    other.write_bytes(open(drive, "rb").read())
    missing = tmp_path / "missing.mcap"
    tasks = replay_tasks([drive, other, missing])
    assert [t.id for t in tasks] == ["paper", "copy", "missing"]
    assert tasks[0].key == tasks[1].key  # same bytes, same options: same key (paths do not count)
    assert tasks[2].key != tasks[0].key and tasks[2].cost == 0
    assert tasks[0].cost == os.path.getsize(drive)
    assert tasks[0].meta == {"input": drive, "kind": "replay"}
    assert replay_tasks([drive], options={"predict_period_s": 0.02})[0].key != tasks[0].key
    assert replay_tasks([drive], vehicle="suv-model")[0].key != tasks[0].key
    assert replay_tasks([drive], effects=["drag"])[0].key != tasks[0].key


def test_diagnose_without_a_workbench_entry_point_is_a_clear_error(drive):
    from vdps_hil.batch import tasks as T
    if T._library("vdps_hil.workbench", "diagnose_file") is not None:
        pytest.skip("the workbench provides diagnose_file")
    with pytest.raises(RuntimeError, match="workbench"):
        diagnose_drive(drive)


def test_worker_info_reports_the_tool_version():
    info = worker_info()
    assert info["tool"] == tool_version() and info["python"].count(".") == 2
