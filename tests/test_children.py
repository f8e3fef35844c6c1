"""Tests of vdps_hil.app.children: Python children never import from the working directory.
Real interpreters, real process pools, modules planted in the working directory."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import subprocess
import sys

from planted_modules import markers, plant

from vdps_hil.app.children import (BLAS_THREAD_VARIABLES, PACKAGE_ROOT, child_environ, isolate_spawned_children,
                                   one_blas_thread_per_child, python_module_command)


def _plus_one(x: int) -> int:
    return x + 1


def _blas_probe() -> tuple[dict, int]:
    """In a spawned child: its BLAS thread variables, and the threads importing numpy started
    (OpenBLAS starts its pool when it loads: one thread fewer than its thread count)."""
    import sys

    assert "numpy" not in sys.modules
    before = len(os.listdir("/proc/self/task"))
    import numpy as np

    np.ones((64, 64)) @ np.ones((64, 64))
    return {k: os.environ.get(k) for k in BLAS_THREAD_VARIABLES}, len(os.listdir("/proc/self/task")) - before


def _spawned_blas_probe() -> tuple[dict, int]:
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
        return ex.submit(_blas_probe).result(timeout=120)


def test_plain_python_m_would_import_the_planted_module(tmp_path):
    """The threat is real here: ``python -m json.tool`` imports ./json.py (a check that the
    planted modules work, so the tests below can fail)."""
    d = plant(tmp_path / "cwd")
    # without safe-path mode: a test before this one in the same process may have set
    # PYTHONSAFEPATH=1 for its pools (isolate_spawned_children), which every child inherits
    env = {k: v for k, v in os.environ.items() if k != "PYTHONSAFEPATH"}
    r = subprocess.run([sys.executable, "-m", "json.tool", "--help"], cwd=d, capture_output=True, env=env)
    assert r.returncode != 0 and markers(d) == ["json"]


def test_module_command_runs_in_safe_path_mode_and_imports_nothing_from_the_cwd(tmp_path):
    d = plant(tmp_path / "cwd")
    cmd = python_module_command("json.tool", ["--help"])
    assert cmd[:3] == [sys.executable, "-P", "-m"]
    r = subprocess.run(cmd, cwd=d, capture_output=True, env=child_environ())
    assert r.returncode == 0, r.stderr
    assert markers(d) == []


def test_child_environ_is_safe_and_finds_the_package(tmp_path):
    env = child_environ({"PATH": os.environ["PATH"], "PYTHONPATH": "/x"})
    assert env["PYTHONSAFEPATH"] == "1"
    assert env["PYTHONPATH"].split(os.pathsep)[-1] == "/x"
    d = plant(tmp_path / "cwd")
    code = "import vdps_hil.app.children as c, sys; print(c.PACKAGE_ROOT); assert '' not in sys.path"
    r = subprocess.run([sys.executable, "-c", code], cwd=d, capture_output=True, text=True,
                       env=child_environ())
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == PACKAGE_ROOT and markers(d) == []


def test_spawned_pool_workers_import_nothing_from_the_cwd(tmp_path, monkeypatch):
    """multiprocessing's spawn bootstrap (``python -c ...``) imports threading and pickle before
    it sets the parent's path: without isolate_spawned_children the planted threading.py runs."""
    d = plant(tmp_path / "cwd")
    monkeypatch.setenv("PYTHONSAFEPATH", "")  # restored afterwards
    monkeypatch.chdir(d)
    isolate_spawned_children()
    assert os.environ["PYTHONSAFEPATH"] == "1"
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
        assert ex.submit(_plus_one, 1).result(timeout=120) == 2
    assert markers(d) == []


def test_spawned_children_load_numpy_with_one_blas_thread(monkeypatch):
    for k in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(k, raising=False)  # as in a user's shell; restored afterwards
    one_blas_thread_per_child()
    env, started = _spawned_blas_probe()
    assert env == {k: "1" for k in BLAS_THREAD_VARIABLES}
    assert started == 0


def test_a_blas_thread_count_the_user_set_is_kept(monkeypatch):
    """The user's own OPENBLAS_NUM_THREADS wins; with 2 the child's OpenBLAS starts a second
    thread (the probe above sees threads: it would see this one)."""
    for k in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    one_blas_thread_per_child()
    env, started = _spawned_blas_probe()
    assert env["OPENBLAS_NUM_THREADS"] == "2" and env["OMP_NUM_THREADS"] == "1"
    assert started == min(2, os.cpu_count() or 1) - 1  # OpenBLAS takes no more threads than cores
