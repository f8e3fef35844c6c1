"""Tests of vdps_hil.batch.tasks: drive naming, the replay task (what ``vdps replay`` computes,
timing fields moved under "run", estimates close to the truth), task builders (keys from
contents and options, costs, per-drive estimate files) and clear errors."""

from __future__ import annotations

import math
import os

import pytest

from vdps_hil.batch.runner import strip_run
from vdps_hil.batch.worker import execute
from vdps_hil.batch.keys import tool_version
from vdps_hil.batch.tasks import (diagnose_drive, diagnose_tasks, drive_ids, replay_drive,
                                  replay_tasks, worker_info)
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive
from vdps_hil.app.replay import replay_file


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    p = tmp_path_factory.mktemp("tasks") / "paper.mcap"
    Drive("paper", seed=4, duration_s=2.0).run(p)
    return os.fspath(p)


@pytest.fixture(scope="module")
def replayed(drive):
    return replay_drive(drive)


def test_drive_ids_are_stems_made_unique_by_a_path_hash():
    ids = drive_ids(["a/x.mcap", "b/x.mcap", "c/my drive (1).mcap", "y.mcap"])
    assert ids[2] == "my_drive_1_" and ids[3] == "y"
    assert ids[0].startswith("x-") and ids[1].startswith("x-") and ids[0] != ids[1]
    assert len(ids[0]) == len("x-") + 8
    assert drive_ids(["a/x.mcap", "b/x.mcap"]) == ids[:2]  # stable


def test_replay_task_is_vdps_replay_with_the_timing_fields_under_run(drive, replayed):
    direct = replay_file(drive)
    assert set(replayed["run"]) == {"wall_time_s", "realtime_factor"}
    assert "wall_time_s" not in replayed and "realtime_factor" not in replayed
    assert strip_run(replayed) == {k: v for k, v in direct.items()
                                   if k not in ("wall_time_s", "realtime_factor")}


def test_replay_task_reads_every_raw_record_and_tracks_the_truth(drive, replayed):
    with RecordingReader(drive) as r:
        raw = sum(i.count for t, i in r.topics().items() if t.startswith("/raw/"))
        truth = [d["values"] for _, _, d in r.iter_messages(["/truth/state"])]
    assert replayed["messages_read"]["raw_records"] == raw
    assert replayed["identification"]["params"]["mass_kg"] > 0
    # final estimate vs the truth at its time (positions: the EKF's origin is its first fix)
    est = replayed["estimates_summary"]["final"]
    t_est = replayed["estimates_summary"]["t_last_s"]
    near = min(truth, key=lambda v: abs(v["t_s"] - t_est))
    assert abs(near["t_s"] - t_est) < 0.03
    speed = math.hypot(est["state"]["xdot_g_mps"], est["state"]["ydot_g_mps"])
    assert speed == pytest.approx(math.hypot(near["vel_g_mps_e"], near["vel_g_mps_n"]), abs=0.3)
    yaw_err = math.remainder(est["state"]["psi_g_rad"] - near["yaw_g_rad"], 2 * math.pi)
    assert abs(yaw_err) < 5 * est["sigma"]["psi_g_rad"] + 0.01


