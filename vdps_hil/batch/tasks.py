"""Batch tasks: what one worker does for one recording (replay, diagnose) or one Monte Carlo
trial (studies), and the builders that turn a list of files into :class:`~.engine.Task` s with
their resume keys.

Task functions run in worker processes: they take JSON-able keyword arguments (paths as
strings, option dicts), open their recording themselves and stream it (the reader yields one
message at a time, chunk by chunk; the decoder's reorder buffer holds about a second; the
system keeps no input log in a file replay), and return a JSON-able summary dict, never a
drive's time series. A task that raises becomes a failed outcome with its one-line error
(``engine.execute``); the batch goes on.

Task functions
--------------
``replay_drive(path, vehicle, options)``
    ``vdps_hil.system.replay_file`` (what ``vdps replay`` does) on one recording: estimates,
    innovations, identified parameters with sigmas, prediction summary, decoder counters.
``diagnose_drive(path, vehicle, options)``
    The workbench diagnosis of one recording (``vdps_hil.workbench``).
``worker_info()``
    A probe: the worker's tool version (a remote cluster must run the client's code).

Resume keys (``keys.task_key``): the recording's bytes, the task function and its options, the
model vehicle file, every file an option names (saved parameters, workbench model, DBC,
signal map), the effect list and the tool version.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import re
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from vdps_hil.batch.engine import Task
from vdps_hil.batch.keys import DigestCache, task_key

__all__ = ["drive_ids", "replay_drive", "diagnose_drive", "replay_tasks", "diagnose_tasks",
           "worker_info", "DEFAULT_MODEL", "REPLAY_OPTIONS", "NoRawData"]

DEFAULT_MODEL = "sedan-model"
_ID_BAD = re.compile(r"[^A-Za-z0-9._-]+")


# ---------------------------------------------------------------------------------- naming
def drive_ids(paths: Sequence[str | os.PathLike]) -> list[str]:
    """One result name per input: the file stem (characters outside ``[A-Za-z0-9._-]`` -> ``_``);
    stems that occur more than once get ``-<8 hex of the absolute path>`` appended."""
    stems = [_ID_BAD.sub("_", Path(p).stem) or "drive" for p in paths]
    out = []
    for p, s in zip(paths, stems):
        if stems.count(s) > 1:
            s = f"{s}-{hashlib.sha1(os.path.abspath(os.fspath(p)).encode()).hexdigest()[:8]}"
        out.append(s)
    return out


# --------------------------------------------------------------------------- task functions
class NoRawData(ValueError):
    """A recording with no readable raw record (one line)."""


def _library(module: str, attr: str):
    try:
        mod = importlib.import_module(module)
    except ImportError:
        return None
    return getattr(mod, attr, None)


REPLAY_OPTIONS = ("model", "dbc", "signalmap", "bus_map", "params", "identify", "predict",
                  "susp_sigma_m", "paper_faithful", "output")
"""Keyword arguments of ``vdps_hil.system.replay_file`` a batch may set (``config`` objects and
``save_params`` are per-run choices a batch does not make)."""
REPLAY_FILE_OPTIONS = ("model", "dbc", "signalmap", "params")
"""Options naming files: their contents are part of the resume key."""
TIMING_KEYS = ("wall_time_s", "realtime_factor")


def replay_drive(path: str, *, vehicle: str = DEFAULT_MODEL,
                 options: Mapping[str, Any] | None = None) -> dict:
    """Replay one recording with ``vdps_hil.system.replay_file`` (what ``vdps replay`` does):
    estimates, innovations, identified parameters with sigmas, prediction summary, counters.
    ``options``: keyword arguments of ``replay_file`` from :data:`REPLAY_OPTIONS`. The replay
    streams the file (decoder reorder window, no input log). Its timing fields (wall time,
    real-time factor) are moved under ``"run"`` (``engine`` docstring). A recording of which
    not one raw record could be read (garbage after the MCAP magic, no /raw/ topics) raises
    :class:`NoRawData`: a replay of nothing is a failed drive, not an empty success."""
    from vdps_hil.system import replay_file

    opts = dict(options or {})
    unknown = sorted(set(opts) - set(REPLAY_OPTIONS))
    if unknown:
        raise ValueError(f"unknown replay option(s): {', '.join(unknown)}")
    if opts.get("paper_faithful") is not None:
        opts["paper_faithful"] = tuple(opts["paper_faithful"])
    doc = replay_file(path, vehicle=vehicle, **opts)
    if not doc.get("messages_read", {}).get("raw_records"):
        problems = doc.get("decode", {}).get("reader", {}).get("problems") or []
        raise NoRawData(f"{path}: no raw record could be read"
                        + (f" ({problems[0]})" if problems else ""))
    doc["run"] = {k: doc.pop(k) for k in TIMING_KEYS if k in doc}
    return doc


def diagnose_drive(path: str, *, vehicle: str = DEFAULT_MODEL,
                   options: Mapping[str, Any] | None = None) -> dict:
    """Workbench diagnosis of one recording (``vdps_hil.workbench.diagnose_file``)."""
    fn = _library("vdps_hil.workbench", "diagnose_file")
    if fn is None:
        raise RuntimeError("the model workbench (vdps_hil.workbench.diagnose_file) is not "
                           "available in this installation")
    return fn(path, vehicle=vehicle, **dict(options or {}))


# --------------------------------------------------------------------------------- builders
def _drive_tasks(kind: str, fn: str, paths: Sequence[str | os.PathLike], *, vehicle: str,
                 options: Mapping[str, Any] | None, file_options: Iterable[str],
                 effects: Iterable[str], digests: DigestCache | None,
                 per_task: Any = None) -> list[Task]:
    from vdps_hil.model.params import resolve_vehicle_path

    paths = [os.fspath(p) for p in paths]
    options = dict(options or {})
    files: dict[str, Any] = {"vehicle": resolve_vehicle_path(vehicle)}
    for name in file_options:
        v = options.get(name)
        if isinstance(v, (str, os.PathLike)) and os.path.isfile(v):
            files[name] = v  # by content; a bare config name is covered by the tool version
    digests = digests if digests is not None else DigestCache(enabled=False)
    effects = list(effects)
    tasks = []
    for p, tid in zip(paths, drive_ids(paths)):
        try:
            d = digests.digest(p)
            size = os.path.getsize(p)
        except OSError as e:  # unreadable input: a task that fails and is reported
            d, size = f"unreadable:{type(e).__name__}", 0
        opts = dict(options, **(per_task(tid) if per_task else {}))
        key = task_key(kind, d, config={"fn": fn, "vehicle": os.fspath(vehicle), "options": opts},
                       files=files, effects=effects, digests=digests)
        tasks.append(Task(id=tid, fn=fn, key=key, cost=float(size), meta={"input": p, "kind": kind},
                          kwargs={"path": p, "vehicle": os.fspath(vehicle), "options": opts}))
    return tasks


def replay_tasks(paths: Sequence[str | os.PathLike], *, vehicle: str = DEFAULT_MODEL,
                 options: Mapping[str, Any] | None = None, effects: Iterable[str] = (),
                 est_dir: str | os.PathLike | None = None,
                 digests: DigestCache | None = None) -> list[Task]:
    """One ``replay_drive`` task per recording (module docstring for the key). ``options``:
    ``replay_file`` keyword arguments (:data:`REPLAY_OPTIONS`, without ``output``);
    ``est_dir``: write each drive's estimate recording to ``<est_dir>/<id>.mcap``."""
    options = dict(options or {})
    bad = sorted(set(options) - set(REPLAY_OPTIONS) | ({"output"} & set(options)))
    if bad:
        raise ValueError(f"replay option(s) not settable in a batch: {', '.join(bad)}")
    per_task = None
    if est_dir is not None:
        def per_task(tid):
            return {"output": os.path.join(os.fspath(est_dir), f"{tid}.mcap")}
    return _drive_tasks("replay", "vdps_hil.batch.tasks:replay_drive", paths, vehicle=vehicle,
                        options=options, file_options=REPLAY_FILE_OPTIONS, effects=effects,
                        digests=digests, per_task=per_task)


def diagnose_tasks(paths: Sequence[str | os.PathLike], *, vehicle: str = DEFAULT_MODEL,
                   options: Mapping[str, Any] | None = None, effects: Iterable[str] = (),
                   file_options: Iterable[str] = ("config", "model"),
                   digests: DigestCache | None = None) -> list[Task]:
    """One ``diagnose_drive`` task per recording (keys as ``replay_tasks``)."""
    return _drive_tasks("diagnose", "vdps_hil.batch.tasks:diagnose_drive", paths, vehicle=vehicle,
                        options=options, file_options=file_options, effects=effects,
                        digests=digests)


def worker_info() -> dict:
    """A probe task: the worker's tool version, Python and platform (to check that a remote
    cluster runs the same code as the client)."""
    import platform
    import sys

    from vdps_hil.batch.keys import tool_version
    return {"tool": tool_version(), "python": sys.version.split()[0],
            "platform": platform.platform()}
