"""Batch engine: one task per recording (or per Monte Carlo trial), run on a local
``dask.distributed`` cluster, on an existing Dask cluster, on a process pool or inline, through
one code path, with resume, per-task error capture and worker-death retries.

Data flow::

    tasks (Task: id, "module:function", kwargs, resume key)
      -> run_batch: skip the tasks whose result file holds the same key (resume)
      -> Engine (backend) -> worker: execute(fn, kwargs) -> {status, result | error, run}
      -> as each finishes: <out>/drives/<id>.json (atomic), progress
      -> at the end: <out>/batch.json (aggregate, task order)

Backends (``EngineConfig.backend``)
-----------------------------------
``dask``       (default) a ``distributed.LocalCluster`` sized to the machine: ``workers``
               worker processes (one thread each, so one task per core), scheduler, nannies,
               workers and the HTTP dashboard listening on 127.0.0.1 only (random free ports).
               With ``scheduler="tcp://host:8786"`` the tasks go to that existing cluster
               instead (``dask scheduler`` / ``dask worker``, Kubernetes, SLURM, ...); its
               workers must see the input files at the same paths and be able to import this
               package; results come back to this process, which alone writes ``--out``.
``processes``  ``concurrent.futures.ProcessPoolExecutor`` (spawn context), the same
               :func:`execute` in each worker: for machines without ``distributed``.
``inline``     :func:`execute` in this process, one task after the other (the serial reference
               the parallel results are checked against, and the easiest to debug).

Failure model
-------------
* A task that **raises** (corrupt file, unsupported format, bad config) does not stop the
  batch: :func:`execute` catches ``Exception`` in the worker and returns
  ``status = "failed"`` with ``error = {"type", "message"}`` (one line). The others go on.
* A worker **process that dies** (killed, out of memory, segfault; a LocalCluster worker
  above its memory limit, RAM / workers by default, is restarted by its nanny) has its task
  retried on another worker. Dask: the scheduler's ``allowed-failures`` is set explicitly to
  ``EngineConfig.allowed_failures`` (default :data:`DEFAULT_ALLOWED_FAILURES` = 2, so a task
  runs at most 3 times; Dask's own default is 3); a task that was on a dying worker more often
  than that is reported as failed ("worker died ... times") instead of killing a whole
  cluster one worker after the other. For an existing cluster the scheduler's own setting
  applies (set it there: ``DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES=2 dask scheduler``);
  the engine reads it back and records it. Process pool: a dying worker breaks the pool; it is
  rebuilt and the unfinished tasks resubmitted, each task that was in flight being charged one
  failure (the pool cannot tell which of them died), with the same limit.
* **Interrupt** (Ctrl-C, a killed client): every finished task has already been written;
  the rerun computes only what is missing or whose key changed.

Timing fields
-------------
Everything that depends on the machine or the run (worker pid and host, wall and CPU time,
peak memory, attempts, whether the result was reused) is under a ``"run"`` key (per task and in the
aggregate), so two runs of the same batch give documents that are identical once ``"run"`` is
removed (``strip_run``), whatever backend or number of workers computed them.

Memory per worker: ``run.peak_rss_mib`` is the worker process's peak resident set
(``getrusage(RUSAGE_SELF).ru_maxrss``, the process's high-water mark since it started, so it
covers every task that worker ran); with ``EngineConfig.trace_memory`` also
``run.py_heap_peak_mib`` (``tracemalloc`` peak of this task alone; slows Python down ~2x, for
benchmarks).
"""

from __future__ import annotations

import concurrent.futures as cf
import importlib
import json
import math
import multiprocessing
import os
import resource
import socket
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from vdps_hil.batch.keys import tool_version

__all__ = ["Task", "Outcome", "EngineConfig", "Engine", "BatchResult", "run_batch", "execute",
           "strip_run", "result_path", "BACKENDS", "DEFAULT_ALLOWED_FAILURES", "EngineError",
           "dask_available", "to_jsonable"]

BACKENDS = ("dask", "processes", "inline")
DEFAULT_ALLOWED_FAILURES = 2
"""Times a task may be on a worker that dies before it is reported as failed (Dask's
``distributed.scheduler.allowed-failures``; the same limit for the process pool)."""

RESULT_DIR = "drives"
AGGREGATE = "batch.json"


class EngineError(RuntimeError):
    """The engine cannot start (no such backend, scheduler unreachable): one line."""


def dask_available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