def test_failures_are_one_line_errors(tmp_path, drive):
    doc = execute("vdps_hil.batch.tasks:replay_drive", {"path": os.fspath(tmp_path / "no.mcap")})
    assert doc["status"] == "failed" and doc["error"]["type"] == "ReplayError"
    assert "\n" not in doc["error"]["message"]
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap at all")
    doc = execute("vdps_hil.batch.tasks:replay_drive", {"path": os.fspath(bad)})
    assert doc["status"] == "failed" and "not an MCAP" in doc["error"]["message"]
    junk = tmp_path / "junk.mcap"  # the magic, then garbage: readable, but nothing in it
    junk.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)))
    doc = execute("vdps_hil.batch.tasks:replay_drive", {"path": os.fspath(junk)})
    # refused by the replay (no sensor in it) or by the batch's own check (no raw record read)
    assert doc["status"] == "failed" and doc["error"]["type"] in ("ReplayError", "NoRawData")
    assert doc["error"]["message"] and "\n" not in doc["error"]["message"]
    with pytest.raises(ValueError, match="unknown replay option"):
        replay_drive(drive, options={"colour": "red"})
    with pytest.raises(ValueError, match="not settable"):
        replay_tasks([drive], options={"output": "x.mcap"})


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
    assert replay_tasks([drive], options={"predict": False})[0].key != tasks[0].key
    assert replay_tasks([drive], vehicle="suv-model")[0].key != tasks[0].key
    assert replay_tasks([drive], effects=["drag"])[0].key != tasks[0].key
    # a parameter file named by an option is keyed by its content
    params = tmp_path / "p.json"
    params.write_text("{}")
    k1 = replay_tasks([drive], options={"params": os.fspath(params)})[0].key
    params.write_text('{"mass_kg": 1}')
    assert replay_tasks([drive], options={"params": os.fspath(params)})[0].key != k1
    # so is a sensor-set file; a set named by its name changes the key as an option
    sset = tmp_path / "s.toml"
    sset.write_text('name = "s"\n[sensors]\nimu = "6axis"\n')
    k2 = replay_tasks([drive], options={"sensorset": os.fspath(sset)})[0].key
    sset.write_text('name = "s"\n[sensors]\nimu = "6axis"\ngnss = "single_antenna"\n')
    assert replay_tasks([drive], options={"sensorset": os.fspath(sset)})[0].key not in (k2, tasks[0].key)
    assert replay_tasks([drive], options={"sensorset": "table1"})[0].key != tasks[0].key


def test_a_named_sensor_set_reaches_the_replay_and_the_workbench(drive, replayed):
    """``vdps batch replay|diagnose --sensorset``: the task's run uses that set, not the one the
    recording's fields infer (both name it in their result)."""
    assert replayed["sensor_set"]["source"] == "inferred from the recording"
    doc = replay_drive(drive, options={"sensorset": "table1", "predict": False, "identify": False})
    assert doc["sensor_set"]["source"] == "table1"
    bad = execute("vdps_hil.batch.tasks:diagnose_drive",
                  {"path": drive, "options": {"sensorset": "nosuch", "with_simulation": False}})
    assert bad["status"] == "failed" and "cannot read sensor set" in bad["error"]["message"], bad["error"]


def test_est_dir_gives_each_drive_its_estimate_recording(drive, tmp_path):
    (t,) = replay_tasks([drive], est_dir=tmp_path, options={"predict": False})
    assert t.kwargs["options"]["output"] == os.path.join(os.fspath(tmp_path), "paper.mcap")
    doc = execute(t.fn, t.kwargs)
    assert doc["status"] == "ok", doc["error"]
    with RecordingReader(tmp_path / "paper.mcap") as r:
        assert r.topics()["/est/state"].count == doc["result"]["estimates_summary"]["count"]


def test_diagnose_task_checks_its_options_and_passes_the_workbench_refusal_on(drive):
    with pytest.raises(ValueError, match="unknown diagnose option"):
        diagnose_drive(drive, options={"save_model": "x.toml"})
    with pytest.raises(ValueError, match="not settable"):
        diagnose_tasks([drive], options={"effect_files": ["x.py"]})
    # a 2 s drive is too short for the workbench's cross-validated ranking: a one-line failure
    doc = execute("vdps_hil.batch.tasks:diagnose_drive",
                  {"path": drive, "options": {"with_simulation": False}})
    assert doc["status"] == "failed" and doc["error"]["type"] == "ValueError"
    assert "\n" not in doc["error"]["message"]


def test_worker_info_reports_the_tool_version():
    info = worker_info()
    assert info["tool"] == tool_version() and info["python"].count(".") == 2
