"""Acceptance tests of the HIL bench (hil.bench): the embedded bench on the rollover scenario
loses nothing (senders' and receivers' counts, sequence counters), warns >= 1 s before the point
of no return and rolls over without the ECU but not with it; no warning on paper-left-turn; the
pipeline in its own process over the loopback-only TCP transport (and the slcan pty); the
estimates of a live run are bit-identical to replaying its recording in the recorded input
order; every socket the bench listens on is bound to 127.0.0.1. The rollover runs start the
pipeline from parameters identified on a calibration drive of the same SUV (``--params``, as a
car after its first drive): from the model file's priors the system's validity rule keeps every
frame "not converged" through the 3.7 s fishhook (the cornering problem has not converged).

The runs go at a speed this machine supports now (``ci_speed``): 1x, or the speed at which the
bench's own probe (``hil.headroom``, measured once per module) leaves 2x headroom when that is
lower (a loaded machine); every physical assertion is on the simulated time axis, so it holds at
any speed. A rollover run that skipped input all the same (load that came after the probe) is
checked for counting and flagging its skips and run again slower (``supported_run``). A pipeline given a quarter of the CPU it needs skips its own work, counts it and stays
within a few deadlines of its input."""

from __future__ import annotations

import json
import math

import pytest

from vdps_hil.app.est_topics import est_docs
from vdps_hil.hil.bench import Bench
from vdps_hil.hil.bench_config import BenchConfig, BenchError, make_system
from vdps_hil.hil.node import INPUT_ORDER_METADATA, input_order_samples
from vdps_hil.record.input_order import read_input_order, recorded_drops
from vdps_hil.hil.transports import listening_sockets
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.profiles import load_profile

def assert_nothing_lost(d: dict) -> None:
    assert d["frames_sent"] > 0 and d["frames_received"] == d["frames_sent"]
    assert d["lines_sent"] > 0 and d["lines_received"] == d["lines_sent"]
    assert d["imu_packets_sent"] > 0 and d["imu_packets_received"] == d["imu_packets_sent"]
    assert d["seq_counters"]["can_counter_breaks"] == 0 and d["seq_counters"]["imu_seq_gaps"] == 0
    assert d["dropped"] == 0 and sum(d["dropped_at_device"].values()) == 0
    assert d["rejected"] == {"can": 0, "imu": 0, "gnss": 0}


def _why(d: dict) -> dict:
    """What a lead-time failure needs explained: the warning episodes, the frames' statuses, the
    predictions and the deadline misses of the run."""
    return {k: d.get(k) for k in ("first_warning_t_s", "warning_episodes", "warning_status", "predictions",
                                  "deadline_misses", "warning_frames_not_valid", "speed", "realtime_factor",
                                  "slower_runs")}


@pytest.fixture(scope="module")
def headroom():
    """The bench's headroom on this machine now (``hil.headroom``), measured once per module."""
    h = Bench(BenchConfig(scenario="fishhook-suv")).measure_headroom()
    print(f"bench tests: {h.describe()}")
    return h


@pytest.fixture(scope="module")
def ci_speed(headroom) -> float:
    """1x, or the speed with 2x measured headroom when this machine has less now."""
    return min(1.0, headroom.supported_speed)


@pytest.fixture(scope="module")
def calibrated_params(tmp_path_factory):
    """Parameters the chain identifies on the paper's drive of the SUV (the paper harness's
    rollover calibration, seed 1000), saved as ``vdps replay --save-params`` does."""
    from vdps_hil.experiments.paper_chain import chain_run
    from vdps_hil.experiments.paper_tasks import ROLLOVER_CALIBRATION
    from vdps_hil.identification.persistence import save_params
    from vdps_hil.model.params import load_vehicle

    cal = chain_run(ROLLOVER_CALIBRATION, load_profile("table1-susp1k"), 1000, model="suv-model",
                    truth_vehicle="suv-truth", predict=False, ident_report_period_s=1.0)
    path = tmp_path_factory.mktemp("params") / "suv.json"
    idf = cal["identifier"]
    status = {n: st.status for n, st in idf.problem_status.items()}
    assert status["cornering"] == "converged", status  # else the bench's warning would wait for it
    save_params(path, idf.params, load_vehicle("suv-model"), meta={"status": status})
    return str(path)


SLOWER_TRIES = 2
"""Runs at half the speed after a run the machine did not support (``supported_run``)."""


