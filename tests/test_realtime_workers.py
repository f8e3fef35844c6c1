"""tools/realtime_workers.py: the real-time phase of ``make test`` runs a module per idle core,
measured from /proc/stat, never fewer than one worker nor more than the cores."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

import pytest

from conftest import REPO

TOOL = REPO / "tools" / "realtime_workers.py"


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("realtime_workers", TOOL)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_one_worker_per_idle_core_between_one_and_the_cores(tool):
    assert tool.workers(2.0, 2, 0.8) == 2
    assert tool.workers(1.6, 2, 0.8) == 2  # 80 % of each core idle counts it
    assert tool.workers(1.59, 2, 0.8) == 1  # one CPU-bound process beside the suite: one at a time
    assert tool.workers(0.0, 2, 0.8) == 1
    assert tool.workers(7.9, 4, 0.8) == 4


def test_with_every_core_busy_the_phase_runs_one_module_at_a_time(tool):
    """Real CPU-bound processes, one per core: at most half a core's worth stays idle, so one
    worker (whatever else the machine is doing, it can only be busier)."""
    n = os.cpu_count() or 1
    hogs = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(n)]
    try:
        idle = tool.idle_cores(0.5)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    assert idle < 0.5 * n
    assert tool.workers(idle, n, 0.8) == 1


def test_the_command_prints_the_number_and_says_why():
    r = subprocess.run([sys.executable, str(TOOL), "--window", "0.2"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0
    assert 1 <= int(r.stdout.strip()) <= len(os.sched_getaffinity(0))
    assert r.stderr.count("\n") == 1 and "cores idle" in r.stderr
    bad = subprocess.run([sys.executable, str(TOOL), "--free", "0"], capture_output=True, text=True, timeout=30)
    assert bad.returncode == 2 and bad.stdout == "" and bad.stderr.count("\n") == 1
