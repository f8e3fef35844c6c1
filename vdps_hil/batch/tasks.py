"""Batch tasks: what one worker does for one recording (replay, diagnose) or one Monte Carlo
trial (studies), and the builders that turn a list of files into :class:`~.worker.Task` s with
their resume keys.

Task functions run in worker processes: they take JSON-able keyword arguments (paths as
strings, option dicts), open their recording themselves and stream it (the reader yields one
message at a time, chunk by chunk; the decoder's reorder buffer holds about a second; the
system keeps no input log in a file replay), and return a JSON-able summary dict, never a
drive's time series. A task that raises becomes a failed outcome with its one-line error
(``worker.execute``); the batch goes on.

Task functions
--------------
``replay_drive(path, vehicle, options)``
    ``vdps_hil.app.replay.replay_file`` (what ``vdps replay`` does) on one recording: estimates,
    innovations, identified parameters with sigmas, prediction summary, decoder counters.
``diagnose_drive(path, vehicle, options)``
    The workbench diagnosis of one recording (``vdps diagnose``: ``workbench.diagnosis``). The
    batch passes only the path; the workbench streams the recording through the estimator into
    packed arrays (no list of samples), and its ranking stores the smooth nuisance columns as
    bands, so its memory grows linearly with the drive's length, by about 180 MiB per minute
    of a Table 1 drive (``tools/bench_diagnose.py``, table1-susp1k, with_simulation off: peak
    RSS 373 / 450 / 640 MiB for 30 / 60 / 120 s drives; before: 637 / 2438 / 10527 MiB,
    quadratic), unlike the replay's, which stays constant. Diagnose drives of minutes, not
    hours (or cut them); a worker over its memory limit is restarted and the task retried, then
    reported failed.
``worker_info()``
    A probe: the worker's tool version (a remote cluster must run the client's code).
``snr_trial``, ``weighting_trial``, ``effect_trial``
    One Monte Carlo trial of a study (``batch.studies``): paper Table 2, Table 3, the
    workbench's hidden-effect drives. Each simulates its drive inside the worker.

Resume keys (``keys.task_key``): the recording's bytes, the task function and its options, the
model vehicle file, every file an option names (saved parameters, workbench model, DBC,
signal map), the effect list and the tool version.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from vdps_hil.batch.worker import Task
from vdps_hil.batch.keys import DigestCache, task_key
from vdps_hil.experiments.paper_tasks import TABLE3_QS

__all__ = ["drive_ids", "replay_drive", "diagnose_drive", "replay_tasks", "diagnose_tasks",
           "worker_info", "snr_trial", "weighting_trial", "effect_trial", "DEFAULT_MODEL",
           "REPLAY_OPTIONS", "DIAGNOSE_OPTIONS", "NoRawData"]

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


REPLAY_OPTIONS = ("model", "dbc", "signalmap", "bus_map", "params", "identify", "predict",
                  "susp_sigma_m", "paper_faithful", "sensorset", "output")
"""Keyword arguments of ``vdps_hil.app.replay.replay_file`` a batch may set (``config`` objects and
``save_params`` are per-run choices a batch does not make)."""
REPLAY_FILE_OPTIONS = ("model", "dbc", "signalmap", "params", "sensorset")
"""Options naming files: their contents are part of the resume key."""
TIMING_KEYS = ("wall_time_s", "realtime_factor")


def replay_drive(path: str, *, vehicle: str = DEFAULT_MODEL,
                 options: Mapping[str, Any] | None = None) -> dict:
    """Replay one recording with ``vdps_hil.app.replay.replay_file`` (what ``vdps replay`` does):
    estimates, innovations, identified parameters with sigmas, prediction summary, counters.
    ``options``: keyword arguments of ``replay_file`` from :data:`REPLAY_OPTIONS`. The replay
    streams the file (decoder reorder window, no input log). Its timing fields (wall time,
    real-time factor) are moved under ``"run"`` (``worker`` docstring). A recording of which
    not one raw record could be read (garbage after the MCAP magic, no /raw/ topics) raises
    :class:`NoRawData`: a replay of nothing is a failed drive, not an empty success."""
    from vdps_hil.app.replay import replay_file

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


DIAGNOSE_OPTIONS = ("model", "dbc", "signalmap", "add", "with_simulation", "sensorset")
"""Keyword arguments of ``vdps_hil.workbench.diagnosis.diagnose`` a batch may set (user effect
code and ``save_model`` are per-drive choices a batch does not make); ``sensorset`` becomes its
``DatasetConfig(sensorset=...)``."""
DIAGNOSE_FILE_OPTIONS = ("model", "dbc", "signalmap", "sensorset")


def _diagnose_fn():
    try:
        from vdps_hil.workbench.diagnosis import diagnose
    except ImportError as e:
        raise RuntimeError(f"the model workbench (vdps_hil.workbench.diagnosis) is not available: "
                           f"{e}") from None
    return diagnose


def diagnose_drive(path: str, *, vehicle: str = DEFAULT_MODEL,
                   options: Mapping[str, Any] | None = None) -> dict:
    """The workbench diagnosis of one recording (``vdps_hil.workbench.diagnosis.diagnose``, what
    ``vdps diagnose`` does): ranking of the effect candidates, recommendation, identified
    parameters, residuals before/after. The workbench's timings go under "run". Its memory
    grows by about 180 MiB per minute of drive (module docstring), unlike the replay's."""
    from vdps_hil.model.params import load_vehicle

    opts = dict(options or {})
    unknown = sorted(set(opts) - set(DIAGNOSE_OPTIONS))
    if unknown:
        raise ValueError(f"unknown diagnose option(s): {', '.join(unknown)}")
    if "add" in opts:
        opts["add"] = tuple(opts["add"])
    if "sensorset" in opts:
        from vdps_hil.workbench.dataset import DatasetConfig

        opts["dataset_config"] = DatasetConfig(sensorset=opts.pop("sensorset"))
    diagnose = _diagnose_fn()
    doc = diagnose(path, load_vehicle(vehicle, "model"), **opts).to_json()
    wb = doc.get("workbench") if isinstance(doc.get("workbench"), dict) else {}
    timings = wb.pop("timings_s", None)
    doc["run"] = {"timings_s": timings}
    return doc


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
                   digests: DigestCache | None = None) -> list[Task]:
    """One ``diagnose_drive`` task per recording (keys as ``replay_tasks``; ``options`` from
    :data:`DIAGNOSE_OPTIONS`)."""
    options = dict(options or {})
    bad = sorted(set(options) - set(DIAGNOSE_OPTIONS))
    if bad:
        raise ValueError(f"diagnose option(s) not settable in a batch: {', '.join(bad)}")
    return _drive_tasks("diagnose", "vdps_hil.batch.tasks:diagnose_drive", paths, vehicle=vehicle,
                        options=options, file_options=DIAGNOSE_FILE_OPTIONS, effects=effects,
                        digests=digests)


