"""File replay (``vdps replay``, the batch tasks, the bench's ``--replay``): the application
around the Figure 2 node (``pipeline.node.VdpsSystem``).

``replay_file``: ``record.decode`` (only ``/raw/``) -> optional sensor-set kind map and
calibration nodes -> ``VdpsSystem`` -> ``/est/state`` (values + sigmas),
``/est/innovation/<kind>``, ``/est/filtered``, ``/est/ident``, ``/est/prediction``,
``/est/can/<bus>`` (the sent frames, vdps.RawCan.v1, tx; layout in ``app.est_topics``) in an
output MCAP that also holds the raw topics copied byte for byte; the summary dict is the
``--json`` document (``app.replay_summary``). The sensor set is named (``configs/sensorsets``)
or inferred from the fields the recording carries, the suspension averaging sized from its
measured rate (``sample_stats`` over the first ``PROBE_SECONDS``, ``replay_config``). The
decoding and the output writing run here or in a second process (``app.replay_io``,
``--jobs 2``).
"""

from __future__ import annotations

import functools
import itertools
import os
import time
from dataclasses import replace
from typing import Any, Mapping

from vdps_hil.app.replay_summary import ReplaySummary
from vdps_hil.bus.samples import Sample
from vdps_hil.estimation.sensorsets import KindMap
from vdps_hil.model.params import IdentifiedParams, Vehicle
from vdps_hil.pipeline.configure import (DEFAULT_SUSP_SIGMA_M, PROBE_SECONDS, SystemConfigError, sample_stats,
                                        system_config)
from vdps_hil.pipeline.node import SystemConfig, VdpsSystem
from vdps_hil.pipeline.outputs import finite_or_none

__all__ = ["DEFAULT_SUSP_SIGMA_M", "PROBE_SECONDS", "ReplayError", "recorded_config", "replay_config",
           "replay_file", "sample_stats"]


class ReplayError(ValueError):
    """A replay that cannot run (bad option, unreadable input, wrong vehicle file): one line."""


