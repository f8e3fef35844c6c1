"""Tests of ``vdps sim``: a run writes the recording and the summaries, the default output name,
and one-line errors with exit status 2 for bad scenarios, effects, faults, profiles and options."""

from __future__ import annotations

import json

import pytest

from vdps_hil.cli.main import main
from vdps_hil.record.reader import RecordingReader


def test_sim_writes_the_recording_and_a_json_summary(tmp_path, capsys):
    out, js = tmp_path / "p.mcap", tmp_path / "p.json"
    rc = main(["sim", "paper", "--duration", "0.5", "--seed", "2", "--profile", "table1",
               "--effect", "imu_bias:gyro_bias_z_radps=0.01", "--fault", "gyro_spike:t_s=0.2",
               "-o", str(out), "--json", str(js)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "paper: 0.50 s simulated" in text and "/raw/can/vdps" in text and "no rollover event" in text
    doc = json.loads(js.read_text())
    assert doc["duration_s"] == 0.5 and doc["seed"] == 2 and doc["profile"] == "table1"
    assert doc["effects"] == ["magic_formula_tire", "imu_bias"] and doc["faults"][0].startswith("gyro_spike:")
    assert doc["messages"]["/truth/state"] == 51 and doc["messages"]["/raw/serial/imu"] == 101
    assert 24.0 < doc["final_speed_mps"] < 26.0 and doc["rollover_events"] == []
    with RecordingReader(out) as r:
        assert r.topics()["/raw/can/vdps"].count == doc["messages"]["/raw/can/vdps"]


def test_default_output_and_json_on_stdout(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["sim", "paper-left-turn", "--duration", "0.2", "--json", "-"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["output"] == "paper-left-turn.mcap"
    assert "simulated" in cap.err  # the human summary moves to stderr
    assert (tmp_path / "paper-left-turn.mcap").stat().st_size > 0


@pytest.mark.parametrize("args, words", [
    (["sim", "no-such-scenario"], "unknown scenario"),
    (["sim", "paper", "--effect", "no_such_effect"], "unknown effect"),
    (["sim", "paper", "--effect", "imu_bias:nope=1"], "unknown parameter"),
    (["sim", "paper", "--fault", "no_such_fault"], "unknown fault"),
    (["sim", "paper", "--fault", "gyro_spike:axis=w"], "axis must be one of"),
    (["sim", "paper", "--profile", "no_such_profile"], "unknown sensor profile"),
    (["sim", "paper", "--vehicle", "no_such_vehicle"], "cannot read vehicle file"),
    (["sim", "paper", "--vehicle", "sedan-model"], "truth file is needed"),
    (["sim", "paper", "--duration", "0"], "duration must be"),
    (["sim", "paper", "--duration", "x"], "Invalid value"),
    (["sim", "paper", "--duration", "1e12"], "at most 86400 s"),  # it simulated until killed
    (["sim", "paper", "--seed", "-5"], "not in the range x>=0"),  # was: internal error (ValueError)
    (["sim", "paper", "-o", "/no/such/dir/x.mcap"], "does not exist"),
    (["sim", "cr-sine-accel", "--truth", "commonroad-mb:2"], "reserved"),
    (["sim", "cr-sine-accel", "--truth", "commonroad-mb:7"], "1 or 3"),
    (["sim", "cr-sine-accel", "--truth", "bogus"], "unknown truth"),
    (["sim", "paper", "--truth", "commonroad-mb:1"], "flat road only"),
    (["sim", "fishhook-suv", "--truth", "commonroad-mb:3", "--flat-road"], "no wheel lift-off"),
    (["sim", "cr-sine-accel", "--truth", "commonroad-mb:1", "--effect", "aero_drag"], "own physics"),
    (["sim", "cr-sine-accel", "--truth", "commonroad-mb:1", "--vehicle", "sedan-truth"], "brings its vehicle"),
    (["sim", "cr-sine-accel", "--flat-road"], "flat_road applies"),
])
def test_errors_are_one_line_with_exit_status_2(args, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("vdps: error:") and words in err
    assert not list(tmp_path.iterdir())  # nothing written


def test_commonroad_truth_prints_its_backend_and_warnings(tmp_path, capsys):
    out, js = tmp_path / "c.mcap", tmp_path / "c.json"
    assert main(["sim", "paper", "--truth", "commonroad-mb:3", "--flat-road", "--duration", "0.3",
                 "-o", str(out), "--json", str(js)]) == 0
    text = capsys.readouterr().out
    assert "truth: commonroad-mb:3 (commonroad-vehicle-models" in text
    assert "warning: flat road" in text and "magic_formula_tire replaced" in text
    doc = json.loads(js.read_text())
    assert doc["truth"]["backend"] == "commonroad-mb:3" and doc["truth"]["flat_road"] is True
    with RecordingReader(out) as r:
        meta = r.metadata()["truth.drive"]
    assert json.loads(meta["truth"])["parameter_set"] == 3 and meta["vehicle"] == "commonroad-mb-3"


def test_gnss_fix_for_foxglove_and_a_progress_bar_only_on_a_terminal(tmp_path):
    """The recording carries /gnss/fix (foxglove.LocationFix) of every GGA it wrote, at the
    GNSS rate, on the simulated clock; the bar is drawn on a pseudo-terminal, not into a pipe."""
    import re

    from mcap.reader import make_reader
    from terminal import run_on_pty, run_piped, screen_text

    out = tmp_path / "p.mcap"
    code, raw = run_on_pty("sim", "paper", "--duration", "2", "-o", out)
    assert code == 0
    text = screen_text(raw)
    assert re.search(r"vdps sim paper: +\d+%\|.*\d\.\d/2\.0 s \[\d\d:\d\d<\d\d:\d\d", text) and "100%" in text
    with open(out, "rb") as f:
        fixes = [(s.name, m.log_time, json.loads(m.data)) for s, ch, m in make_reader(f).iter_messages()
                 if ch.topic == "/gnss/fix"]
    assert len(fixes) in (10, 11)  # 5 Hz over 2 s
    name, log_time, doc = fixes[0]
    assert name == "foxglove.LocationFix" and abs(doc["latitude"] - 24.787) < 0.01
    assert doc["timestamp"]["sec"] * 10**9 + doc["timestamp"]["nsec"] == log_time
    piped = run_piped("sim", "paper", "--duration", "0.5", "-o", tmp_path / "q.mcap")
    assert piped.returncode == 0 and "%|" not in piped.stdout + piped.stderr
