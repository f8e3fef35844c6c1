"""Batch engine: tasks run on a local ``dask.distributed`` cluster, on an existing Dask cluster,
on a process pool or inline, through one code path, with per-task error capture and
worker-death retries (what a task is and how a worker runs it: :mod:`vdps_hil.batch.worker`;
resume, result files and the aggregate: :mod:`vdps_hil.batch.runner`).

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
               :func:`execute` in each worker: for machines without ``distributed``. Its workers
               load numpy's BLAS with one thread (as Dask's nannies do for theirs:
               :func:`vdps_hil.app.children.spawned_pool`; a user's own
               ``OPENBLAS_NUM_THREADS`` is kept).
``inline``     :func:`execute` in this process, one task after the other (the serial reference
               the parallel results are checked against, and the easiest to debug).

The local worker processes (spawned: ``python -c ...``) start in safe-path mode
(``PYTHONSAFEPATH=1``, :func:`vdps_hil.app.children.isolate_spawned_children`): a module in the
working directory is never imported by them.

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
* **Interrupt** (Ctrl-C, a killed client): see :mod:`vdps_hil.batch.runner`.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
import uuid
from dataclasses import dataclass
from typing import Any, Iterator, Sequence

from vdps_hil.app.children import isolate_spawned_children, spawned_pool
from vdps_hil.batch.keys import tool_version
from vdps_hil.batch.worker import Outcome, Task, execute, failure, one_line, outcome

__all__ = ["EngineConfig", "Engine", "BACKENDS", "DEFAULT_ALLOWED_FAILURES", "EngineError", "dask_available"]

BACKENDS = ("dask", "processes", "inline")
DEFAULT_ALLOWED_FAILURES = 2
"""Times a task may be on a worker that dies before it is reported as failed (Dask's
``distributed.scheduler.allowed-failures``; the same limit for the process pool)."""


class EngineError(RuntimeError):
    """The engine cannot start (no such backend, scheduler unreachable): one line."""


def dask_available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


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
            isolate_spawned_children()  # spawned workers import nothing from the working directory
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
                                  f"{one_line(e)}") from None
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
                f"could not ask the workers for their vdps-hil version: {one_line(e)}")
            return
        mine = tool_version()
        self.info["worker_tools"] = sorted(set(seen.values()))
        odd = sorted(addr for addr, v in seen.items() if v != mine)
        if odd:
            self.info.setdefault("warnings", []).append(
                f"{len(odd)} worker(s) run another vdps-hil ({', '.join(sorted({seen[a] for a in odd}))}; "
                f"this client: {mine}): their results may differ from a local run")

    def _new_pool(self):
        return spawned_pool(self.config.resolved_workers())  # safe-path mode, one BLAS thread per worker

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
                yield outcome(t, execute(t.fn, t.kwargs, self.config.trace_memory, tuple(t.args)),
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
                    doc = failure("WorkerDied", f"a worker died while running this task "
                                  f"{'more than ' + str(n) + ' times' if n is not None else 'too often'}"
                                  f" (allowed-failures = {n}): {one_line(e)}")
                except Exception as e:  # noqa: BLE001 - cancelled, lost scheduler, ...
                    doc = failure(type(e).__name__, one_line(e))
                f.release()
                yield outcome(t, doc, attempts=None)
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
                                yield outcome(t, failure(
                                    "WorkerDied", f"a worker process died while running this task "
                                    f"{deaths[t.id]} times (allowed-failures = {limit})"),
                                    attempts=deaths[t.id])
                            else:
                                queue.append(t)
                            continue
                        except Exception as e:  # noqa: BLE001 - e.g. unpicklable result
                            doc = failure(type(e).__name__, one_line(e))
                        yield outcome(t, doc, attempts=deaths.get(t.id, 0) + 1)
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