def replay_file(path, *, vehicle: str | Vehicle = "sedan-model", output=None, model=None, dbc=None,
                signalmap=None, bus_map: Mapping[str, str] | None = None, params=None, save_params=None,
                config: SystemConfig | None = None, identify: bool = True, predict: bool = True,
                susp_sigma_m: float = DEFAULT_SUSP_SIGMA_M, paper_faithful=None, copy_raw: bool = True,
                sensorset=None, input_order: str = "time", jobs: int = 1, foxglove: bool = True,
                progress=None, serve=None) -> dict:
    """Replay a recording's ``/raw/`` topics through :class:`VdpsSystem` (``vdps replay``).

    Decodes only ``/raw/`` (``record.decode``), runs the system, writes ``output`` (MCAP: the
    raw topics copied unchanged, ``/est/state`` with sigmas, ``/est/innovation/<kind>`` with NIS,
    ``/est/filtered``, ``/est/ident``, ``/est/prediction`` and the sent VDPS_Warning frames on
    ``/est/can/<bus>`` (schema vdps.RawCan.v1, direction tx)) and returns the summary (the
    ``--json`` document). ``vehicle``: a *model* vehicle file or name (a truth file is refused);
    ``params``: a saved parameter file to start the identifier from; ``save_params``: where to
    save the identified parameters; ``model``: a saved workbench model
    (``vdps_hil.workbench.model_file``); ``paper_faithful``: names of the EKF switches set to
    the paper as printed (``"all"`` for all four); ``sensorset``: a named sensor set
    (``configs/sensorsets``; default: inferred from the fields the recording carries, e.g. an
    ESC cluster without suspension -> ``esc3``, no road angles). Without ``config`` the
    suspension window averaging is sized from the measured sample rate and ``susp_sigma_m``
    (Table 1: 1 mm). ``input_order``: ``"time"`` (the decoded ``/raw/`` samples in time order) or
    ``"recorded"`` (the ``/decoded/`` samples in the order a live system received them, metadata
    ``hil.input_order`` of a ``vdps bench -o`` or ``vdps log --pipeline -o`` recording: the replay
    reproduces the live estimates; the ``/raw/`` topics are still decoded for the counters and
    copied; a log's recorded settings (``recorded_config``) must match and size the config). ``jobs``: 2
    decodes the recording and writes the output in a second process (``app.replay_io``)
    while this one runs the system: the same messages, less wall time on two free cores (the
    ``recorded`` order always runs in one). ``foxglove``: the output also holds the Foxglove view
    (``app.foxglove_view``: ``/decoded/``, ``/gnss/fix``, ``/est/fix``, ``/est/tf``, ``/est/pose``,
    ``/est/warning``). The signal map and DBC are the options', else those the recording's
    metadata names (``record.recorded_decoding``). ``progress(seconds_done)``: called every few
    thousand samples with the recording time fed so far. ``serve``: an ``app.live_view.LiveServer``
    that also gets the outputs and the view (with or without ``output``). Raises :class:`ReplayError` (one line)."""
    from vdps_hil.record.reader import RecordingError, RecordingReader, damage_note

    wall0 = time.perf_counter()
    veh = _load_model_vehicle(vehicle)
    start, model_effects, model_doc = _starting_point(veh, params, model)
    _check_options(save_params, identify, input_order, jobs)
    try:
        reader = RecordingReader(path)
    except RecordingError as e:
        raise ReplayError(str(e)) from None
    try:
        recorded, probe, drops = None, None, ()
        if input_order == "recorded":
            recorded, probe, drops = _recorded_input(reader, path, config, veh, start, susp_sigma_m)
        if config is not None and sensorset is not None:
            raise ReplayError("give a sensor set or a config, not both")
        decoded_with = _recorded_decoding(reader, path, dbc, signalmap)
        dbc, signalmap = decoded_with.dbc, decoded_with.signalmap
        io_kw = dict(dbc=dbc, signalmap=signalmap, bus_map=bus_map, output=output, copy_raw=copy_raw)
        configure = functools.partial(replay_config, veh=veh, susp_sigma_m=susp_sigma_m,
                                      paper_faithful=paper_faithful, sensorset=sensorset, identify=identify,
                                      predict=predict)
        view = _foxglove_view(reader) if (foxglove and output is not None) or serve is not None else None
        if serve is not None:
            serve.epoch_ns = view.epoch_ns
        unsettled = tuple((model_doc or {}).get("params_unsettled", ()))
        try:
            system, side, summary, sensors_desc = _run(path, reader, veh, config, configure, start, model_effects,
                                                       recorded, probe, jobs, io_kw, view, progress, serve,
                                                       unsettled, drops)
        except ReplayError as e:
            raise ReplayError(f"{e}{damage_note(reader.problems, path)}") from None
    finally:
        reader.close()
    wall = time.perf_counter() - wall0
    doc = _document(path, output, veh, system, side, summary, sensors_desc, wall, model_doc, save_params)
    doc["decoded_with"] = {"source": decoded_with.source, "files": decoded_with.found}
    return doc


def _progress_tap(source, progress, every: int = 2048):
    """The samples of ``source`` unchanged; ``progress(seconds since the first sample)`` every
    ``every`` samples and at the end."""
    t0 = None
    n = 0
    s = None
    for s in source:
        if t0 is None:
            t0 = s.t_ns
        n += 1
        if n >= every:
            n = 0
            progress((s.t_ns - t0) / 1e9)
        yield s
    if s is not None:
        progress((s.t_ns - t0) / 1e9)


def _foxglove_view(reader):
    """The Foxglove view of the output (``app.foxglove_view``), its log times on the epoch the
    output writer keeps (``app.replay_io``: the first raw record's log time minus its t_ns)."""
    from vdps_hil.app.foxglove_view import FoxgloveView
    from vdps_hil.record import schemas as S

    first = next(iter(reader.iter_records(prefixes=(S.RAW_PREFIX,))), None)
    epoch = max(0, first.log_time_ns - first.t_ns) if first is not None and first.log_time_ns else 0
    return FoxgloveView(epoch_ns=epoch)


