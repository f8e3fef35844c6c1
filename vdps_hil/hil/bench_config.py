"""What the bench runs and the pipeline it builds: :class:`BenchConfig` (the ``vdps bench``
options), the model vehicle file paired with a truth file, saved start parameters, the bench's
``VdpsSystem`` (:func:`make_system`, also in the pipeline process ``hil.child``) and the
calibration drive before a bench run (:func:`calibrate`)."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from .ecu import ActuatorConfig
from .pacing import DEFAULT_LATE_TOLERANCE_S

__all__ = ["BenchConfig", "BenchError", "calibrate", "make_system", "model_for", "params_not_settled", "start_point",
           "warm_pipeline_kernels"]


class BenchError(RuntimeError):
    """The bench could not run (one-line message)."""


@dataclass
class BenchConfig:
    """What to run (``vdps bench`` options). Times [s]."""

    scenario: str = "fishhook-suv"
    vehicle: str | None = None
    model: str | None = None
    effects: tuple[str, ...] = ()
    faults: tuple[str, ...] = ()
    duration_s: float | None = None
    speed: float = 1.0
    can: str = "virtual"
    sim_can: str | None = None
    react: bool = False
    output: str | None = None
    seed: int = 0
    profile: str | None = None
    actuator: ActuatorConfig = field(default_factory=ActuatorConfig)
    block_s: float = 0.02  # simulated per pass; + lookahead (20 ms) stays far below the ECU dead time (100 ms)
    lookahead_s: float = 0.02
    late_tolerance_s: float = DEFAULT_LATE_TOLERANCE_S
    drain_timeout_s: float = 3.0
    max_lag_s: float = 0.25
    switch_interval_s: float | None = 0.001
    readers: str = "inline"  # the pipeline reads its adapters in its own loop (``hil.node``), or "threads"
    start_delay_s: float = 0.3
    params: str | None = None  # saved identified parameters the pipeline starts from (``hil.bench`` docstring)
    rt_priority: int | None = None  # SCHED_FIFO priority of the run's threads (``hil.scheduling``); None: untouched


def model_for(truth_name: str) -> str:
    """The model vehicle file paired with a truth file (``suv-truth`` -> ``suv-model``)."""
    stem = Path(truth_name).name
    if stem.endswith(".toml"):
        stem = stem[:-5]
    if stem.endswith("-truth"):
        return stem[:-6] + "-model"
    raise BenchError(f"no model file paired with vehicle {truth_name!r}: give --model FILE")


def _saved_params(model: str, params: str):
    from vdps_hil.identification.persistence import load_params
    from vdps_hil.model.params import load_vehicle

    return load_params(params, load_vehicle(model, "model"))


def params_not_settled(model: str, params: str) -> dict:
    """What the parameter file had not settled when saved, as ``vdps replay``'s JSON says it:
    {"params_unsettled": problem -> status, "params_not_identified": parameter -> status or None}
    (empty when it settled everything; ``ParamsFileError``, a ValueError, when it is unusable)."""
    from vdps_hil.identification.persistence import not_settled

    return not_settled(_saved_params(model, params))


def start_point(model: str, params: str):
    """(identified parameters, problems the file did not settle) of the parameter file
    ``params`` for the model vehicle file ``model`` (``identification.persistence``;
    ``ParamsFileError``, a ValueError, when the file is unusable)."""
    from vdps_hil.identification.persistence import unsettled_problems

    saved = _saved_params(model, params)
    return saved.params, tuple(unsettled_problems(saved))


def calibrate(scenario: str, truth_vehicle: str, model: str, directory: str | os.PathLike, *,
              profile: str | None = None, seed: int = 1000) -> dict:
    """A calibration drive before the bench, as a car's first drive: the simulator drives
    ``scenario`` with the bench's truth vehicle, the drive is recorded and replayed through the
    chain with the identifier (``vdps replay --save-params``), and the identified parameters are
    saved in ``directory``. Returns {scenario, seed, params (file), converged (per problem),
    cpu_s}. The chain of the replay reads only the recording's /raw/ topics and the model file."""
    from vdps_hil.sim.drive import CONFIG_ERRORS, DEFAULT_PROFILE, Drive
    from vdps_hil.app.replay import ReplayError, replay_file

    d = Path(directory)
    rec, out = d / f"calibration-{scenario}.mcap", d / f"calibration-{scenario}-params.json"
    t0 = time.process_time()
    try:
        Drive(scenario, profile=profile or DEFAULT_PROFILE, seed=seed, vehicle=truth_vehicle).run(rec)
        doc = replay_file(rec, vehicle=model, predict=False, save_params=out)
    except CONFIG_ERRORS + (ReplayError,) as e:
        raise BenchError(f"--calibrate {scenario}: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
    return {"scenario": scenario, "seed": seed, "params": str(out),
            "converged": dict(doc["identification"]["converged"]), "cpu_s": time.process_time() - t0}


def make_system(model: str, susp_rate_hz: float, susp_sigma_m: float, params: str | None = None, *,
                live: bool = False, drops: tuple[int, ...] = ()):
    """The VDPS pipeline for the bench: ``VdpsSystem`` with the model vehicle file and the
    suspension sensor's rate and noise (its data sheet, from the sensor profile; not truth),
    started from the priors or from a saved parameter file ``params``.

    ``live`` (the bench's own pipeline): predictions in a worker process, dropped when late,
    and no replay log held (``pipeline.node.LIVE_PREDICTIONS``); the worker is started and
    warmed here, before the run. Else (a replay of a bench recording) the replay rule, with ``drops`` the live run's
    dropped predictions (``hil.input_order`` setting ``prediction``).

    ``model`` may also be a saved workbench model (``vdps diagnose --save-model``, schema
    ``vdps-model``): then the vehicle file it names, its identified parameters as the
    identifier's start and its effects in the chain, as ``vdps replay --model`` (with a
    parameter file as well: refused)."""
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.pipeline.node import SystemConfig, VdpsSystem

    saved = _saved_workbench_model(model)
    if saved is None:
        vehicle = load_vehicle(model, "model")
        start, unsettled = start_point(model, params) if params is not None else (None, ())
        return _ready(VdpsSystem(vehicle, SystemConfig.for_profile(susp_rate_hz, susp_sigma_m, start_params=start,
                                                                   start_unsettled=unsettled,
                                                                   **_prediction_kw(live, drops))))
    if params is not None:
        raise BenchError("give --params or a saved workbench model as --model (it carries its parameters), not both")
    from vdps_hil.workbench.model_file import ModelFileError, load_model

    try:
        vehicle = load_vehicle(saved.vehicle, "model")
        refined, effects, _ = load_model(model, vehicle)
    except (ModelFileError, ValueError) as e:
        raise BenchError(f"--model {model}: {str(e).splitlines()[0]}") from None
    cfg = SystemConfig.for_profile(susp_rate_hz, susp_sigma_m, start_params=refined.params, model_effects=effects,
                                   **_prediction_kw(live, drops))
    return _ready(VdpsSystem(vehicle, cfg))


WORKER_START_S = 60.0
"""How long set-up waits for the prediction worker to start (a loaded machine: seconds)."""


def _prediction_kw(live: bool, drops) -> dict:
    from vdps_hil.pipeline.node import LIVE_PREDICTIONS

    return dict(LIVE_PREDICTIONS) if live else {"prediction_drops_t0_ns": tuple(int(t) for t in drops)}


def _ready(system):
    system.ready(WORKER_START_S)
    return system


def warm_pipeline_kernels() -> None:
    """Load the pipeline's compiled kernels (``vdps_hil.jit``) before the bench clock starts: the
    first call of a kernel in a process loads its machine code from the cache (0.5-3 s for all of
    them, more on a loaded machine), which on the clock is a deadline miss at the start of every
    run. The simulator's kernels are left out (the pipeline process never imports the
    simulator). One VDPS_Warning frame is encoded and thrown away for the same reason: the first
    encode once imported cantools and parsed the DBC (0.1-0.25 s quiet), which in the first
    output cycle made every bench run start 90-150 ms late and skip its first 250-1100 samples;
    it now compiles the message's layout (``codecs.can_encode``), a smaller first cost."""
    from vdps_hil import jit
    from vdps_hil.codecs.can_encode import warning_frame

    jit.warm(skip=("vdps_hil.sim.",))
    warning_frame(0, None, 0.0, 0.0, 0, 0)


def _saved_workbench_model(path: str):
    """The parsed workbench model file at ``path``, or None when ``path`` is not one (a vehicle
    file or name)."""
    p = Path(path)
    if p.suffix.lower() not in (".toml", ".json") or not p.is_file():
        return None  # a vehicle name: the workbench (scipy and all, ~1 s) is not imported
    from vdps_hil.workbench.model_file import ModelFileError, read_model

    try:
        return read_model(p)
    except ModelFileError:
        return None

