"""Timing of the bench, defined once: warning latency per pipeline output cycle, and lead times.

Warning latency
---------------
A *pipeline output cycle* is one call of the pipeline's ``handle(sample)``, for every sample
it receives (about 4000 per simulated second with the Table 1 rates): after it the pipeline has
acted on that sample and anything it outputs -- an estimate, a prediction, a ``VDPS_Warning``
frame (the system's warning node runs at its estimate instants, 100 Hz, and sends at 50 Hz and
on a level change) -- is out. Its input is the sensor frame (CAN) or serial read chunk that
carried the sample, i.e. the last sensor data the cycle -- and a prediction made in it -- used.
Then::

    L_k = t_bus,k - t_in,k                                       [wall ms]

    t_in,k   time the simulator put that sensor frame / the chunk's last byte onto its wire
             (the device side's send log, ``serial_device.SendLog``; the frame index or byte
             offset comes from the pipeline's count of what it received, exact when nothing is
             lost)
    t_bus,k  cycles that sent VDPS_Warning: the time the frame was on the bus, i.e. received
             by the simulator's end of the CAN bus (the ECU's receiver); matched to the
             pipeline's sends by order. Other cycles: the time ``handle`` returned (when a
             frame would have gone out had one been due).

So L includes the wire into the pipeline (pty, virtual bus, TCP), the adapter's read and
decoding, queueing behind earlier samples, the pipeline's computation (the estimator at every
IMU sample, the predictor at its cadence) and, for warning frames, the way back. The bench
reports p50, p99 and the maximum over all cycles (``warning_latency_ms``) and over the cycles
that sent a frame (``warning_frame_latency_ms``). All host times are CLOCK_MONOTONIC, the same
in every process of the host. Latencies are wall time, whatever ``--speed``.

Lead time (as ``experiments.scoring``)
--------------------------------------
``warning_lead_time_s = t_PONR - t_w`` and ``warning_lead_to_tipup_s = t_tip - t_w`` on the
bench's simulated time axis, with t_w the first accepted ``VDPS_Warning`` frame (CRC, counter,
status 0) with level >= 2 on the bus (``experiments.scoring.evaluate_warning_frames``) and
t_PONR, t_tip the truth events (``sim.rollover``) of this run. With ``--react`` the ECU may
prevent the point of no return; the lead time is then taken to the events of the *reference*
run: the same scenario without any ECU action (``reference = "open_loop"``), which the bench
simulates first (truth only: the harness may read truth, the pipeline never does).

Symbols: t times [s or ns as named]; L latency [ms]; k cycle index.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from .pacing import percentiles_ms
from .serial_device import SendLog

__all__ = ["SOURCES", "CycleLog", "cycle_latencies", "latency_summary", "lead_times",
           "reference_events"]

SOURCES = ("can", "imu", "gnss")
"""Input streams of a cycle, by code (0, 1, 2)."""


class CycleLog:
    """The pipeline's record of its output cycles (module docstring), one row per cycle:
    ``src`` (index in SOURCES), ``idx`` (0-based index of the input frame, or offset of the
    chunk's last byte, in that stream), ``m_out`` (monotonic ns when ``handle`` had returned and
    its outputs were sent), ``n_frames`` (warning frames sent), ``first_frame`` (0-based index of
    the first of them among all frames the pipeline sent)."""

    COLS = ("src", "idx", "m_out", "n_frames", "first_frame")

    def __init__(self):
        self._rows: list[tuple[int, int, int, int, int]] = []

    def add(self, src: int, idx: int, m_out: int, n_frames: int = 0, first_frame: int = -1) -> None:
        self._rows.append((src, idx, m_out, n_frames, first_frame))

    def __len__(self) -> int:
        return len(self._rows)

    def arrays(self) -> dict[str, np.ndarray]:
        a = np.asarray(self._rows, dtype=np.int64).reshape(-1, len(self.COLS))
        return {c: a[:, i] for i, c in enumerate(self.COLS)}

    @classmethod
    def from_arrays(cls, d: Mapping[str, np.ndarray]) -> "CycleLog":
        log = cls()
        cols = [np.asarray(d[c], dtype=np.int64) for c in cls.COLS]
        log._rows = [tuple(int(v) for v in row) for row in zip(*cols)]
        return log


def cycle_latencies(cycles: CycleLog, send_logs: Mapping[str, SendLog],
                    frame_bus_mono_ns: Sequence[int] | np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per-cycle ``t_in``, ``t_bus`` and ``latency_ns`` (module docstring); cycles whose input
    was never logged as sent (a lost item) get ``t_in = -1`` and are left out of
    ``latency_ns``. ``frame_bus_mono_ns``: bus times of the pipeline's warning frames in send
    order (None: use the pipeline's send times)."""
    a = cycles.arrays()
    n = len(a["src"])
    t_in = np.full(n, -1, dtype=np.int64)
    for code, name in enumerate(SOURCES):
        sel = a["src"] == code
        if sel.any() and name in send_logs:
            t_in[sel] = send_logs[name].time_of(a["idx"][sel])
    t_bus = a["m_out"].copy()
    has_frame = a["n_frames"] > 0
    if frame_bus_mono_ns is not None and has_frame.any():
        fb = np.asarray(frame_bus_mono_ns, dtype=np.int64)
        last = a["first_frame"] + a["n_frames"] - 1
        ok = has_frame & (last < len(fb)) & (last >= 0)
        t_bus[ok] = np.maximum(fb[last[ok]], t_bus[ok])
    good = t_in >= 0
    return {"t_in": t_in, "t_bus": t_bus, "has_frame": has_frame, "valid": good,
            "latency_ns": (t_bus - t_in)[good], "frame_latency_ns": (t_bus - t_in)[good & has_frame]}