def _recorded_decoding(reader, path, dbc, signalmap):
    """The signal map and DBC to decode with: the options, else those the recording's metadata
    names, found by path and content hash (``record.recorded_decoding``)."""
    from vdps_hil.record.recorded_decoding import RecordedDecodingError, find_recorded_decoding

    try:
        return find_recorded_decoding(reader, path, dbc=dbc, signalmap=signalmap)
    except RecordedDecodingError as e:
        raise ReplayError(str(e)) from None


def _starting_point(veh: Vehicle, params, model):
    """(identifier start parameters, workbench model effects, model summary) from ``--params``
    or ``--model`` (not both), or Nones."""
    start, model_doc = None, None
    if params is not None and model is not None:
        raise ReplayError("give --params or --model (a saved model carries its parameters), not both")
    if params is not None:
        from vdps_hil.identification.persistence import ParamsFileError, load_params, not_settled

        try:
            saved = load_params(params, veh)
        except ParamsFileError as e:
            raise ReplayError(str(e)) from None
        start = saved.params
        # the chain waits for the live identifier on those of them the policy names (pipeline.node)
        model_doc = not_settled(saved) or None
    model_effects = None
    if model is not None:
        start, model_effects, model_doc = _load_workbench_model(model, veh)
    return start, model_effects, model_doc


def _check_options(save_params, identify: bool, input_order: str, jobs: int) -> None:
    if save_params is not None and not identify:
        raise ReplayError("--save-params needs the identifier (drop --no-identify)")
    if input_order not in ("time", "recorded"):
        raise ReplayError(f"input order must be 'time' or 'recorded', got {input_order!r}")
    if jobs not in (1, 2):
        raise ReplayError(f"jobs must be 1 or 2 (decoding and the system), got {jobs!r}")


def _recorded_input(reader, path, config, veh: Vehicle, start, susp_sigma_m: float):
    """(the recorded input order's samples, the live system's probe statistics or None, the
    predictions it dropped) of ``--input-order recorded`` (``record.input_order``,
    ``recorded_config``)."""
    from vdps_hil.record.input_order import INPUT_ORDER_METADATA, read_input_order, recorded_drops

    if INPUT_ORDER_METADATA not in reader.metadata():
        raise ReplayError(f"{os.fspath(path)}: no recorded input order (metadata {INPUT_ORDER_METADATA}, "
                          "written by vdps bench -o and vdps log --pipeline -o without rotation); "
                          "use --input-order time")
    probe = None
    try:
        recorded, settings = read_input_order(reader)
        drops = recorded_drops(settings)
        if config is None:
            probe = recorded_config(settings, veh, start, susp_sigma_m)
    except ReplayError:
        raise
    except (ValueError, KeyError, IndexError, TypeError, AttributeError) as e:
        raise ReplayError(f"{os.fspath(path)}: recorded input order unreadable: {e}") from None
    return recorded, probe, drops


