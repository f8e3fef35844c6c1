"""The fixed-step clock shared by the truth backends (``sim.simulator.Simulator``,
``sim.truth_cr.CommonRoadTruth``): time is an integer step count n with t_ns = n dt_ns exactly,
truth snapshots every ``truth_every`` steps, step hooks after every step (the sensors' recorder),
``step_to`` / ``run``, and one explicit Runge-Kutta step with the inputs held over it::

    rk2 (Heun):  k2 = f(x + h k1);  x+ = x + h/2 (k1 + k2)
    rk4:         k2 = f(x + h/2 k1), k3 = f(x + h/2 k2), k4 = f(x + h k3);
                 x+ = x + h/6 (k1 + 2 (k2 + k3) + k4)

A subclass sets ``n``, ``stopped``, ``duration_s``, ``_step_hooks``, ``record_truth``, ``truth``
and ``_on_truth``, calls
:meth:`FixedStepTruth._init_clock`, and implements ``step()`` (ending with ``_after_step()``) and
``_emit_truth()``.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

from vdps_hil.model.core import Inputs
from vdps_hil.units import NS_PER_S

__all__ = ["SimulationError", "FixedStepTruth", "InputSource", "input_row", "rk_step", "schedule_columns", "snapshot_ltr",
           "INTEGRATORS"]

INTEGRATORS = ("rk2", "rk4")
InputSource = Callable[[float, Sequence[float]], Inputs]
"""``source(t_s, x) -> Inputs``: an open-loop schedule or a closed-loop driver."""


class SimulationError(RuntimeError):
    """The simulation cannot go on (bad configuration, non-finite state)."""


def rk_step(f: Callable[[list], list], x: Sequence[float], k1: Sequence[float], h: float,
            integrator: str) -> list[float]:
    """x after one step h of ``integrator`` ("rk2" or "rk4"); ``k1 = f(x)`` is given (callers
    cache it), ``f`` holds the inputs fixed."""
    if integrator == "rk4":
        hh = 0.5 * h
        k2 = f([a + hh * b for a, b in zip(x, k1)])
        k3 = f([a + hh * b for a, b in zip(x, k2)])
        k4 = f([a + h * b for a, b in zip(x, k3)])
        h6 = h / 6.0
        return [a + h6 * (b + 2.0 * (c + d) + e) for a, b, c, d, e in zip(x, k1, k2, k3, k4)]
    k2 = f([a + h * b for a, b in zip(x, k1)])
    h2 = 0.5 * h
    return [a + h2 * (b + c) for a, b, c in zip(x, k1, k2)]


def input_row(u: Inputs) -> tuple[float, ...]:
    """(steering wheel angle, drive torques 1-4, brake torques 1-4): one row of inputs."""
    return (u.steer_wheel_angle_rad, *u.wheel_torque_nm, *u.brake_torque_nm)


def schedule_columns(signals) -> Callable[[Sequence[float]], list[list[float]]]:
    """``columns(times)``: the 9 input channels (``input_row`` order) of a scenario's open-loop
    schedule (its ``signals``) at those times, the values ``Scenario.schedule_function`` gives
    without a base (channels not in the schedule zero, brakes max(0, signal))."""
    fns = [signals.get(c) for c in ("steer_wheel_angle_rad", *(f"wheel_torque_nm_{i}" for i in range(1, 5)))]
    bfs = [signals.get(f"brake_torque_nm_{i}") for i in range(1, 5)]

    def columns(times):
        zero = [0.0] * len(times)
        return ([[f(t) for t in times] if f is not None else zero for f in fns]
                + [[max(0.0, f(t)) for t in times] if f is not None else zero for f in bfs])

    return columns


def snapshot_ltr(s: dict) -> float:
    """The truth snapshot's load transfer ratio (F_right - F_left) / sum of ``normal_load_n_i``
    (wheels 1..4 = FL FR RR RL); 0 when the loads sum to zero or less."""
    fl = s["normal_load_n_1"] + s["normal_load_n_4"]
    fr = s["normal_load_n_2"] + s["normal_load_n_3"]
    return (fr - fl) / (fr + fl) if fr + fl > 0 else 0.0


class FixedStepTruth:
    """Clock, hooks and run control of a steppable truth (module docstring)."""

    n: int
    dt_ns: int
    dt_s: float
    stopped: bool
    duration_s: float | None
    _truth_every: int
    _step_hooks: list
    record_truth: bool
    truth: list
    _on_truth: Callable | None

    def _init_clock(self, dt_s: float, truth_rate_hz: float, integrator: str) -> None:
        """Check and set the step (<= 1 ms, dividing the truth period) and the integrator."""
        if integrator not in INTEGRATORS:
            raise SimulationError(f"unknown integrator {integrator!r} (rk4 or rk2)")
        self.integrator = integrator
        dt_ns = int(round(dt_s * NS_PER_S))
        truth_ns = int(round(NS_PER_S / truth_rate_hz))
        if dt_ns <= 0 or dt_ns > 1_000_000 or truth_ns % dt_ns:
            raise SimulationError(f"dt_s must be <= 1 ms and divide the truth period {truth_ns} ns; got {dt_s}")
        self.dt_ns = dt_ns
        self.dt_s = dt_ns / NS_PER_S
        self._truth_every = truth_ns // dt_ns

    def _init_inputs(self, inputs, scenario, model, env) -> None:
        """The input source: ``inputs`` (Inputs held, or a source), else the scenario's schedule
        or driver (reading ``model`` and ``env``), else zero inputs; no override.
        ``_time_only``: the source is a function of time alone (held inputs or a schedule
        without a driver), so the inputs of several steps may be sampled ahead."""
        cols = None
        if inputs is None and scenario is not None:
            if scenario.driver_spec is None:
                sched = scenario.schedule_function()
                inputs = lambda t, x: sched(t)  # noqa: E731  (as Scenario.input_source without a driver)
                cols = schedule_columns(scenario.signals)
            else:
                inputs = scenario.input_source(model, env)
        if inputs is None:
            inputs = Inputs()
        if isinstance(inputs, Inputs):
            row = input_row(inputs)
            cols = lambda ts, _r=row: [[v] * len(ts) for v in _r]  # noqa: E731
        self._source = (lambda t, x, _u=inputs: _u) if isinstance(inputs, Inputs) else inputs
        self._time_columns = cols
        self._time_only = cols is not None
        self._time_source = self._source  # the source the columns describe (replaced: not time-only)
        self._override = None

    @property
    def t_s(self) -> float:
        return self.n * self.dt_ns / NS_PER_S

    @property
    def t_ns(self) -> int:
        return self.n * self.dt_ns

    def add_step_hook(self, fn: Callable) -> None:
        """Call ``fn(sim)`` after every integration step (e.g. a 1 kHz sensor model)."""
        self._step_hooks.append(fn)

    def _after_step(self) -> bool:
        """Hooks, then the truth snapshot when one is due; False when stopped."""
        for hook in self._step_hooks:
            hook(self)
        if self.n % self._truth_every == 0:
            self._emit_truth()
        return not self.stopped

    def _emit_truth(self) -> None:
        raise NotImplementedError

    def _deliver_truth(self, s: dict) -> None:
        """Keep the snapshot (``record_truth``) and hand it to ``on_truth``."""
        if self.record_truth:
            self.truth.append(s)
        if self._on_truth is not None:
            self._on_truth(s)

    def step(self) -> bool:
        raise NotImplementedError

    def step_n(self, n_target: int) -> int:
        """Step to step count ``n_target`` (or until stopped); returns the step count reached."""
        while self.n < n_target and not self.stopped:
            self.step()
        return self.n

    def step_to(self, t_s: float) -> float:
        """Advance to the last step time <= t_s (or until stopped). Returns the time reached."""
        self.step_n(int(math.floor(t_s * NS_PER_S / self.dt_ns + 1e-9)))
        return self.t_s

    def run(self, duration_s: float | None = None) -> list[dict]:
        """Step to ``duration_s`` (default: the scenario's) and return the truth snapshots."""
        d = duration_s if duration_s is not None else self.duration_s
        if d is None:
            raise SimulationError("no duration: give run(duration_s) or a scenario")
        self.step_to(d)
        return self.truth