def latency_summary(lat: Mapping[str, np.ndarray]) -> dict:
    """``warning_latency_ms`` (all cycles) and ``warning_frame_latency_ms`` (frame cycles):
    p50, p99, max [ms] and n."""
    return {"warning_latency_ms": percentiles_ms(lat["latency_ns"]),
            "warning_frame_latency_ms": percentiles_ms(lat["frame_latency_ns"]),
            "cycles": int(len(lat["t_in"])), "cycles_unmatched": int(np.count_nonzero(~lat["valid"]))}


def _event_t(events, kind: str) -> float:
    for e in events or ():
        if e.get("kind") == kind:
            return float(e["t_s"])
    return math.nan


def lead_times(frames: Sequence, events: Sequence[Mapping], reference: Sequence[Mapping] | None = None) -> dict:
    """Lead times of the warning frames on the bus (``can.Message`` with ``timestamp`` = bench
    time [s]) against this run's truth ``events``, or ``reference`` events when this run has no
    point of no return (module docstring)."""
    from vdps_hil.experiments.scoring import evaluate_warning_frames

    own_ponr = not math.isnan(_event_t(events, "point_of_no_return"))
    use_ref = not own_ponr and reference is not None and not math.isnan(_event_t(reference, "point_of_no_return"))
    ev = list(reference) if use_ref else list(events)
    out = evaluate_warning_frames(frames, ev)
    return {"warning_lead_time_s": out.lead_time_s, "warning_lead_to_tipup_s": out.lead_to_tip_up_s,
            "first_warning_t_s": out.first_warning_t_s, "first_imminent_t_s": out.first_imminent_t_s,
            "lead_reference": "open_loop" if use_ref else "this_run",
            "point_of_no_return_t_s": out.truth_point_of_no_return_t_s, "tip_up_t_s": out.truth_tip_up_t_s,
            "false_alarms": out.false_alarms, "warning_episodes": [list(e) for e in out.warning_episodes],
            "warning_frames_accepted": out.frames_accepted, "warning_frames_rejected": out.frames_rejected,
            "warning_frames_not_valid": out.frames_invalid_status, "warning_max_gap_s": out.max_gap_s}


def reference_events(drive) -> list[dict]:
    """Rollover events of ``drive``'s scenario without any ECU action (the truth simulator
    alone: fast, no sensors)."""
    from vdps_hil.sim.simulator import Simulator

    sim = Simulator(drive.vehicle, scenario=drive.scenario, effects=drive.effect_set, record_truth=False,
                    duration_s=drive.duration_s)
    sim.run(drive.duration_s)
    return sim.events