def _run(path, reader, veh: Vehicle, config, configure, start, model_effects, recorded, probe, jobs: int,
         io_kw: dict, view=None, progress=None, serve=None, unsettled: tuple[str, ...] = (), drops: tuple = ()):
    """Configure the system (``config``, or ``configure(rates, fields)`` from the first seconds
    or the recorded ``probe``) and run it over the recording: (system, recording side, summary,
    sensor-set description). The recording side (decoding, the output) runs here or in a second
    process (``app.replay_io``); raw records read before the configuration is accepted wait, so
    a refused one writes nothing. ``unsettled``: problems of a ``--params`` file that were not
    converged when saved: the warnings stay invalid until the live identifier converges them.
    ``drops``: the predictions a live run dropped (``--input-order recorded``), dropped again."""
    from vdps_hil.app.replay_io import LocalRecordingSide, RecordingProcess, ReplayIOError, SampleCounter

    side = None
    try:
        if jobs == 2 and recorded is None:
            side = RecordingProcess(path, **io_kw)
        else:
            side = LocalRecordingSide(reader, **io_kw)
        head: list[Sample] = []
        nodes, sensors_desc = [], None
        if config is None:  # the sensor set and suspension rate from the first seconds, decoded once
            head, rates, fields = sample_stats(side) if probe is None else ([], *probe)
            config, _, nodes, sensors_desc = configure(rates, fields)
        side.start_output({"source": "vdps replay", "input": os.path.basename(os.fspath(path)),
                           "vehicle": veh.name, "vehicle_sha256": veh.source_sha256})
        if start is not None:
            config = replace(config, start_params=start)
        if unsettled:  # the validity rule gates those the warning policy names (pipeline.node)
            config = replace(config, start_unsettled=tuple(unsettled))
        if model_effects is not None:
            config = replace(config, model_effects=model_effects)
        if drops:
            config = replace(config, prediction_drops_t0_ns=drops)
        system = VdpsSystem(veh, config)
        system.clear_input_log()
        summary = ReplaySummary() if view is None else view.summary()
        source = itertools.chain(head, side)
        counter = None  # the decoded samples are counted by the recording side
        if recorded is not None:
            for _ in side:  # the decoders' counters, and the raw copy
                pass
            counter = SampleCounter()
            source = recorded
        out = side
        if serve is not None:
            from vdps_hil.app.live_view import ServedSide

            out = ServedSide(side, serve)
        if view is not None:
            view.origin = lambda: system.pipeline.origin
            source = view.tap(source, out)
        if progress is not None:
            source = _progress_tap(source, progress)
        mapper = KindMap.of(sensors_desc)
        _feed(system, source, None if counter is None else counter.count, mapper, nodes, summary, out)
        if mapper.dropped and sensors_desc is not None:
            sensors_desc["not_used"] = dict(mapper.dropped)  # a sensor the set does not name
        summary.outputs(system.finish(), out.writer)
        side.finish()
        summary.take_counts(side.sample_counts if counter is None else counter.document())
    except ReplayIOError as e:
        raise ReplayError(str(e)) from None
    finally:
        if side is not None:
            side.abort()
    return system, side, summary, sensors_desc


def _feed(system: VdpsSystem, source, count, kind_map: KindMap, nodes, summary: ReplaySummary,
          side) -> None:
    """Every sample of ``source`` (counted by ``count``, kinds renamed by ``kind_map``, which
    leaves out a sensor the set does not name, through the calibration ``nodes``) into the
    system; its outputs into the summary and ``side.writer`` (read at each output: the output
    opens at the first raw record)."""
    handle = system.handle
    kind_map = kind_map if kind_map else None  # asked once, not per sample
    n = 0
    for s in source:
        if count is not None:
            count(s)
        if kind_map is not None:
            s = kind_map(s)
            if s is None:
                continue
        for node in nodes:
            s = node.process(s)
        outs = handle(s)
        n += 1
        if n >= 4096:  # a file replay keeps the file, not a copy in memory
            system.clear_input_log()
            n = 0
        if outs:
            summary.outputs(outs, side.writer)


def _document(path, output, veh: Vehicle, system: VdpsSystem, side, summary: ReplaySummary, sensors_desc,
              wall: float, model_doc, save_params) -> dict:
    """The ``--json`` document of a replay; saves the identified parameters to ``save_params``."""
    from vdps_hil.app.replay_io import RecordingProcess

    doc = summary.document(system, side, veh)
    doc.update({"input": os.fspath(path), "output": None if output is None else os.fspath(output),
                "vehicle": veh.name, "sensor_set": sensors_desc, "wall_time_s": wall,
                "realtime_factor": (doc["duration_s"] / wall) if wall > 0 and doc["duration_s"] else None,
                "jobs": 2 if isinstance(side, RecordingProcess) else 1})
    if model_doc is not None and "params_unsettled" in model_doc:
        doc["params_unsettled"] = model_doc["params_unsettled"]  # the policy's among them gate the warning
        doc["params_not_identified"] = model_doc["params_not_identified"]
    elif model_doc is not None:
        doc["model"] = model_doc
    if save_params is not None:
        from vdps_hil.identification.persistence import ParamsFileError, save_params as _save

        idf = system.identifier
        values, at_bound = idf.handover_params()  # a value on its bound is never saved as one
        try:
            _save(save_params, values, veh, sigmas=idf.sigmas,
                  meta={"source": os.path.basename(os.fspath(path)), "updates":
                        {n: c.updates for n, c in idf.counters.items()},
                        "status": {n: st.status for n, st in idf.problem_status.items()},
                        "param_status": {p.name: p.status for st in idf.problem_status.values() for p in st.params},
                        "at_bound_kept_start": list(at_bound)})
        except ParamsFileError as e:
            raise ReplayError(str(e)) from None
        doc["saved_params"] = os.fspath(save_params)
    return doc


