"""Batch tasks: what one worker does for one recording (replay, diagnose) or one Monte Carlo
trial (studies), and the builders that turn a list of files into :class:`~.engine.Task` s with
their resume keys.

Task functions run in worker processes: they take JSON-able keyword arguments (paths as
strings, option dicts), open their recording themselves and stream it (the reader yields one
message at a time, chunk by chunk; decoders and the estimator are incremental), and return a
JSON-able summary dict: never a drive's time series. A task that raises becomes a failed
outcome with its one-line error (``engine.execute``); the batch goes on.

Task functions
--------------
``replay_drive(path, vehicle, config, ...)``
    The replay of one recording. Uses ``vdps_hil.system.replay_file`` (the ``vdps replay``
    library function) when it is present; otherwise the internal streaming replay
    :func:`replay_stream` (raw CAN and serial decoded with the project's codecs, samples fed to
    the ``EstimatorPipeline`` in time order).
``diagnose_drive(path, ...)``
    The workbench diagnosis of one recording (``vdps_hil.workbench``), when present.
"""

from __future__ import annotations

import importlib
import json
import math
import os
import re
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from vdps_hil.batch.engine import Task
from vdps_hil.batch.keys import DigestCache, task_key

__all__ = ["drive_ids", "replay_drive", "replay_stream", "diagnose_drive", "replay_tasks",
           "diagnose_tasks", "UnsupportedRecording", "DEFAULT_MODEL", "worker_info"]

DEFAULT_MODEL = "sedan-model"
_ID_BAD = re.compile(r"[^A-Za-z0-9._-]+")


class UnsupportedRecording(ValueError):
    """A recording this replay cannot process (no usable raw topics, unknown serial format)."""


# ---------------------------------------------------------------------------------- naming
def drive_ids(paths: Sequence[str | os.PathLike]) -> list[str]:
    """One result name per input: the file stem (characters outside ``[A-Za-z0-9._-]`` -> ``_``);
    stems that occur more than once get ``-<8 hex of the absolute path>`` appended."""
    stems = [_ID_BAD.sub("_", Path(p).stem) or "drive" for p in paths]
    out = []
    for p, s in zip(paths, stems):
        if stems.count(s) > 1:
            import hashlib
            s = f"{s}-{hashlib.sha1(os.path.abspath(os.fspath(p)).encode()).hexdigest()[:8]}"
        out.append(s)
    return out


# ------------------------------------------------------------------------ internal replay
def _can_sample_source(reader, bus: str) -> Any:
    from vdps_hil.codecs.can_codec import VdpsCanDecoder
    return VdpsCanDecoder(source=f"can/{bus}")


class _SerialDecoder:
    """Bytes of one serial device -> samples, by the format in its channel metadata."""

    def __init__(self, device: str, baud: int | None, fmt: str):
        from vdps_hil.codecs.framing import LineFramer
        from vdps_hil.codecs.imu import ImuDecoder
        from vdps_hil.codecs.nmea import NmeaDecoder

        self.fmt = fmt
        if fmt == "xsens-mtdata2":
            self._imu = ImuDecoder(device, **({"baud": baud} if baud else {}))
            self.feed = self._imu.feed
            self.flush = self._imu.flush
            self.counters = lambda: dict(self._imu.counters)
        elif fmt == "nmea":
            self._framer = LineFramer(baud or 115200)
            self._nmea = NmeaDecoder(device)
            self.feed = self._feed_nmea
            self.flush = lambda: []
            self.counters = lambda: {**dict(self._nmea.counters),
                                     **{f"framer_{k}": v for k, v in self._framer.counters.items()}}
        else:
            raise UnsupportedRecording(f"serial device {device!r}: unsupported format {fmt!r} "
                                       "(xsens-mtdata2 or nmea)")

    def _feed_nmea(self, t_ns: int, data: bytes) -> list:
        out = []
        for tl, line in self._framer.feed(t_ns, data):
            out += self._nmea.feed_line(tl, line)
        return out