def supported_run(make_config, speed: float, status=None) -> dict:
    """The bench run of ``make_config(speed)``, again at half the speed (at most
    :data:`SLOWER_TRIES` times) while a run counts deadline misses: the probe's headroom holds for
    the load it saw, and other work on a shared machine (the real-time phase's second pytest
    process) can stall the pipeline later. A stall past the deadline skips input, counted, and the
    frames say "sensor missing" for the IMU monitor's settle time after it (a 0.2 s stall at 1.2 s
    cost 0.6 s of warning lead, measured 2026-12-07), so the lead-time assertions are about a run
    the machine kept up with. Every run that missed is checked for what it must still do: its
    skips counted per kind and flagged on the bus. Returns the last run's JSON with
    ``"slower_runs"``: the speeds and miss counts of the runs before it."""
    tried = []
    for _ in range(SLOWER_TRIES + 1):
        d = Bench(make_config(speed)).run(status).to_json()
        m = d["deadline_misses"]
        assert m["samples"] == sum(m["by_kind"].values())
        if m["samples"] == 0:
            break
        assert d["warning_status"]["sensor_missing"] > 0, (m, d["warning_status"])
        print(f"bench tests: {m['samples']} samples skipped at {speed:.3g}x (load the probe did not see); "
              f"again at {speed / 2:.3g}x")
        tried.append({"speed": speed, "skipped": m["samples"]})
        speed /= 2
    d["slower_runs"] = tried
    return d


@pytest.fixture(scope="module")
def rollover_run(tmp_path_factory, calibrated_params, ci_speed):
    out = tmp_path_factory.mktemp("bench") / "fishhook.mcap"
    seen = []

    def status(s):
        s["listening"] = listening_sockets(s["pids"]["simulator"])
        seen.append(s)

    def config(speed):
        seen.clear()
        if out.exists():
            out.unlink()
        return BenchConfig(scenario="fishhook-suv", speed=speed, output=str(out), params=calibrated_params)

    return supported_run(config, ci_speed, status), out, seen


def test_embedded_bench_loses_nothing_warns_early_and_rolls_over_without_the_ecu(rollover_run, ci_speed):
    d, _, seen = rollover_run
    assert d["transport"] == "virtual" and not d["react"] and d["params"]
    assert d["speed"] == ci_speed / 2 ** len(d["slower_runs"])
    assert_nothing_lost(d)
    # at a supported speed nothing is skipped (a run that skipped was run again slower, its skips
    # counted and flagged: supported_run)
    assert d["deadline_misses"]["samples"] == 0, _why(d)
    assert d["rolled_over"] and d["stop_reason"] == "point_of_no_return"
    assert d["lead_reference"] == "this_run"
    assert d["point_of_no_return_t_s"] == pytest.approx(3.72, abs=0.02)
    assert d["warning_lead_time_s"] >= 1.0, _why(d)
    assert d["warning_lead_to_tipup_s"] == pytest.approx(d["warning_lead_time_s"] - (3.72 - 2.21), abs=0.02)
    assert d["warning_frames_accepted"] == d["warning_frames"] == d["warning_frames_on_bus"] > 0
    assert d["ecu"]["frames"]["crc_mismatch"] == 0 and d["ecu"]["intervention_t_s"] is None
    # timing is defined over every pipeline cycle (one per sample handled)
    assert d["output_cycles"] >= 1000 and d["output_cycles_unmatched"] == 0
    for k in ("p50", "p99"):
        assert math.isfinite(d["warning_latency_ms"][k]) and d["warning_latency_ms"][k] >= 0
    assert d["warning_latency_ms"]["p50"] <= d["warning_latency_ms"]["p99"] <= d["warning_latency_ms"]["max"]
    assert d["sends"] > 0 and 0 <= d["late_sends"] <= d["sends"]
    assert d["realtime_factor"] > 0.5 * d["speed"]
    # the status line saw the run progress and end; the embedded bench listens on no network
    # socket but loopback
    assert seen[-1]["final"] and seen[-1]["frames_sent"] == d["frames_sent"]
    assert all(addr == "127.0.0.1" for s in seen for addr, _ in s["listening"])
    assert {"t_s", "roll_deg", "warning_level", "late_sends"} <= set(seen[0])


def test_recording_has_the_standard_layout(rollover_run):
    d, out, _ = rollover_run
    with RecordingReader(out) as r:
        topics = r.topics()
        md = r.metadata()
        raw = list(r.iter_raw_can("vdps"))
    for t in ("/raw/can/vdps", "/raw/serial/imu", "/raw/serial/gnss", "/decoded/imu/imu", "/est/state",
              "/est/can/vdps", "/est/prediction", "/truth/state", "/truth/events"):
        assert t in topics, t
    rx = [m for _, m in raw if m.is_rx]
    tx = [m for _, m in raw if not m.is_rx]
    assert len(rx) == d["frames_received"] and len(tx) == d["warning_frames"]
    assert all(m.arbitration_id == 0x080 for m in tx)
    assert {"truth.drive", "vdps.health", INPUT_ORDER_METADATA, "hil.bench"} <= set(md)
    assert json.loads(md["hil.bench"]["result"])["frames_sent"] == d["frames_sent"]
    assert topics["/truth/state"].count >= 370  # 100 Hz to 3.72 s


