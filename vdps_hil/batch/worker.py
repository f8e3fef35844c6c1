"""What travels to a worker and back: a :class:`Task` (names and JSON-able arguments only), the
worker's :func:`execute` (a task's exception is data: ``status = "failed"`` with a one-line
error, never a stopped batch), its document ``{status, result | error, run}`` and the
:class:`Outcome` it becomes; :func:`to_jsonable` makes results plain JSON.

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

import importlib
import math
import os
import resource
import socket
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

__all__ = ["Task", "Outcome", "execute", "to_jsonable", "failure", "outcome", "one_line"]


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


def one_line(e: BaseException) -> str:
    """The first line of an exception's message."""
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
        error = {"type": type(e).__name__, "message": one_line(e)}
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



def failure(kind: str, message: str) -> dict:
    """The document of a task that failed outside the task function (a dead worker, a lost
    scheduler)."""
    return {"status": "failed", "result": None, "error": {"type": kind, "message": message},
            "run": {}}


def outcome(t: Task, doc: dict, attempts: int | None) -> Outcome:
    """The :class:`Outcome` of ``t`` from a worker's document (``attempts`` into ``run``)."""
    run = dict(doc.get("run") or {})
    if attempts is not None:
        run["attempts"] = attempts
    return Outcome(id=t.id, status=doc["status"], result=doc.get("result"), error=doc.get("error"),
                   run=run, key=t.key, meta=dict(t.meta))
