"""Predictions off the sample path: the warning chain's prediction jobs run in a worker (the
second core) and their results are used at a deadline in bus time, so the sample path never
waits for a prediction and a replay reproduces the live outputs bit for bit.

The job and its deadline
------------------------
At a prediction instant t0 (the chain's cadence, bus time) the chain hands the worker a
snapshot: the predictor's identified parameters and the :class:`PredictorInitialState` built
from the estimate at t0 (both immutable). The worker computes::

    job(params, init) = RolloverAssessment(Predictor(vehicle with params).predict(init))
                        or the failure "Type: message" (a diverging prediction)

The result is *used* at the first chain tick with t >= t0 + ``prediction_latency_s`` (the
deadline; ``[warning]`` of ``configs/prediction/default.toml``, a configured and recorded
figure), never earlier, whatever the worker's speed. What happens at the deadline is the
chain's ``deadline`` rule:

* ``"drop"`` (live: the bench, ``vdps log --pipeline``): a job not finished is dropped
  (cancelled if it has not started, its result discarded if it has), counted
  (``WarningChain.drops``, its t0 in ``WarningChain.dropped_t0_ns``), and every frame from then
  until the next used prediction carries status 3 "fault" (the level is still sent, from the
  last prediction used). The sample path only asks ``future.done()``.
* ``"wait"`` (replay): the chain waits for the result, so a replay has no deadline miss *by
  construction*; a live run's misses are *reproduced from the record*: the replay is given the
  live run's dropped t0s (``drop_t0_ns``) and drops exactly those jobs (it does not compute
  them). Same input order + same drops = same outputs, bit for bit (``tests/test_offpath.py``).

Which worker (``WORKERS``)
--------------------------
* ``"inline"``: the job runs in the calling thread at t0 (the reference; a deadline is then
  never missed). Identical results to the others: the same compiled code on the same inputs.
* ``"thread"``: one worker thread. The prediction's kernel
  (``prediction.integration_kernel.reduced_loop``) is compiled with ``nogil=True`` (every kernel
  of ``vdps_hil.jit`` is), but the predictor's set-up around it (initial state, the specialised
  core for new parameters, the result and its rollover measures) is Python holding the GIL:
  ``tools/bench_offpath.py`` measures how much of that lands on the sample path.
* ``"process"``: one worker process (``spawn``: no fork of a threaded process); the snapshot and
  the assessment cross as pickles of a few hundred bytes; the predictor is built once in the
  worker from the same vehicle, config and effects. It starts in about a second (numba and the
  kernel cache); until it answers, live deadlines are missed (counted), a replay waits. As for
  any ``multiprocessing`` start, a script that runs a live system guards its top level with
  ``if __name__ == "__main__":`` (the worker imports the main module). A worker that died
  makes every later job a counted failure ("fault"), never an exception on the sample path.

Layer 8 (prediction): imports only what the predictor does.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from typing import Mapping

from .assessment import RolloverAssessment
from .initial_state import PredictorInitialState
from .predictor import Predictor

__all__ = ["DEADLINES", "WORKERS", "PredictionRunner", "prediction_job"]

WORKERS = ("inline", "thread", "process")
DEADLINES = ("wait", "drop")

_FAILURES = (OverflowError, ZeroDivisionError, FloatingPointError, ValueError)


def prediction_job(predictor: Predictor, init: PredictorInitialState):
    """One job (module docstring): (RolloverAssessment, None) or (None, "Type: message").
    A diverging or absurd prediction (an estimate far outside the model's range) is a failure
    the chain counts and reports as "fault", never an exception on the warning path."""
    try:
        r = predictor.predict(init)
        if r.stop_reason == "non_finite":  # the compiled core overflows to inf, not OverflowError
            raise FloatingPointError(f"the prediction diverged (non-finite state after {r.n_steps} steps)")
        return RolloverAssessment.from_prediction(r), None
    except _FAILURES as e:
        return None, f"{type(e).__name__}: {e}"


class _Predictors:
    """The base predictor and the one for the latest parameters (rebuilt when they change)."""

    def __init__(self, base: Predictor):
        self.base = base
        self.current = base
        self._key: tuple | None = None

    def select(self, params: Mapping[str, float] | None) -> Predictor:
        if params is not None:
            key = tuple(sorted(params.items()))
            if key != self._key:
                self.current = self.base.with_params(params)
                self._key = key
        return self.current

    def job(self, params: Mapping[str, float] | None, init: PredictorInitialState):
        return prediction_job(self.select(params), init)


_WORKER_STATE: _Predictors | None = None


def _warm(predictors: _Predictors) -> int:
    """One prediction from a straight run at 20 m/s (loads the compiled kernels in a worker
    before the first real job; the result is not used)."""
    v, r = 20.0, predictors.base.vehicle.tire.rolling_radius_m
    init = PredictorInitialState(t_ns=0, pos_g_m=(0.0, 0.0, 0.0), vel_g_mps=(v, 0.0, 0.0), euler_g_rad=(0.0, 0.0, 0.0),
                                 road_bank_rad=0.0, road_grade_rad=0.0, rate_b_radps=(0.0, 0.0, 0.0),
                                 wheel_speed_radps=(v / r,) * 4)
    prediction_job(predictors.base, init)
    return 1


def _process_init(vehicle, config, effects, fast) -> None:
    global _WORKER_STATE
    _WORKER_STATE = _Predictors(Predictor(vehicle, config, effects, fast=fast))


def _process_warm() -> int:
    return _warm(_WORKER_STATE)


def _process_job(params, init):
    return _WORKER_STATE.job(params, init)


class _Done:
    """A finished future (the inline worker)."""

    def __init__(self, value):
        self._value = value

    def done(self) -> bool:
        return True

    def result(self, timeout=None):
        return self._value

    def cancel(self) -> bool:
        return False


class PredictionRunner:
    """``submit(params, init) -> future`` of :func:`prediction_job` on ``worker`` (module
    docstring); ``params``: the identified parameters as a mapping (None: the base predictor's).
    The base predictor's vehicle, config and effects are the worker's for the whole run."""

    def __init__(self, predictor: Predictor, worker: str = "inline"):
        if worker not in WORKERS:
            raise ValueError(f"prediction worker must be one of {', '.join(WORKERS)}, got {worker!r}")
        self.worker = worker
        self._local = _Predictors(predictor)
        self._params: Mapping[str, float] | None = None
        self._pool: cf.Executor | None = None
        if worker == "thread":
            self._pool = cf.ThreadPoolExecutor(1, thread_name_prefix="vdps-predict")
        elif worker == "process":
            ctx = multiprocessing.get_context("spawn")
            fast = predictor.reduced_core is not None
            self._pool = cf.ProcessPoolExecutor(1, mp_context=ctx, initializer=_process_init,
                                                initargs=(predictor.vehicle, predictor.config, predictor.effects, fast))
        self._started = None if self._pool is None else self._pool.submit(
            _process_warm if worker == "process" else _warm, *(() if worker == "process" else (self._local,)))
        """The worker's start (process start-up, kernels loaded): :meth:`ready`."""

    @property
    def predictor(self) -> Predictor:
        """The predictor of the latest parameters submitted (for the process worker built here
        only when asked)."""
        return self._local.select(self._params)

    def submit(self, params: Mapping[str, float] | None, init: PredictorInitialState):
        self._params = params if params is not None else self._params
        if self.worker == "inline":
            return _Done(self._local.job(params, init))
        try:
            if self.worker == "thread":
                return self._pool.submit(self._local.job, params, init)
            return self._pool.submit(_process_job, params, init)
        except (RuntimeError, AttributeError) as e:  # a dead (BrokenExecutor) or closed worker: a counted failure
            return _Done((None, f"prediction worker: {type(e).__name__}: {e}"))

    def ready(self, timeout_s: float | None = None) -> bool:
        """Wait (at set-up, never on the sample path) until the worker has started and run one
        prediction; False if it has not within ``timeout_s`` (its jobs are then dropped live
        until it has, or waited for in a replay)."""
        if self._started is None:
            return True
        try:
            self._started.result(timeout_s)
        except (cf.TimeoutError, cf.BrokenExecutor):
            return False
        return True

    def close(self) -> None:
        """Stop the worker: jobs not started are cancelled, the running one (a few ms) finishes,
        and the pool's threads are joined, so none writes to a closed pipe while the process
        exits (``shutdown(wait=False)`` left a "Bad file descriptor" traceback on a bench
        child's stderr)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