def test_live_estimates_are_bit_identical_to_a_replay_in_the_recorded_input_order(rollover_run, calibrated_params):
    _, out, _ = rollover_run
    with RecordingReader(out) as r:
        samples, settings = read_input_order(r)
        live = {topic: [(t, doc) for _, t, doc in r.iter_messages([topic])]
                for topic in ("/est/state", "/est/prediction", "/est/ident")}
    assert not any(s.source.startswith("/truth") or s.kind.startswith("truth") for s in samples)
    p = load_profile("table1-susp1k")
    # the live pipeline predicted in a worker and dropped late predictions; the replay drops the same
    assert settings["prediction"]["worker"] == "process" and settings["prediction"]["deadline"] == "drop"
    system = make_system("suv-model", p.suspension.rate_hz, p.suspension.sigma_m, calibrated_params,
                         drops=recorded_drops(settings))
    replayed: dict = {k: [] for k in live}
    for s in samples:
        for o in system.handle(s):
            for topic, t, vals, sig in est_docs(o):
                if topic in replayed:
                    replayed[topic].append((t, vals, sig))
    for topic in live:
        assert len(live[topic]) == len(replayed[topic]) > 0, topic
        for (t1, doc), (t2, vals, sig) in zip(live[topic], replayed[topic]):
            assert t1 == t2
            # JSON keeps the shortest exact repr of a double: equal floats are equal bits
            assert doc["values"] == {k: (None if isinstance(v, float) and math.isnan(v) else v)
                                     for k, v in vals.items()}


def test_with_react_the_ecu_brakes_and_the_suv_stays_upright(calibrated_params, ci_speed):
    d = supported_run(lambda speed: BenchConfig(scenario="fishhook-suv", speed=speed, react=True,
                                                params=calibrated_params), ci_speed)
    assert_nothing_lost(d)
    assert not d["rolled_over"] and d["stop_reason"] == "duration" and d["duration_s"] == pytest.approx(7.0)
    e = d["ecu"]
    assert e["react"] and e["intervention_t_s"] is not None and e["late_actuations"] == 0
    assert e["actuation_t_s"] == pytest.approx(e["intervention_t_s"] + 0.1)
    assert e["full_brake_t_s"] == pytest.approx(e["actuation_t_s"] + 0.3)
    # the lead time is taken to the point of no return of the same drive without the ECU
    assert d["lead_reference"] == "open_loop" and d["point_of_no_return_t_s"] == pytest.approx(3.72, abs=0.02)
    assert d["warning_lead_time_s"] >= 1.0, _why(d)
    assert d["max_abs_roll_deg"] < 20.0


def test_no_warning_on_paper_left_turn(ci_speed):
    d = Bench(BenchConfig(scenario="paper-left-turn", speed=ci_speed)).run().to_json()
    assert_nothing_lost(d)
    assert not d["rolled_over"] and d["truth_events"] == []
    assert d["warning_frames_accepted"] > 0  # the warning is on the bus, 50 Hz ...
    assert math.isnan(d["first_warning_t_s"]) and d["false_alarms"] == 0  # ... never at level >= 2
    assert d["ecu"]["first_warning_t_s"] is None and d["ecu"]["max_level"] < 2
    # from the priors: "not converged" until the cornering problem converges (the switch to
    # valid is tested deterministically on a replay in test_pipeline_node/test_replay_cmd; in this
    # real-time run under heavy load it came after the end once: 594 of 594 frames not valid)
    assert 0 < d["warning_frames_not_valid"] <= d["warning_frames_accepted"]


def test_cross_process_bench_over_loopback_tcp(calibrated_params, ci_speed):
    """The pipeline in its own process (python -m vdps_hil.hil.child), CAN over the socketcand
    protocol on 127.0.0.1 (the transport tools/bench_hil.py chose), serial on ptys; while it runs
    every socket either process listens on is on 127.0.0.1."""
    sockets = []

    def status(s):
        for pid in set(s["pids"].values()):
            sockets.extend(listening_sockets(pid))

    d = supported_run(lambda speed: BenchConfig(scenario="fishhook-suv", speed=speed, can="tcp",
                                                params=calibrated_params), ci_speed, status)
    assert d["transport"] == "tcp" and d["can"]["listen"].startswith("127.0.0.1:")
    assert_nothing_lost(d)
    assert d["rolled_over"] and d["warning_lead_time_s"] >= 1.0, _why(d)
    assert d["output_cycles"] >= 1000 and d["pipeline"]["errors"] == []
    assert sockets and all(addr == "127.0.0.1" for addr, _ in sockets), sockets