def replay_stream(path: str | os.PathLike, *, vehicle: str = DEFAULT_MODEL,
                  predict_period_s: float = 0.01) -> dict:
    """Streaming replay of the ``/raw/`` topics of one recording through the project's decoders
    and the estimator pipeline; returns a summary (no time series).

    Memory: the reader holds at most a few chunks; the decoders hold partial frames; the
    pipeline's replay log (``EstimatorPipeline.input_log``, every sample since the start) is
    cleared every 4096 samples, so memory does not grow with the drive's length.
    """
    import base64

    from vdps_hil.estimation.pipeline import EstimatorPipeline, PipelineConfig
    from vdps_hil.estimation.states import STATE_NAMES
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.record import schemas as S
    from vdps_hil.record.reader import RecordingReader

    model = load_vehicle(vehicle, "model")
    pipe = EstimatorPipeline(model, PipelineConfig(predict_period_s=predict_period_s))
    samples: dict[str, int] = {}
    nis: dict[str, list[float]] = {}
    t_first = t_last = None
    n_est = 0
    with RecordingReader(path) as r:
        topics = r.topics()
        raw = {t: i.count for t, i in topics.items() if t.startswith("/raw/")}
        if not raw:
            raise UnsupportedRecording(f"{path}: no /raw/ topics (topics: "
                                       f"{', '.join(topics) or 'none'})")
        can_dec: dict[str, Any] = {}
        ser_dec: dict[str, _SerialDecoder] = {}
        for topic in raw:
            if topic.startswith(S.RAW_CAN_PREFIX):
                bus = topic[len(S.RAW_CAN_PREFIX):]
                can_dec[topic] = _can_sample_source(r, bus)
            elif topic.startswith(S.RAW_SERIAL_PREFIX):
                dev = topic[len(S.RAW_SERIAL_PREFIX):]
                baud, fmt = r.serial_config(dev)
                ser_dec[topic] = _SerialDecoder(dev, baud, fmt)
        log = pipe._log  # the replay log (see the docstring); cleared as we go

        def feed(batch):
            nonlocal t_first, t_last, n_est
            for s in batch:
                samples[s.kind] = samples.get(s.kind, 0) + 1
                for o in pipe.handle(s):
                    if hasattr(o, "nis"):
                        if o.status == "ok" and math.isfinite(o.nis) and o.dof:
                            acc = nis.setdefault(o.kind, [0.0, 0.0])
                            acc[0] += o.nis / o.dof
                            acc[1] += 1
                    else:
                        n_est += 1
                t_first = s.t_ns if t_first is None else t_first
                t_last = s.t_ns
            if len(log) > 4096:
                log.clear()

        loads = json.loads
        for rec in r.iter_records(prefixes=("/raw/",)):
            try:
                doc = loads(rec.data)
                if rec.topic in can_dec:
                    batch = can_dec[rec.topic].decode(rec.t_ns, doc["arbitration_id"],
                                                      bytes.fromhex(doc["data_hex"]),
                                                      doc.get("is_extended_id", False))
                elif rec.topic in ser_dec:
                    batch = ser_dec[rec.topic].feed(rec.t_ns, base64.b64decode(doc["data_b64"]))
                else:
                    continue
            except (ValueError, KeyError, TypeError):
                samples["_undecodable_records"] = samples.get("_undecodable_records", 0) + 1
                continue
            feed(batch)
        for d in ser_dec.values():
            feed(d.flush())
        log.clear()
        est = pipe.estimate()
        doc = {
            "recording": {"raw_topics": raw, "truncated": r.truncated,
                          "problems": list(r.problems), "rejected": r.rejected,
                          "layout_version": r.layout_version},
            "decoders": {**{t: {k: dict(v) for k, v in d.counters.items()} for t, d in can_dec.items()},
                         **{t: d.counters() for t, d in ser_dec.items()}},
        }
    doc["samples"] = dict(sorted(samples.items()))
    doc["span_s"] = None if t_first is None else (t_last - t_first) / 1e9
    counters = pipe.counters
    doc["estimator"] = {
        "engine": "internal",
        "estimates": n_est,
        "counters": {k: v for k, v in counters.items() if k != "ekf"},
        "ekf": json.loads(json.dumps(_plain(counters["ekf"]))),
        "rejected": pipe.rejected(),
        "mean_nis_per_dof": {k: v[0] / v[1] for k, v in sorted(nis.items()) if v[1]},
        "final": None if est is None else {
            "t_s": est.t_ns / 1e9, "state": dict(zip(STATE_NAMES, est.x)),
            "sigma": dict(zip(STATE_NAMES, est.sigma))},
    }
    return doc