def worker_info() -> dict:
    """A probe task: the worker's tool version, Python and platform (to check that a remote
    cluster runs the same code as the client), and the BLAS thread variables its numpy was
    loaded with (``app.children.BLAS_THREAD_VARIABLES``: None where unset)."""
    import os
    import platform
    import sys

    from vdps_hil.app.children import BLAS_THREAD_VARIABLES
    from vdps_hil.batch.keys import tool_version
    return {"tool": tool_version(), "python": sys.version.split()[0],
            "platform": platform.platform(), "blas_threads": {k: os.environ.get(k) for k in BLAS_THREAD_VARIABLES}}


# ------------------------------------------------------------------------------ study trials
def _timing_to_run(doc: dict, keys: Iterable[str] = ("wall_s",)) -> dict:
    run = doc.get("run") if isinstance(doc.get("run"), dict) else {}
    doc["run"] = {**run, **{k: doc.pop(k) for k in keys if k in doc}}
    return doc


def snr_trial(profile: str, k: float, seed: int) -> dict:
    """One trial of the SNR study (paper Table 2): the paper-scenario drive with every Table 1
    sigma times ``k`` through the real chain (``vdps_hil.experiments.paper_tasks.snr_task``): the
    relative error of I_x, I_y, I_z at 10.25 s and the SNR series (``t_ns``, ``series``: the
    inertia problem's omega_dot and moments at the estimate instants of 5-10.25 s). The SNR needs
    the zero-noise trial of the same seed; the study computes it (``paper_tasks.snr_db``)."""
    from vdps_hil.experiments.paper_tasks import snr_task

    return _timing_to_run(snr_task(profile, float(k), int(seed)))


