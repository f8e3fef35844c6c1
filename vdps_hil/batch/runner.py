"""``run_batch``: the tasks on an :class:`~vdps_hil.batch.engine.Engine`, with resume, one result
file per task as it finishes and the aggregate document at the end.

Data flow::

    tasks (Task: id, "module:function", kwargs, resume key)
      -> run_batch: skip the tasks whose result file holds the same key (resume)
      -> Engine (backend) -> worker: execute(fn, kwargs) -> {status, result | error, run}
      -> as each finishes: <out>/drives/<id>.json (atomic), progress
      -> at the end: <out>/batch.json (aggregate, task order)

Interrupt (Ctrl-C, a killed client): every finished task has already been written; the rerun
computes only what is missing or whose key changed. Timing fields are under ``"run"``
(:mod:`vdps_hil.batch.worker`): ``strip_run`` removes them.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from vdps_hil.batch.engine import Engine, EngineConfig
from vdps_hil.batch.keys import tool_version
from vdps_hil.batch.worker import Outcome, Task, to_jsonable

__all__ = ["BatchResult", "run_batch", "strip_run", "result_path", "write_json_atomic", "RESULT_DIR", "AGGREGATE"]

RESULT_DIR = "drives"
AGGREGATE = "batch.json"


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


def write_json_atomic(path: Path, doc: dict) -> None:
    """``doc`` (plain JSON, ``to_jsonable``) to ``path`` by a rename: never half a file."""
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
                        write_json_atomic(result_path(out, o.id, results_subdir), o.to_json())
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
        write_json_atomic(out / aggregate_name, aggregate)
    return BatchResult(ordered, info, aggregate)
