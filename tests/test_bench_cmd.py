"""Tests of ``vdps bench``: a run prints what happened in plain words and writes the --json
document with the issue's keys; by default the pipeline runs in its own process and the
headroom measured before the run is stated; the status line; the JSON on stdout moves the words
to stderr; mistakes are one line with exit status 2 and nothing written. The runs go at a speed
this machine supports now (``speed``: 1x, or less on a loaded machine)."""

from __future__ import annotations

import copy
import json

import pytest

from vdps_hil.cli.bench_cmd import describe
from vdps_hil.cli.main import main

from test_scheduling import fifo_permitted

KEYS = {"frames_sent": int, "frames_received": int, "lines_sent": int, "lines_received": int, "dropped": int,
        "warning_latency_ms": dict, "warning_lead_time_s": (float, type(None)),
        "warning_lead_to_tipup_s": (float, type(None)), "rolled_over": bool, "realtime_factor": float,
        "late_sends": int}


@pytest.fixture(scope="module")
def speed() -> str:
    """1x, or the speed with 2x headroom when this machine has less now (``hil.headroom``)."""
    from vdps_hil.hil.bench import Bench
    from vdps_hil.hil.bench_config import BenchConfig

    h = Bench(BenchConfig(scenario="paper", duration_s=1.5)).measure_headroom(probe_s=0.5)
    return f"{min(1.0, h.supported_speed):.3g}"


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("cmd")
    out, js = d / "b.mcap", d / "b.json"
    return d, out, js


def test_bench_prints_what_happened_and_writes_json_and_recording(short_run, speed, capsys):
    d, out, js = short_run
    for _ in range(3):
        rc = main(["bench", "--scenario", "paper", "--duration", "1.2", "--speed", speed, "-o", str(out),
                   "--json", str(js)])
        cap = capsys.readouterr()
        if rc != 2:
            break
        # the command's own check met more load than the module's probe: it refused in one line
        # and named a speed; run as it says (half the speed), as a user would
        assert "the pipeline cannot keep up; run at --speed" in cap.err and "Traceback" not in cap.err, cap.err
        print(f"refused at {speed}x: {cap.err.strip()}")
        speed = f"{float(speed) / 2:.3g}"
    assert rc == 0, cap.err
    text = cap.out
    assert "vdps bench: paper" in text and "ECU reaction off" in text
    assert "pipeline in its own process; CAN over TCP on 127.0.0.1" in text  # the default transport
    assert "  headroom: " in text and f"x at speed {float(speed):g}x (measured before the run" in text
    assert "the pipeline received every one of them" in text
    assert "warning: none" in text and "stayed upright" in text
    assert "  predictor parameters at the end: " in text  # from the priors: which were identified
    assert f"recording: {out}" in text and out.stat().st_size > 0
    # the status line (not a terminal here: one line per simulated second, and the last one)
    status = [ln for ln in cap.err.splitlines() if ln.startswith("t ")]
    assert len(status) >= 2 and "/1.20 s" in status[-1]
    doc = json.loads(js.read_text())
    for k, typ in KEYS.items():
        assert isinstance(doc[k], typ), (k, doc[k])
    assert set(doc["warning_latency_ms"]) >= {"p50", "p99"}
    assert doc["dropped"] == 0 and doc["frames_received"] == doc["frames_sent"] > 0
    assert set(doc["predictions"]["param_sources"].values()) <= {"identified", "held", "start"}
    assert doc["rolled_over"] is False and doc["output"] == str(out)
    assert doc["transport"] == "tcp" and doc["headroom"]["headroom"] >= 1.0 and doc["headroom"]["speed"] == float(speed)
    # SCHED_FIFO 10 by default where the machine permits it, else the default policy and why
    sc = doc["scheduling"]
    if fifo_permitted():
        assert sc == {"policy": "fifo", "priority": 10} and "scheduling: SCHED_FIFO priority 10" in text
    else:
        assert sc["policy"] == "default" and "not permitted" in sc["reason"] and "default time sharing" in text