def weighting_trial(profile: str, seed: int, duration_s: float, noise_scale: float = 0.0,
                    qs: Sequence[float] = TABLE3_QS) -> dict:
    """One trial of the weighting study (paper Table 3), the one Table 3 computation
    ``experiments.paper_tasks.table3_task`` in the study's layout: a paper-scenario drive of
    ``duration_s`` with the sensor sigmas times ``noise_scale`` (0: noise-free, as the paper)
    through the real chain, its identifier inputs recorded; the inertia problem re-run on them
    with Q_4 = diag(q, q, q), W_4 = I, P(0) = I for each q. Per q (key ``f"{q:g}"``): minimum
    eigenvalue of sum A^T Q^T Q A, convergence time per inertia (first time from which
    |I - I_true| <= 10 % holds to the end; NaN: never, the paper's "Nan"; null in the trial's
    JSON, ``engine.to_jsonable``) and the final relative errors."""
    from vdps_hil.experiments.paper_tasks import INERTIA, table3_task

    t3 = table3_task(profile, float(duration_s), int(seed), qs=[float(q) for q in qs],
                     noise_scale=float(noise_scale))
    rows = {f"{q:g}": {"q": q, "min_eigenvalue": v["min_eigenvalue"],
                       "convergence_s": dict(zip(INERTIA, v["convergence_s"])),
                       "final_rel_err": dict(zip(INERTIA, v["final_rel_err"]))}
            for q, v in t3["rows"].items()}
    return {"profile": profile, "seed": int(seed), "noise_scale": float(noise_scale),
            "duration_s": float(duration_s), "inputs": t3["inputs"], "rows": rows,
            "run": {"wall_s": t3["wall_s"]}}


def effect_trial(effect: str | None, seed: int, maneuver: str | None = None,
                 vehicle: str = DEFAULT_MODEL, options: Mapping[str, Any] | None = None) -> dict:
    """One trial of the hidden-effect study: the workbench's maneuver for ``effect`` with the
    effect hidden in the truth simulator (``vdps_hil.experiments.workbench_study``; ``effect``
    None: a null drive of ``maneuver`` with nothing hidden), simulated into a temporary file,
    diagnosed from its ``/raw/`` topics with the model vehicle file (``diagnose_drive``). Returns the
    recommended effects, ``hit`` (the hidden effect is the first recommendation) and
    ``found`` (it is among them); for a null drive ``false_alarm`` (anything recommended).
    ``options``: diagnosis options (default: no simulation-error runs, which the hit rate does
    not need)."""
    import tempfile

    from vdps_hil.batch.report import recommended_effects
    from vdps_hil.experiments.workbench_study import HIDDEN, hidden_drive

    _diagnose_fn()  # fail before simulating when there is no workbench entry point

    if effect is not None:
        if effect not in HIDDEN:
            raise ValueError(f"unknown hidden effect {effect!r} (one of {', '.join(sorted(HIDDEN))})")
        maneuver, spec = HIDDEN[effect]
        specs = [spec]
    else:
        if maneuver is None:
            raise ValueError("a null trial needs a maneuver")
        specs = []
    with tempfile.TemporaryDirectory(prefix="vdps-effect-") as d:
        path = os.path.join(d, "drive.mcap")
        hidden_drive(path, maneuver, specs, seed=int(seed))
        diag = diagnose_drive(path, vehicle=vehicle,
                              options={"with_simulation": False} if options is None else options)
    rec = recommended_effects(diag)
    doc = {"effect": effect, "maneuver": maneuver, "seed": int(seed), "recommended": rec}
    if effect is not None:
        doc["hit"] = bool(rec) and rec[0] == effect
        doc["found"] = effect in rec
    else:
        doc["false_alarm"] = bool(rec)
    if isinstance(diag, dict) and isinstance(diag.get("run"), dict):
        doc["run"] = diag["run"]
    return doc