def _plain(o):
    if isinstance(o, Mapping):
        return {str(k): _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_plain(v) for v in o]
    return o


# --------------------------------------------------------------------------- task functions
def _library(module: str, attr: str):
    try:
        mod = importlib.import_module(module)
    except ImportError:
        return None
    return getattr(mod, attr, None)


def replay_drive(path: str, *, vehicle: str = DEFAULT_MODEL, options: Mapping[str, Any] | None = None,
                 engine: str = "auto") -> dict:
    """Replay one recording (module docstring). ``engine``: "auto" (the project's
    ``replay_file`` when present, else internal), "internal" or "library"."""
    opts = dict(options or {})
    fn = _library("vdps_hil.system", "replay_file") if engine in ("auto", "library") else None
    if fn is None:
        if engine == "library":
            raise RuntimeError("vdps_hil.system.replay_file is not available in this installation")
        return replay_stream(path, vehicle=vehicle, **opts)
    return fn(path, vehicle=vehicle, **opts)


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
                 options: Mapping[str, Any] | None, files: Mapping[str, Any] | None,
                 effects: Iterable[str], digests: DigestCache | None,
                 extra_kwargs: Mapping[str, Any] | None = None) -> list[Task]:
    from vdps_hil.model.params import resolve_vehicle_path

    paths = [os.fspath(p) for p in paths]
    vehicle_file = resolve_vehicle_path(vehicle)
    all_files = {"vehicle": vehicle_file, **dict(files or {})}
    digests = digests if digests is not None else DigestCache(enabled=False)
    tasks = []
    for p, tid in zip(paths, drive_ids(paths)):
        try:
            d = digests.digest(p)
            size = os.path.getsize(p)
        except OSError as e:  # unreadable input: a failed task, reported like the others
            d, size = f"unreadable:{type(e).__name__}", 0
        key = task_key(kind, d, config={"fn": fn, "vehicle": os.fspath(vehicle),
                                        "options": dict(options or {}), **dict(extra_kwargs or {})},
                       files=all_files, effects=effects, digests=digests)
        kwargs = {"path": p, "vehicle": os.fspath(vehicle), "options": dict(options or {}),
                  **dict(extra_kwargs or {})}
        tasks.append(Task(id=tid, fn=fn, kwargs=kwargs, key=key,
                          meta={"input": p, "kind": kind}, cost=float(size)))
    return tasks


def replay_tasks(paths: Sequence[str | os.PathLike], *, vehicle: str = DEFAULT_MODEL,
                 options: Mapping[str, Any] | None = None, engine: str = "auto",
                 files: Mapping[str, Any] | None = None, effects: Iterable[str] = (),
                 digests: DigestCache | None = None) -> list[Task]:
    """One ``replay_drive`` task per recording, keyed by the recording's bytes, the options,
    the model vehicle file (and ``files``: config files by role), the effect list and the tool
    version."""
    return _drive_tasks("replay", "vdps_hil.batch.tasks:replay_drive", paths, vehicle=vehicle,
                        options=options, files=files, effects=effects, digests=digests,
                        extra_kwargs={"engine": engine})


def diagnose_tasks(paths: Sequence[str | os.PathLike], *, vehicle: str = DEFAULT_MODEL,
                   options: Mapping[str, Any] | None = None,
                   files: Mapping[str, Any] | None = None, effects: Iterable[str] = (),
                   digests: DigestCache | None = None) -> list[Task]:
    """One ``diagnose_drive`` task per recording (keys as ``replay_tasks``)."""
    return _drive_tasks("diagnose", "vdps_hil.batch.tasks:diagnose_drive", paths, vehicle=vehicle,
                        options=options, files=files, effects=effects, digests=digests)


def worker_info() -> dict:
    """A probe task: the worker's tool version, Python and platform (to check that a remote
    cluster runs the same code as the client)."""
    import platform
    import sys

    from vdps_hil.batch.keys import tool_version
    return {"tool": tool_version(), "python": sys.version.split()[0],
            "platform": platform.platform()}