# ---------------------------------------------------------------------------------- tasks
@dataclass(frozen=True)
class Task:
    """One unit of work. ``fn`` is ``"module:function"`` (imported in the worker, so nothing but
    names and JSON-able arguments travel); ``kwargs`` its keyword arguments; ``key`` the resume
    key (``keys.task_key``; None: never reused); ``meta`` is copied into the result document
    (e.g. the input path); ``args`` positional arguments; ``cost`` orders submission (largest
    first: the long drives do not end up alone at the end of the batch)."""

    id: str
    fn: str
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    key: str | None = None
    args: tuple = ()
    meta: Mapping[str, Any] = field(default_factory=dict)
    cost: float = 0.0


@dataclass
class Outcome:
    """What became of one task: ``status`` "ok" or "failed"; ``result`` (the task function's
    dict) or ``error`` ({"type", "message"}); ``run`` (timing fields, module docstring)."""

    id: str
    status: str
    result: dict | None
    error: dict | None
    run: dict
    key: str | None = None
    meta: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_json(self) -> dict:
        return {"id": self.id, **self.meta, "key": self.key, "status": self.status,
                "result": self.result, "error": self.error, "run": self.run}


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return text[0] if text else ""


def _resolve(fn: str) -> Callable:
    module, _, attr = fn.partition(":")
    if not module or not attr:
        raise ValueError(f"task function {fn!r}: expected 'module:function'")
    obj = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def _peak_rss_mib() -> float:
    # ru_maxrss: kilobytes on Linux, bytes on macOS
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / (1024.0 * 1024.0) if sys.platform == "darwin" else r / 1024.0


def execute(fn: str, kwargs: Mapping[str, Any], trace_memory: bool = False, args: tuple = ()) -> dict:
    """Run one task in a worker: ``{"status", "result", "error", "run"}``. Never raises for an
    ``Exception`` of the task (it becomes ``status = "failed"`` with a one-line error)."""
    t0 = time.perf_counter()
    c0 = time.process_time()
    rss0 = _peak_rss_mib()
    if trace_memory:
        import tracemalloc
        tracemalloc.start()
    status, result, error = "ok", None, None
    try:
        result = _resolve(fn)(*args, **dict(kwargs))
        if not isinstance(result, dict):
            raise TypeError(f"task function {fn} returned {type(result).__name__}, not a dict")
        result = to_jsonable(result)
    except Exception as e:  # noqa: BLE001 - a task's failure is data, the batch goes on
        status, result = "failed", None
        error = {"type": type(e).__name__, "message": _one_line(e)}
    run = {"pid": os.getpid(), "host": socket.gethostname(),
           "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
           "peak_rss_mib": _peak_rss_mib(), "peak_rss_mib_before": rss0}
    if trace_memory:
        import tracemalloc
        run["py_heap_peak_mib"] = tracemalloc.get_traced_memory()[1] / (1024.0 * 1024.0)
        tracemalloc.stop()
    return {"status": status, "result": result, "error": error, "run": run}