def recorded_config(settings: Mapping[str, Any], veh: Vehicle, start: IdentifiedParams | None,
                    susp_sigma_m: float) -> tuple[dict[str, float], dict[str, set]] | None:
    """The probe statistics (rates [Hz] per kind, fields per kind) a live ``vdps log --pipeline``
    sized its system from, recorded with its input order (``system`` setting), or None (a bench
    recording: the replay probes the ``/raw/`` topics). The live system's vehicle, starting
    parameters and suspension sigma must be the replay's, else ReplayError names the option:
    ``--input-order recorded`` is for reproducing the live run."""
    sysd = settings.get("system")
    if sysd is None:
        return None
    if sysd["vehicle_sha256"] != veh.source_sha256:
        raise ReplayError(f"the live system ran vehicle {sysd['vehicle']!r} (another file than {veh.name!r}): "
                          f"give --vehicle {sysd['vehicle']} to reproduce it")
    mine = None if start is None else finite_or_none(start.as_dict())
    if sysd["start_params"] != mine:
        raise ReplayError("the live system started from " + (
            "the priors: drop --params/--model" if sysd["start_params"] is None else
            f"the parameters of {sysd.get('params_file')!r}: give them as --params") + " to reproduce it")
    if sysd["susp_sigma_m"] != susp_sigma_m:
        raise ReplayError(f"the live system used --susp-sigma {sysd['susp_sigma_m']!r}: give it to reproduce it")
    rates = {str(k): float(v) for k, v in sysd["probe_rates_hz"].items()}
    fields = {str(k): {str(f) for f in v} for k, v in sysd["probe_fields"].items()}
    return rates, fields


def _load_model_vehicle(vehicle) -> Vehicle:
    if isinstance(vehicle, Vehicle):
        if vehicle.kind != "model":
            raise ReplayError(f"vehicle {vehicle.name} is a {vehicle.kind} file; the replay needs a model file")
        return vehicle
    from vdps_hil.model.params import VehicleFileError, load_vehicle

    try:
        return load_vehicle(vehicle, "model")
    except VehicleFileError as e:
        raise ReplayError(str(e).splitlines()[0]) from None


def _load_workbench_model(path, vehicle: Vehicle):
    """A saved workbench model (``vdps diagnose --save-model``; format and checks in
    ``vdps_hil.workbench.model_file``): (identified parameters that start the identifier, the
    model's effects: dynamics for the predictor, IMU measurement effects taken out of the
    readings by ``VdpsSystem``; a summary for the JSON). Errors are one line."""
    from vdps_hil.model.effects.base import MeasurementEffect
    from vdps_hil.workbench.model_file import ModelFileError, load_model

    try:
        veh, effects, mf = load_model(path, vehicle)
    except (ModelFileError, OSError, ValueError) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ReplayError(f"--model: {msg}") from None
    doc = {"file": str(path), "vehicle": mf.vehicle, "source": mf.source,
           "effects": [e.name for e in effects],
           "predictor_effects": [e.name for e in effects.dynamics],
           "imu_corrected": [e.name for e in effects if isinstance(e, MeasurementEffect)]}
    return veh.params, effects, doc


def replay_config(rates: Mapping[str, float], fields: Mapping[str, set], veh, susp_sigma_m, paper_faithful,
                  sensorset=None, **kw):
    """(SystemConfig, kind_map, sample nodes, sensor-set description) for a replay, from the
    sample ``rates`` and ``fields`` of the recording's first seconds (``sample_stats``): the rule
    of ``pipeline.configure.system_config``, its errors as :class:`ReplayError`."""
    try:
        return system_config(rates, fields, veh, susp_sigma_m, paper_faithful, sensorset, **kw)
    except SystemConfigError as e:
        raise ReplayError(str(e)) from None

