"""Tests of vdps_hil.batch.engine: parallel results equal the serial ones exactly, tasks run in
distinct worker processes, a real LocalCluster and a separately started Dask cluster run
batches, killed workers are retried, failing tasks are reported without stopping the batch,
and every socket of the cluster listens on 127.0.0.1 only (resume: test_runner).

Drives are short simulated ones (1 s, seeds 0-7); clusters are module-scoped (start-up is the
expensive part)."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vdps_hil.app.children import BLAS_THREAD_VARIABLES
from vdps_hil.batch.engine import Engine, EngineConfig
from vdps_hil.batch.keys import tool_version
from vdps_hil.batch.runner import AGGREGATE, result_path, run_batch, strip_run
from vdps_hil.batch.tasks import replay_tasks
from vdps_hil.batch.report import identified_params, parameter_flags, render_html
from vdps_hil.batch.worker import Outcome, Task

from batch_drives import HEAVY, N_DRIVES, corrupt, drives  # noqa: F401 - fixtures

try:
    import distributed
    import psutil
except ImportError:  # the optional extra 'dask'; CI must have it (these are acceptance tests)
    if os.environ.get("CI"):
        raise
    pytest.skip("distributed (pip install 'vdps-hil[dask]') not installed", allow_module_level=True)

VENV_BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def serial(drives, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    res = run_batch(replay_tasks(drives), EngineConfig(backend="inline"), out_dir=out, kind="replay")
    assert res.counts == {"total": N_DRIVES, "ok": N_DRIVES, "failed": 0}
    return res, out


@pytest.fixture(scope="module")
def local_engine():
    """A LocalCluster: 2 worker processes, scheduler and dashboard on 127.0.0.1."""
    with Engine(EngineConfig(backend="dask", workers=2, allowed_failures=1)) as eng:
        yield eng


def _listening(procs) -> list[tuple[int, str, int]]:
    out = []
    for p in procs:
        try:
            conns = p.net_connections(kind="inet")
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        out += [(p.pid, c.laddr.ip, c.laddr.port) for c in conns if c.status == psutil.CONN_LISTEN]
    return out


def _tree(pid: int) -> list:
    p = psutil.Process(pid)
    return [p] + p.children(recursive=True)


def test_the_fleet_report_flags_the_drive_where_the_mass_jumped(serial):
    agg = serial[0].aggregate
    ids = [t["id"] for t in agg["tasks"]]
    masses = [identified_params(t["result"])["mass_kg"] for t in agg["tasks"]]
    _, _, z = parameter_flags([m for m, _ in masses], [s for _, s in masses])
    assert [i for i, zi in zip(ids, z) if abs(zi) > 3] == [f"drive{HEAVY}"]
    # the identified jump is the 300 kg put on board, within 3 sigma of both drives
    others = [m for i, (m, _) in enumerate(masses) if i != HEAVY]
    jump = masses[HEAVY][0] - sorted(others)[len(others) // 2]
    assert abs(jump - 300.0) < 3 * math.hypot(masses[HEAVY][1], masses[0][1]) + 5.0
    html = render_html(agg)
    flagged = html[html.index("Drives that differ"):html.index("Failed drives")]
    assert f"drive{HEAVY}" in flagged and "mass_kg" in flagged


# ------------------------------------------------------------------------------ LocalCluster
def test_two_workers_give_the_serial_results_exactly_in_two_processes(drives, serial, local_engine,
                                                                       tmp_path):
    ser, ser_dir = serial
    par = run_batch(replay_tasks(drives), out_dir=tmp_path, kind="replay", engine=local_engine)
    assert par.counts == ser.counts
    # same JSON apart from the timing fields ("run"), aggregate and per-drive files alike
    assert strip_run(par.aggregate) == strip_run(ser.aggregate)
    for o in par.outcomes:
        a = json.loads(result_path(tmp_path, o.id).read_text())
        b = json.loads(result_path(ser_dir, o.id).read_text())
        assert strip_run(a) == strip_run(b)
        assert a["result"]["estimates_summary"]["final"] is not None  # the replay did estimate
    pids = {o.run["pid"] for o in par.outcomes}
    assert len(pids) == 2 and os.getpid() not in pids
    assert pids == set(local_engine.worker_pids())
    assert {o.run["pid"] for o in ser.outcomes} == {os.getpid()}


def test_every_listening_socket_of_the_local_cluster_is_on_localhost(local_engine):
    socks = _listening(_tree(os.getpid()))
    pids = {pid for pid, _, _ in socks}
    # scheduler + dashboard in this process, a listener (and an HTTP server) per worker process
    assert set(local_engine.worker_pids()) <= pids
    assert len(socks) >= 4
    assert all(ip == "127.0.0.1" for _, ip, _ in socks), socks
    info = local_engine.info
    assert info["scheduler"].startswith("tcp://127.0.0.1:")
    assert info["dashboard"] is None or info["dashboard"].startswith("http://127.0.0.1:")


def test_without_dashboard_the_http_servers_still_listen_on_localhost_at_free_ports():
    before = {port for _, _, port in _listening(_tree(os.getpid()))}
    with Engine(EngineConfig(backend="dask", workers=1, dashboard=False)) as eng:
        socks = [s for s in _listening(_tree(os.getpid())) if s[2] not in before]
        assert eng.info["dashboard"] is None and len(socks) >= 3
    assert all(ip == "127.0.0.1" for _, ip, _ in socks), socks
    assert 8787 not in {port for _, _, port in socks}  # never Dask's fixed default port


def test_a_worker_killed_mid_batch_has_its_task_retried(drives, serial, local_engine):
    tasks = replay_tasks(drives)
    client = local_engine.client
    killed, victims = None, set()
    outcomes: list[Outcome] = []
    for o in local_engine.run(tasks):
        outcomes.append(o)
        if killed is None:
            # a task has finished, the others are queued on the workers: kill a worker that
            # holds tasks, remembering which ones it held
            pids = client.run(os.getpid)
            addr, keys = next((a, k) for a, k in client.processing().items() if k)
            killed = pids[addr]
            victims = {k[len("vdps-"):-len("-12345678")] for k in keys}
            os.kill(killed, signal.SIGKILL)
    assert len(outcomes) == N_DRIVES and all(o.ok for o in outcomes), [o.error for o in outcomes]
    assert victims and victims <= {t.id for t in tasks}
    # the killed worker's tasks ran again elsewhere (the other worker or the restarted one)
    by_id = {o.id: o for o in outcomes}
    assert all(by_id[v].run["pid"] != killed for v in victims)
    ser = {o.id: o for o in serial[0].outcomes}
    for o in outcomes:
        assert strip_run(o.result) == strip_run(ser[o.id].result)  # a retried task: same result


def test_a_task_that_kills_every_worker_fails_after_the_allowed_failures(local_engine):
    # signal.raise_signal(SIGKILL) in the worker: the worker dies each time it runs the task;
    # allowed_failures = 1: two deaths, then the task is reported, the others complete
    tasks = [Task("killer", "signal:raise_signal", args=(int(signal.SIGKILL),)),
             Task("fine", "vdps_hil.batch.tasks:worker_info")]
    outcomes = {o.id: o for o in local_engine.run(tasks)}
    assert outcomes["killer"].status == "failed"
    assert outcomes["killer"].error["type"] == "WorkerDied"
    assert "allowed-failures = 1" in outcomes["killer"].error["message"]
    assert outcomes["fine"].ok


# ------------------------------------------------------------ a separately started cluster
@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """``dask scheduler`` and two ``dask worker`` processes started as commands, on 127.0.0.1
    (what a user does on a real cluster), allowed-failures set on the scheduler by env var."""
    d = tmp_path_factory.mktemp("cluster")
    sched_file = d / "scheduler.json"
    env = dict(os.environ, DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES="1")
    dask = os.fspath(VENV_BIN / "dask")
    log = open(d / "cluster.log", "wb")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--dashboard-address", "127.0.0.1:0", "--scheduler-file",
                               os.fspath(sched_file)], env=env, stdout=log, stderr=log)]
    try:
        # The scheduler creates its file before it writes it: poll until it parses (the
        # race failed CI once with an empty file, JSONDecodeError at char 0).
        deadline = time.monotonic() + 30
        address = None
        while address is None and time.monotonic() < deadline:
            try:
                address = json.loads(sched_file.read_text())["address"]
            except (FileNotFoundError, json.JSONDecodeError, KeyError):
                time.sleep(0.1)
        assert address, (d / "cluster.log").read_text()
        for _ in range(2):
            procs.append(subprocess.Popen(
                [dask, "worker", "--scheduler-file", os.fspath(sched_file), "--nworkers", "1",
                 "--nthreads", "1", "--host", "127.0.0.1", "--dashboard-address", "127.0.0.1:0"],
                env=env, stdout=log, stderr=log))
        client = distributed.Client(address, timeout="30s")
        client.wait_for_workers(2, timeout=60)
        client.close()
        yield address, procs
        with distributed.Client(address, timeout="10s") as c:
            c.shutdown()  # closes scheduler and workers (faster than a signal per process)
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        log.close()


def test_a_separately_started_cluster_runs_a_batch_with_a_corrupt_and_a_missing_file(
        drives, corrupt, serial, dask_cluster, tmp_path):
    address, procs = dask_cluster
    missing = os.fspath(tmp_path / "gone.mcap")
    inputs = drives[:4] + [corrupt, missing]
    res = run_batch(replay_tasks(inputs), EngineConfig(scheduler=address), out_dir=tmp_path / "out",
                    kind="replay")
    assert res.info["scheduler"] == address and res.info["workers"] == 2
    assert res.info["allowed_failures"] == 1  # read back from the scheduler
    # the workers report their tool version; a mismatch with this process is a warning (in
    # this shared development tree the source may change between client and worker start)
    assert len(res.info["worker_tools"]) == 1
    assert ("warnings" in res.info) == (res.info["worker_tools"] != [tool_version()])
    by_id = {o.id: o for o in res.outcomes}
    assert [o.id for o in res.outcomes] == ["drive0", "drive1", "drive2", "drive3", "corrupt", "gone"]
    ser = {o.id: o for o in serial[0].outcomes}
    for i in range(4):
        assert by_id[f"drive{i}"].ok
        assert strip_run(by_id[f"drive{i}"].result) == strip_run(ser[f"drive{i}"].result)
    assert by_id["corrupt"].status == "failed"
    assert by_id["corrupt"].error["type"] in ("ReplayError", "NoRawData")
    assert by_id["gone"].status == "failed"
    assert "gone.mcap" in by_id["gone"].error["message"]
    assert res.counts == {"total": 6, "ok": 4, "failed": 2}
    agg = json.loads((tmp_path / "out" / AGGREGATE).read_text())
    assert {f["id"] for f in agg["failed"]} == {"corrupt", "gone"}
    # the tasks ran in the cluster's worker processes, none in this one
    worker_pids = {p.pid for w in procs[1:] for p in _tree(w.pid)}
    assert {o.run["pid"] for o in res.outcomes if o.run.get("pid")} <= worker_pids


def test_every_listening_socket_of_the_started_cluster_is_on_localhost(dask_cluster):
    _, procs = dask_cluster
    socks = _listening([p for proc in procs for p in _tree(proc.pid)])
    assert len(socks) >= 5  # scheduler + dashboard, per worker: nanny, worker, HTTP
    assert all(ip == "127.0.0.1" for _, ip, _ in socks), socks


# ------------------------------------------------------------------------- process pool
def test_process_pool_gives_the_serial_results_and_survives_a_killed_worker(drives, serial):
    tasks = replay_tasks(drives[:4])
    ser = {o.id: o for o in serial[0].outcomes}
    before = {p.pid for p in psutil.Process().children()}
    with Engine(EngineConfig(backend="processes", workers=2)) as eng:
        outcomes = []
        for o in eng.run(tasks):
            if not outcomes:  # kill a pool worker (not the spawn resource tracker)
                kids = [p for p in psutil.Process().children() if p.pid not in before
                        and "spawn_main" in " ".join(p.cmdline())]
                os.kill(kids[0].pid, signal.SIGKILL)
            outcomes.append(o)
    assert sorted(o.id for o in outcomes) == [t.id for t in tasks]
    assert all(o.ok for o in outcomes), [o.error for o in outcomes]
    for o in outcomes:
        assert strip_run(o.result) == strip_run(ser[o.id].result)


# ------------------------------------------------------------------- errors and resume


# ------------------------------------------------------------- nothing from the working directory
@pytest.mark.parametrize("backend", ["processes", "dask"])
def test_spawned_workers_import_nothing_from_the_working_directory(backend, tmp_path, monkeypatch):
    """Started where modules named json, threading, pickle, numpy, ... lie: the spawned workers
    (``python -c ...`` bootstrap) import none of them."""
    from planted_modules import markers, plant

    cwd = plant(tmp_path / "cwd")
    monkeypatch.setenv("PYTHONSAFEPATH", "")  # as in a user's shell; restored afterwards
    monkeypatch.chdir(cwd)
    with Engine(EngineConfig(backend=backend, workers=1)) as eng:
        out = list(eng.run([Task("info", "vdps_hil.batch.tasks:worker_info")]))
    assert [o.status for o in out] == ["ok"], [o.error for o in out]
    assert markers(cwd) == []


def test_process_pool_workers_load_numpy_with_one_blas_thread(monkeypatch):
    """A pool of one worker per core: one BLAS thread each (``app.children.one_blas_thread_per_child``;
    numpy's OpenBLAS started one per core in every worker)."""
    for k in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(k, raising=False)  # as in a user's shell; restored afterwards
    with Engine(EngineConfig(backend="processes", workers=2)) as eng:
        out = list(eng.run([Task(f"info{i}", "vdps_hil.batch.tasks:worker_info") for i in range(2)]))
    assert [o.status for o in out] == ["ok", "ok"], [o.error for o in out]
    assert all(o.result["blas_threads"] == {k: "1" for k in BLAS_THREAD_VARIABLES} for o in out), out