def to_jsonable(o: Any) -> Any:
    """Plain JSON types: numpy scalars/arrays to Python, tuples to lists, non-finite floats to
    None (JSON has no NaN), keys to str."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, Mapping):
        return {str(k): to_jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [to_jsonable(v) for v in o]
    if hasattr(o, "tolist") and callable(o.tolist):  # numpy arrays and scalars
        return to_jsonable(o.tolist())
    if o is None or isinstance(o, (str, int, bool)):
        return o
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    return str(o)


# --------------------------------------------------------------------------------- engine
@dataclass(frozen=True)
class EngineConfig:
    """``backend`` (``BACKENDS``; None = dask when installed, else processes), ``workers``
    (None = every core), ``scheduler`` (address of an existing Dask scheduler; implies dask),
    ``allowed_failures`` (module docstring), ``dashboard`` (LocalCluster dashboard on
    127.0.0.1), ``memory_limit`` (per LocalCluster worker, Dask syntax; "auto" = RAM / workers),
    ``trace_memory`` (tracemalloc per task)."""

    backend: str | None = None
    workers: int | None = None
    scheduler: str | None = None
    allowed_failures: int = DEFAULT_ALLOWED_FAILURES
    dashboard: bool = True
    memory_limit: str | float | None = "auto"
    trace_memory: bool = False

    def resolved_backend(self) -> str:
        if self.scheduler:
            if self.backend not in (None, "dask"):
                raise EngineError(f"--scheduler needs the dask backend, not {self.backend!r}")
            return "dask"
        if self.backend is None:
            return "dask" if dask_available() else "processes"
        if self.backend not in BACKENDS:
            raise EngineError(f"unknown backend {self.backend!r} (one of {', '.join(BACKENDS)})")
        return self.backend

    def resolved_workers(self) -> int:
        if self.workers is None:
            return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                       else (os.cpu_count() or 1))
        if int(self.workers) < 1:
            raise EngineError(f"--workers must be at least 1, got {self.workers}")
        return int(self.workers)


class Engine:
    """Runs tasks; a context manager that owns its cluster or pool (started on entry, closed on
    exit). ``run(tasks)`` yields :class:`Outcome` objects as tasks finish; ``info`` describes
    the engine (backend, workers, scheduler address, dashboard, allowed failures)."""

    def __init__(self, config: EngineConfig | None = None):
        self.config = config or EngineConfig()
        self.backend = self.config.resolved_backend()
        self.info: dict[str, Any] = {"backend": self.backend,
                                     "allowed_failures": self.config.allowed_failures}
        self._cluster = None
        self._client = None
        self._pool = None

    # -- lifecycle
    def __enter__(self) -> "Engine":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        cfg = self.config
        if self.backend == "dask":
            self._start_dask()
        elif self.backend == "processes":
            self.info["workers"] = cfg.resolved_workers()
            self._pool = self._new_pool()
        else:
            self.info["workers"] = 1

    def _start_dask(self) -> None:
        cfg = self.config
        try:
            import dask
            from distributed import Client, LocalCluster
        except ImportError:
            raise EngineError("the dask backend needs 'distributed' "
                              "(pip install 'vdps-hil[dask]'); or use --backend processes") from None
        import logging
        if cfg.scheduler:
            try:
                self._client = Client(cfg.scheduler, timeout="10s")
            except (OSError, TimeoutError) as e:
                raise EngineError(f"cannot reach the Dask scheduler at {cfg.scheduler}: "
                                  f"{_one_line(e)}") from None
            self.info["scheduler"] = cfg.scheduler
            self.info["allowed_failures"] = self._client.run_on_scheduler(_scheduler_allowed_failures)
            self.info["workers"] = len(self._client.scheduler_info()["workers"])
            self.info["dashboard"] = None
            self._check_worker_versions()
            return
        n = cfg.resolved_workers()
        with dask.config.set({"distributed.scheduler.allowed-failures": cfg.allowed_failures}):
            # The scheduler always runs an HTTP server (health, metrics; the dashboard when
            # enabled): on 127.0.0.1 at a free port, never Dask's default 0.0.0.0-style ":8787".
            self._cluster = LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                scheduler_port=0, dashboard_address="127.0.0.1:0",
                worker_dashboard_address="127.0.0.1:0" if cfg.dashboard else None,
                memory_limit=cfg.memory_limit, silence_logs=logging.ERROR,
                scheduler_kwargs={"allowed_failures": cfg.allowed_failures,
                                  "dashboard": bool(cfg.dashboard)})
        self._client = Client(self._cluster)
        self.info["workers"] = n
        self.info["scheduler"] = self._cluster.scheduler_address
        self.info["dashboard"] = self._cluster.dashboard_link if cfg.dashboard else None

    def _check_worker_versions(self) -> None:
        """Every worker of an existing cluster must run this tool version (the results are
        keyed by it): the versions seen go to ``info["worker_tools"]``, a mismatch to
        ``info["warnings"]``."""
        try:
            seen = self._client.run(tool_version)
        except Exception as e:  # noqa: BLE001 - e.g. a worker without this package
            self.info.setdefault("warnings", []).append(
                f"could not ask the workers for their vdps-hil version: {_one_line(e)}")
            return
        mine = tool_version()
        self.info["worker_tools"] = sorted(set(seen.values()))
        odd = sorted(addr for addr, v in seen.items() if v != mine)
        if odd:
            self.info.setdefault("warnings", []).append(
                f"{len(odd)} worker(s) run another vdps-hil ({', '.join(sorted({seen[a] for a in odd}))}; "
                f"this client: {mine}): their results may differ from a local run")

    def _new_pool(self):
        return cf.ProcessPoolExecutor(max_workers=self.config.resolved_workers(),
                                      mp_context=multiprocessing.get_context("spawn"))

    def close(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            finally:
                self._client = None
        if self._cluster is not None:
            try:
                self._cluster.close()
            finally:
                self._cluster = None
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    @property
    def client(self):
        """The ``distributed.Client`` (dask backend), e.g. to list worker pids in tests."""
        return self._client

    def worker_pids(self) -> list[int]:
        """Process ids of the Dask workers (empty for the other backends)."""
        if self._client is None:
            return []
        return sorted(self._client.run(os.getpid).values())

    # -- running
    def run(self, tasks: Sequence[Task]) -> Iterator[Outcome]:
        """Outcomes in completion order. Tasks are submitted largest ``cost`` first."""
        order = sorted(tasks, key=lambda t: -t.cost)
        if self.backend == "dask":
            yield from self._run_dask(order)
        elif self.backend == "processes":
            yield from self._run_pool(order)
        else:
            for t in order:
                yield _outcome(t, execute(t.fn, t.kwargs, self.config.trace_memory, tuple(t.args)),
                               attempts=1)

    def _run_dask(self, tasks: Sequence[Task]) -> Iterator[Outcome]:
        from distributed import as_completed
        from distributed.scheduler import KilledWorker

        client = self._client
        token = uuid.uuid4().hex[:8]
        futures = {}
        for i, t in enumerate(tasks):
            f = client.submit(execute, t.fn, dict(t.kwargs), self.config.trace_memory, tuple(t.args),
                              key=f"vdps-{t.id}-{token}", pure=False, priority=len(tasks) - i)
            futures[f] = t
        try:
            for f in as_completed(list(futures)):
                t = futures.pop(f)
                try:
                    doc = f.result()
                except KilledWorker as e:
                    n = self.info.get("allowed_failures")
                    doc = _failed("WorkerDied", f"a worker died while running this task "
                                  f"{'more than ' + str(n) + ' times' if n is not None else 'too often'}"
                                  f" (allowed-failures = {n}): {_one_line(e)}")
                except Exception as e:  # noqa: BLE001 - cancelled, lost scheduler, ...
                    doc = _failed(type(e).__name__, _one_line(e))
                f.release()
                yield _outcome(t, doc, attempts=None)
        finally:
            for f in futures:
                f.cancel()

    def _run_pool(self, tasks: Sequence[Task]) -> Iterator[Outcome]:
        from concurrent.futures.process import BrokenProcessPool

        deaths: dict[str, int] = {}
        queue = list(tasks)
        limit = self.config.allowed_failures
        while queue:
            pending = {self._pool.submit(execute, t.fn, dict(t.kwargs), self.config.trace_memory,
                                              tuple(t.args)): t
                       for t in queue}
            queue = []
            in_flight: set[str] = set()
            broken = False
            try:
                while pending:
                    done, _ = cf.wait(pending, timeout=0.2, return_when=cf.FIRST_COMPLETED)
                    if not broken:
                        in_flight = {pending[f].id for f in pending if f.running()} or in_flight
                    for f in done:
                        t = pending.pop(f)
                        try:
                            doc = f.result()
                        except BrokenProcessPool:
                            broken = True
                            if t.id in in_flight or not in_flight:
                                deaths[t.id] = deaths.get(t.id, 0) + 1
                            if deaths.get(t.id, 0) > limit:
                                yield _outcome(t, _failed(
                                    "WorkerDied", f"a worker process died while running this task "
                                    f"{deaths[t.id]} times (allowed-failures = {limit})"),
                                    attempts=deaths[t.id])
                            else:
                                queue.append(t)
                            continue
                        except Exception as e:  # noqa: BLE001 - e.g. unpicklable result
                            doc = _failed(type(e).__name__, _one_line(e))
                        yield _outcome(t, doc, attempts=deaths.get(t.id, 0) + 1)
            finally:
                if not broken and pending:  # the consumer stopped early (interrupt)
                    for f in pending:
                        f.cancel()
            if broken:
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_pool()
                queue.sort(key=lambda t: -t.cost)


def _scheduler_allowed_failures(dask_scheduler=None) -> int | None:
    return getattr(dask_scheduler, "allowed_failures", None)


def _failed(kind: str, message: str) -> dict:
    return {"status": "failed", "result": None, "error": {"type": kind, "message": message},
            "run": {}}


def _outcome(t: Task, doc: dict, attempts: int | None) -> Outcome:
    run = dict(doc.get("run") or {})
    if attempts is not None:
        run["attempts"] = attempts
    return Outcome(id=t.id, status=doc["status"], result=doc.get("result"), error=doc.get("error"),
                   run=run, key=t.key, meta=dict(t.meta))


# ------------------------------------------------------------------------------ run_batch
@dataclass
class BatchResult:
    """Outcomes in task order, the engine's description and the aggregate document."""

    outcomes: list[Outcome]
    info: dict
    aggregate: dict

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.outcomes if not o.ok]

    @property
    def counts(self) -> dict[str, int]:
        return self.aggregate["counts"]


