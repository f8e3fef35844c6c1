"""The bench's headroom (hil.headroom): the measurement of the bench's own drive and pipeline on
this machine, the verdict thresholds, and the refusal of a run the machine cannot keep up with
(``vdps bench``: one line, exit 2, nothing written)."""

from __future__ import annotations

import time

import pytest

from vdps_hil.cli.main import main
from vdps_hil.hil.bench import Bench
from vdps_hil.hil.bench_config import BenchConfig
from vdps_hil.hil.headroom import PROBE_SPEED, REFUSE_BELOW, WARN_BELOW, Headroom, _floor_2_digits


def test_headroom_is_one_over_speed_times_the_summed_costs_and_the_verdicts_follow_it():
    h = Headroom(speed=2.0, probe_s=1.0, sim_cost=0.05, pipeline_cost=0.15, wall_s=0.3)
    assert h.cost == pytest.approx(0.2) and h.headroom == pytest.approx(2.5)
    assert h.verdict() == "ok" and h.supported_speed == pytest.approx(1 / (WARN_BELOW * 0.2))
    assert Headroom(4.0, 1.0, 0.05, 0.15, 0.3).verdict() == "warn"  # 1.25x
    assert Headroom(6.0, 1.0, 0.05, 0.15, 0.3).verdict() == "refuse"  # 0.83x
    assert REFUSE_BELOW < WARN_BELOW
    d = h.to_json()
    assert d["headroom"] == pytest.approx(2.5) and d["verdict"] == "ok"
    assert "headroom 2.5x at speed 2x" in h.describe() and "\n" not in h.describe()


@pytest.mark.parametrize("x, floor", [(0.897, 0.89), (0.8999, 0.89), (0.9, 0.9), (0.0456, 0.045),
                                      (1.234, 1.2), (12.7, 12.0)])
def test_the_second_probe_speed_is_rounded_down_never_up(x, floor):
    """The slower probe runs at the speed with WARN_BELOW headroom rounded down to two digits:
    0.897x rounded to nearest was a 0.9x probe, as fast as the first probe's 0.9 limit (a
    loaded run, 2026-12-07)."""
    assert _floor_2_digits(x) == floor and _floor_2_digits(x) <= x


def test_the_measurement_runs_the_bench_itself_and_counts_both_sides_cpu():
    """The probe is the bench (same drive, wires and pipeline) run briefly at the run's speed
    (at most PROBE_SPEED), or slower; its costs are the CPU each side spent per simulated
    second."""
    b = Bench(BenchConfig(scenario="paper", duration_s=3.0, speed=1.0))
    w0 = time.perf_counter()
    h = b.measure_headroom(probe_s=0.5)
    wall = time.perf_counter() - w0
    assert b.headroom is h and h.probe_s == pytest.approx(0.5) and h.speed == 1.0
    # the probe ran live at the run's speed (or half of it, twice at most, when even that skipped
    # work; or again, slower, at the speed the first probe said has WARN_BELOW headroom when 1x has
    # less): 0.8 simulated s take at least 0.8 / speed of wall time. The second probe's own cost is
    # the one kept and need not say the same speed: on a loaded machine a second probe at 0.77x
    # cost 0.90 s per simulated s (supported 0.55x; fresh-clone CI, 2026-12-06), so only its being
    # slower than the first is asserted (measure_headroom: below 0.9 of it)
    first = min(b.config.speed, PROBE_SPEED)
    assert 0 < h.probe_speed <= first
    if h.probe_speed != b.config.speed:
        assert h.probe_speed in (0.5, 0.25) or h.probe_speed < 0.9 * first
    assert wall >= 0.8 / h.probe_speed and h.wall_s == pytest.approx(wall, rel=0.05)
    # both sides cost something, and no machine runs the bench a million times faster than real time
    assert 1e-6 < h.sim_cost < 100 and 1e-6 < h.pipeline_cost < 100
    assert h.headroom == pytest.approx(1.0 / (h.sim_cost + h.pipeline_cost))
    assert h.sim_cpu == h.sim_cost and h.pipeline_cpu == h.pipeline_cost
    d = h.to_json()
    assert d["pipeline_cpu_s_per_s"] == h.pipeline_cpu and d["probe_speed"] == h.probe_speed
    assert f"a {h.probe_speed:.2g}x probe run of the bench" in h.describe()


def test_a_run_the_machine_cannot_keep_up_with_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """At 1000x real time the paper drive needs 1000 simulated seconds of work per wall second:
    no 2-core machine has that headroom."""
    monkeypatch.chdir(tmp_path)
    rc = main(["bench", "--scenario", "paper", "--duration", "2", "--speed", "1000", "--quiet",
               "-o", str(tmp_path / "b.mcap")])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("vdps: error: headroom ")
    assert "below 1x the pipeline cannot keep up" in err and "--no-headroom-check" in err
    assert not list(tmp_path.iterdir())