def test_json_on_stdout_moves_the_words_to_stderr(tmp_path, monkeypatch, speed, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--scenario", "paper", "--duration", "0.5", "--speed", speed, "--can", "virtual",
                 "--no-headroom-check", "--quiet", "--json", "-"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["scenario"] == "paper" and doc["output"] is None and doc["headroom"] is None
    assert "vdps bench: paper" in cap.err and not [ln for ln in cap.err.splitlines() if ln.startswith("t ")]
    assert not list(tmp_path.iterdir())  # no -o: no recording


def test_a_parameter_file_that_had_not_settled_the_cornering_stiffnesses_keeps_the_warning_waiting(
        tmp_path, speed, capsys):
    """``--params`` starts the pipeline from the file's values; the warning is valid at once only
    for the problems the file settled (its ``meta.status``; pipeline.node's rule): cornering
    "model mismatch" there waits for the pipeline's own identification, as from the priors."""
    from vdps_hil.identification.config import PROBLEM_NAMES
    from vdps_hil.identification.persistence import save_params
    from vdps_hil.model.params import load_vehicle

    veh = load_vehicle("sedan-model")
    docs = {}
    for name, cornering in (("settled", "converged"), ("unsettled", "model mismatch")):
        f = tmp_path / f"{name}.json"
        save_params(f, veh.params, veh, meta={"status": {**{n: "converged" for n in PROBLEM_NAMES},
                                                         "cornering": cornering}})
        assert main(["bench", "--scenario", "paper", "--duration", "0.8", "--speed", speed, "--can", "virtual",
                     "--no-headroom-check", "--quiet", "--params", str(f), "--json", "-"]) == 0
        cap = capsys.readouterr()
        docs[name] = (json.loads(cap.out), cap.err)
    settled, unsettled = docs["settled"][0], docs["unsettled"][0]
    assert settled["predictions"]["require_converged"] == [] and "--params:" not in docs["settled"][1]
    assert "params_unsettled" not in settled
    assert unsettled["predictions"]["require_converged"] == ["cornering"]
    assert unsettled["params_unsettled"] == {"cornering": "model mismatch"}
    assert "--params: not identified when saved: cornering model mismatch; the warning waited" in docs["unsettled"][1]
    # 0.8 s cannot converge the cornering problem (held 1 s): no valid frame; from the settled file
    # the frames are valid from the first prediction on
    assert unsettled["warning_status"]["valid"] == 0 and unsettled["warning_status"]["not_converged"] > 0
    assert settled["warning_status"]["valid"] > 0


def _doc(**over) -> dict:
    base = {"scenario": "fishhook-suv", "vehicle": "suv", "model": "suv-model", "transport": "virtual",
            "can": {"pipeline_spec": "virtual:x"}, "speed": 1.0, "react": True, "duration_s": 7.0,
            "wall_time_s": 7.01, "realtime_factor": 0.999, "frames_sent": 10, "imu_packets_sent": 5,
            "lines_sent": 3, "dropped": 0, "late_sends": 1, "sends": 20, "late_tolerance_ms": 2.0,
            "lead_reference": "open_loop", "first_warning_t_s": 1.13, "warning_lead_time_s": 2.59,
            "point_of_no_return_t_s": 3.72, "warning_lead_to_tipup_s": 1.08, "tip_up_t_s": 2.21,
            "ecu": {"frames": {"accepted": 300, "timeouts": 0}, "intervention_t_s": 1.13, "actuation_t_s": 1.23,
                    "full_brake_t_s": 1.53, "actuator": {"delay_s": 0.1, "brake_torque_full_nm_per_wheel": 2500.0}},
            "rolled_over": False, "truth_events": [], "max_abs_roll_deg": 7.2,
            "warning_latency_ms": {"p50": 1.3, "p99": 25.0}, "output_cycles": 29514, "pipeline_keeps_up": True,
            "output": "bench.mcap", "deadline_misses": {"samples": 0},
            "headroom": {"headroom": 3.14, "speed": 1.0, "simulator_cost_s_per_s": 0.1, "pipeline_cost_s_per_s": 0.2}}
    base.update(over)
    return base


def test_the_words_say_warning_time_lead_ecu_action_outcome_and_recording():
    text = "\n".join(describe(_doc()))
    assert "first VDPS_Warning of level >= 2 on the bus at 1.13 s" in text
    assert "2.59 s before the point of no return (without the ECU's reaction, at 3.72 s)" in text
    assert "1.08 s before tip-up" in text
    assert "cut the drive torque and started braking at 1.23 s (100 ms dead time)" in text
    assert "full brakes (2500 N m per wheel) at 1.53 s" in text
    assert "stayed upright" in text and "without the ECU it would have rolled over at 3.72 s" in text
    assert "recording: bench.mcap" in text
    assert "headroom: 3.1x at speed 1x (measured before the run: simulator 100 ms + pipeline 200 ms" in text
    assert "deadline misses" not in text
    late = "\n".join(describe(_doc(deadline_misses={"samples": 812, "episodes": 3, "deadline_ms": 100.0,
                                                    "first_t_s": 1.25})))
    assert ("deadline misses: the pipeline fell more than 100 ms behind 3 time(s) and skipped 812 samples "
            "(first at 1.25 s); its warnings said 'sensor missing' meanwhile") in late
    assert "predictions:" not in text and "estimate consistency" not in text
    inc = "\n".join(describe(_doc(warning_unhealthy={"inconsistent": 20, "imu_missing": 0, "imu_fault": 0},
                                  warning_status={"valid": 352, "not_converged": 50, "sensor_missing": 0, "fault": 20})))
    assert ("estimate consistency: the innovation monitor found the estimate inconsistent with the fixes in 20 of "
            "422 warning cycles; their frames said 'fault'") in inc
    pred = "\n".join(describe(_doc(predictions={"worker": "process", "latency_s": 0.02, "started": 15, "used": 13,
                                                "dropped": 2, "failed": 0})))
    assert ("predictions: 2 of 15 dropped at their deadline (20 ms of bus time), 0 failed; the warning frames "
            "said 'fault' until the next prediction was used") in pred
    rolled = "\n".join(describe(_doc(react=False, rolled_over=True, lead_reference="this_run", dropped=4,
                                     pipeline_keeps_up=False, output=None)))
    assert "ROLLED OVER" in rolled and "4 were LOST" in rolled and "listening only" in rolled
    assert "did NOT keep up" in rolled and "recording:" not in rolled
    # no valid frame at all for want of convergence (a run from the priors): said, with the way out
    waited = "\n".join(describe(_doc(first_warning_t_s=None, warning_status={"valid": 0, "not_converged": 370,
                                                                              "sensor_missing": 1, "fault": 0},
                                      predictions={"require_converged": ["cornering"]})))
    assert ("warning: none -- the pipeline never sent a valid VDPS_Warning of level >= 2; no frame was valid: "
            "'not converged' in 370 of 371 warning cycles (the warning waited for cornering: from the model file's "
            "priors, or a parameter file that had not settled it; [warning] require_converged and "
            "converged_hold_s)") in waited
    # a parameter file that had not settled what the warning waits for: said as vdps replay says it
    assert "--params:" not in waited
    unsettled = "\n".join(describe(_doc(params="p.json", params_unsettled={"cornering": "model mismatch"},
                                         params_not_identified=None, predictions={"require_converged": ["cornering"]})))
    assert ("--params: not identified when saved: cornering model mismatch; the warning waited for cornering to be "
            "identified here") in unsettled
    some = "\n".join(describe(_doc(first_warning_t_s=None, warning_status={"valid": 5, "not_converged": 365})))
    assert "never sent a valid VDPS_Warning of level >= 2\n" in some + "\n" and "no frame was valid" not in some
    lifted = copy.deepcopy(_doc(truth_events=[{"kind": "tip_up", "t_s": 2.21}]))
    assert "after lifting two wheels" in "\n".join(describe(lifted))


@pytest.mark.parametrize("args, words", [
    (["--scenario", "no-such-scenario"], "unknown scenario"),
    (["--speed", "0"], "--speed must be a positive number"),
    (["--speed", "x"], "--speed must be a positive number or 'auto'"),
    (["--speed", "1e9", "--no-headroom-check"], "--speed must be at most 1000"),  # was: 60 s, then "did not stop"
    (["--seed", "-1"], "not in the range x>=0"),
    (["--speed", "auto", "--no-headroom-check"], "--speed auto needs the headroom measurement"),
    (["--can", "nonsense"], "is not INTERFACE:CHANNEL"),
    (["--can", "nosuchbus:0"], "unknown CAN interface"),
    (["--can", "pty", "--sim-can", "virtual:x"], "--sim-can applies"),
    (["--vehicle", "sedan-model"], "truth file is needed"),
    (["--fault", "no_such_fault"], "unknown fault"),
    (["-o", "/no/such/dir/x.mcap"], "does not exist"),
    (["--calibrate", "no-such-scenario", "--quiet"], "--calibrate no-such-scenario"),
    (["--calibrate", "paper", "--params", "p.json"], "not both"),
])
def test_errors_are_one_line_with_exit_status_2(args, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["bench", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("vdps: error:") and words in err
    assert not list(tmp_path.iterdir())


def test_help_shows_examples_and_the_transports(capsys):
    assert main(["bench", "--help"]) == 0
    out = capsys.readouterr().out
    assert "vdps bench --react -o bench.mcap" in out and "socketcan:vcan0" in out and "127.0.0.1" in out


def test_calibrate_starts_the_pipeline_from_a_calibration_drive(tmp_path, speed, capsys):
    """``--calibrate paper``: the same SUV first drives the paper's scenario offline, the chain
    identifies its parameters, and the bench's pipeline starts from them, so its warnings are
    valid from the start (``make run`` uses this). 1.5 s of the fishhook."""
    js = tmp_path / "b.json"
    rc = main(["bench", "--calibrate", "paper", "--duration", "1.5", "--speed", speed, "--no-headroom-check",
               "--quiet", "--json", str(js)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "calibration: pipeline started from the parameters identified on 'paper'" in text
    doc = json.loads(js.read_text())
    assert doc["calibration"]["scenario"] == "paper" and doc["calibration"]["converged"]["cornering"]
    # valid from the first prediction on: only a frame sent before the estimator's first
    # estimate may say "sensor missing" (from the priors about 240 frames say "not converged").
    # Three counted mechanisms may make frames non-valid meanwhile, each by design: the machine's
    # load made the pipeline skip samples ("sensor missing"), a prediction was dropped at its
    # deadline ("fault" until the next is used), or the innovation monitor found the estimate
    # inconsistent with the fixes ("fault"; issue 20) -- then still most frames are valid (from
    # the priors none is)
    n, bad = doc["warning_frames_accepted"], doc["warning_frames_not_valid"]
    counted = (doc["deadline_misses"]["samples"] + doc["predictions"]["dropped"] + doc["predictions"]["failed"]
               + doc["warning_unhealthy"]["inconsistent"])
    assert doc["predictions"]["used"] > 0
    assert doc["params"] is not None and 2 < n and bad <= (n // 2 if counted else 2), (
        doc["deadline_misses"], doc["warning_status"], doc["predictions"], doc["warning_unhealthy"])


def test_speed_auto_runs_at_the_fastest_speed_with_twice_the_measured_headroom(tmp_path, capsys):
    """``--speed auto`` (``make run``): the headroom measured at 1x, the run at the speed with
    WARN_BELOW (2x) headroom, never faster than real time; the summary restates the headroom at
    the speed run."""
    from vdps_hil.hil.headroom import WARN_BELOW

    js = tmp_path / "b.json"
    assert main(["bench", "--scenario", "paper", "--duration", "1", "--speed", "auto", "--can", "virtual",
                 "--json", str(js)]) == 0
    cap = capsys.readouterr()
    doc = json.loads(js.read_text())
    h = doc["headroom"]
    assert 0 < doc["speed"] <= 1.0 and h["speed"] == doc["speed"]
    # the speed is rounded to two digits: 2x headroom within that rounding, or real time with more
    assert h["headroom"] >= WARN_BELOW * 0.94 and (doc["speed"] == 1.0 or h["headroom"] <= WARN_BELOW * 1.06)
    assert f"--speed auto: {doc['speed']:g}x" in cap.err
    assert doc["duration_s"] == pytest.approx(1.0) and doc["dropped"] == 0