def result_path(out_dir: str | os.PathLike, task_id: str, subdir: str = RESULT_DIR) -> Path:
    return Path(out_dir) / subdir / f"{task_id}.json"


def _write_json_atomic(path: Path, doc: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(json.dumps(to_jsonable(doc), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _reusable(out_dir: Path | None, t: Task, subdir: str) -> Outcome | None:
    if out_dir is None or t.key is None:
        return None
    p = result_path(out_dir, t.id, subdir)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("key") != t.key or doc.get("status") != "ok":
        return None
    run = dict(doc.get("run") or {})
    run["reused"] = True
    return Outcome(id=t.id, status="ok", result=doc.get("result"), error=None, run=run,
                   key=t.key, meta=dict(t.meta))


def strip_run(doc: Any) -> Any:
    """``doc`` without any ``"run"`` entry at any depth (the timing fields)."""
    if isinstance(doc, dict):
        return {k: strip_run(v) for k, v in doc.items() if k != "run"}
    if isinstance(doc, list):
        return [strip_run(v) for v in doc]
    return doc


def run_batch(tasks: Sequence[Task], config: EngineConfig | None = None, *,
              out_dir: str | os.PathLike | None = None, kind: str = "batch",
              force: bool = False, progress=None, options: Mapping[str, Any] | None = None,
              engine: Engine | None = None, results_subdir: str = RESULT_DIR,
              aggregate_name: str | None = AGGREGATE) -> BatchResult:
    """Run ``tasks`` (ids must be unique) and write ``<out_dir>/drives/<id>.json`` per task as it
    finishes plus ``<out_dir>/batch.json`` at the end (module docstring).

    A task whose result file exists with status ok and the same key is reused (not run) unless
    ``force``. ``progress`` (``progress.Progress`` or None) is told about every outcome.
    ``options`` (JSON-able) is recorded in the aggregate. ``engine``: an already started
    engine (the caller closes it); otherwise one is made from ``config`` and closed here.
    ``results_subdir`` / ``aggregate_name``: where the per-task files and the aggregate go
    (``aggregate_name=None``: not written, e.g. one stage of a study).
    """
    ids = [t.id for t in tasks]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ValueError(f"task ids must be unique, repeated: {', '.join(dup[:5])}")
    out = None if out_dir is None else Path(out_dir)
    wall0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    outcomes: dict[str, Outcome] = {}
    todo: list[Task] = []
    for t in tasks:
        prev = None if force else _reusable(out, t, results_subdir)
        if prev is not None:
            outcomes[t.id] = prev
        else:
            todo.append(t)
    if progress is not None:
        progress.start(total=len(tasks), reused=len(tasks) - len(todo))
    info: dict[str, Any] = {}
    own = engine is None
    try:
        if todo:
            eng = engine or Engine(config)
            try:
                if own:
                    eng.start()
                info = dict(eng.info)
                if progress is not None:
                    progress.engine(info)
                for o in eng.run(todo):
                    outcomes[o.id] = o
                    if out is not None:
                        _write_json_atomic(result_path(out, o.id, results_subdir), o.to_json())
                    if progress is not None:
                        progress.update(o)
            finally:
                if own:
                    eng.close()
    finally:
        if progress is not None:
            progress.close()
    ordered = [outcomes[t.id] for t in tasks if t.id in outcomes]
    n_ok = sum(o.ok for o in ordered)
    aggregate = {
        "kind": kind, "tool": tool_version(), "options": to_jsonable(dict(options or {})),
        "counts": {"total": len(tasks), "ok": n_ok, "failed": len(ordered) - n_ok},
        "tasks": [o.to_json() for o in ordered],
        "failed": [{"id": o.id, **o.meta, "error": o.error} for o in ordered if not o.ok],
        "run": {"engine": info, "started_utc": started, "wall_s": time.perf_counter() - wall0,
                "computed": len(todo), "reused": len(tasks) - len(todo)},
    }
    if out is not None and aggregate_name:
        _write_json_atomic(out / aggregate_name, aggregate)
    return BatchResult(ordered, info, aggregate)