def test_cross_process_bench_over_slcan_on_a_pty(tmp_path, monkeypatch, ci_speed):
    """Run where modules named json, threading, numpy, ... lie in the working directory: the
    pipeline process (python -P -m vdps_hil.hil.child) imports none of them."""
    from planted_modules import markers, plant

    monkeypatch.chdir(plant(tmp_path / "cwd"))
    out = tmp_path / "pty.mcap"
    d = Bench(BenchConfig(scenario="paper", duration_s=1.5, speed=ci_speed, can="pty", output=str(out))).run()
    d = d.to_json()
    assert markers(tmp_path / "cwd") == []
    assert d["transport"] == "pty" and d["can"]["pipeline_spec"].startswith("slcan:/dev/pts/")
    assert_nothing_lost(d)
    with RecordingReader(out) as r:  # the child's part and the truth merged into one file
        topics = r.topics()
        assert "/truth/state" in topics and "/est/state" in topics and "/raw/serial/imu" in topics
        assert len(input_order_samples(r)) == sum(v.count for k, v in topics.items() if k.startswith("/decoded/"))


@pytest.mark.parametrize("kw, words", [
    ({"scenario": "no-such-scenario"}, "unknown scenario"),
    ({"speed": 0.0}, "--speed must be a positive number"),
    ({"can": "nonsense"}, "is not INTERFACE:CHANNEL"),
    ({"can": "tcp", "sim_can": "virtual:x"}, "--sim-can applies"),
    ({"faults": ("no_such_fault",)}, "unknown fault"),
    ({"vehicle": "sedan-model"}, "truth file is needed"),
    ({"params": "/nonexistent/p.json"}, "cannot read"),
    ({"rt_priority": 100}, "--rt-priority must be an integer 0..99"),
])
def test_bad_configurations_are_one_line_errors(kw, words):
    with pytest.raises(BenchError) as e:
        Bench(BenchConfig(**kw))
    assert words in str(e.value) and "\n" not in str(e.value)


def test_an_injected_fault_shows_in_the_sequence_counters_not_as_a_bench_loss(ci_speed):
    d = Bench(BenchConfig(scenario="paper", duration_s=1.0, speed=ci_speed,
                          faults=("dropped_frames:fraction=0.05",))).run().to_json()
    assert d["faults"] == ["dropped_frames:fraction=0.05"]
    assert d["dropped"] == 0 and d["frames_received"] == d["frames_sent"]  # the wires lost nothing
    assert d["seq_counters"]["can_counter_breaks"] > 0  # the pipeline sees the frames the fault removed


def test_a_pipeline_short_of_cpu_skips_its_own_work_counts_it_and_says_so(headroom, calibrated_params):
    """At 8x the supported speed, and at least 8x real time (a quarter of the CPU the pipeline
    needs, or less), the embedded pipeline misses its deadline: it skips samples (counted per
    kind), the cycles it handles stay within a few deadlines of their input instead of falling
    seconds behind (the drive is 2.5 s), and its warnings say "sensor missing" (the skipped IMU
    span is an outage to the estimator). Started from identified parameters, so "not converged"
    does not hide the status. (8 x the speed capped at 1x was no overload where the headroom at
    1x is near 1: 4.2x on a machine with 1.1x then missed no deadline in one run of two.)"""
    speed = 8.0 * max(1.0, headroom.supported_speed)
    d = Bench(BenchConfig(scenario="fishhook-suv", duration_s=2.5, speed=speed,
                          params=calibrated_params)).run().to_json()
    m = d["deadline_misses"]
    assert m["samples"] > 0 and m["episodes"] >= 1 and m["by_kind"]["imu"] > 0 and m["deadline_ms"] == 100.0
    assert m["samples"] == sum(m["by_kind"].values()) and not d["pipeline_keeps_up"]
    assert d["warning_latency_ms"]["p99"] <= 3 * m["deadline_ms"]
    assert d["warning_status"]["sensor_missing"] > 0
    assert d["output_cycles"] > 0 and d["output_cycles_unmatched"] == 0


def test_the_pipeline_process_never_imports_the_simulator():
    """python -m vdps_hil.hil.child (the pipeline of --can tcp/pty) cannot reach truth: it does
    not even import vdps_hil.sim."""
    import subprocess
    import sys

    code = ("import sys, vdps_hil.hil.child, vdps_hil.hil.node, vdps_hil.pipeline.node; "
            "print('\\n'.join(m for m in sys.modules if m.startswith('vdps_hil')))")
    mods = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          check=True).stdout.split()
    assert "vdps_hil.hil.child" in mods and "vdps_hil.pipeline.node" in mods
    assert not [m for m in mods if m == "vdps_hil.sim" or m.startswith("vdps_hil.sim.")]
