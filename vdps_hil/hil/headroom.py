"""The bench's headroom on this machine, measured before the run (``vdps bench`` prints it and
refuses a run that cannot keep up).

Measurement (``measure_headroom``, about ``(warm_s + probe_s) / speed`` + 2 s of wall time per probe)
----------------------------------------------------------------------------------------------------
The bench itself runs first, briefly: the same drive (scenario, vehicle, profile, faults, seed),
the same transport, wires, adapters, pipeline and start parameters, for ``warm_s + probe_s``
simulated seconds at the run's own speed (at most ``PROBE_SPEED``, 1x; a probe whose pipeline
skipped work -- a machine too slow for that speed -- is repeated at half the speed, twice at
most), without recording and without the ECU's reaction. When that leaves less than
``WARN_BELOW`` headroom, a second probe runs at the speed it says has ``WARN_BELOW`` (where
``--speed auto`` will run) and its cost is the one kept: the bench costs more per simulated
second at a lower speed (fewer items per send pass and per wake-up: 0.70 s of CPU per
simulated second at 0.5x against 0.51 s at 1x over TCP, 2026-12-05), so a cost measured at one
speed and applied at another must come from the slower one. The CPU time spent by each side between the simulated
instants ``warm_s`` (the compiled kernels loaded, the filter initialised) and the end of the
probe, per simulated second, is the cost::

    c_sim  = CPU s per simulated s of the simulator side (physics, sensors, wire encoding,
             pacing and sending: the threads ``bench-sim`` and ``bench-can-rx``; the bench's
             process when the pipeline runs in a child)
    c_pipe = CPU s per simulated s of the pipeline side (reading the wires, decoding, the
             system's handle, the deadline checks: the rest of the process, or the child)
    H      = 1 / (X (c_sim + c_pipe))          headroom at speed X

Why the live run and CPU time: the first version of this probe timed the simulator and the
chain offline (a recording, bulk-decoded), which leaves out the wires, the per-frame decoders,
the reader threads and the pacing; the live bench then cost 2.5-3x what the probe said, so a
"2.1x" machine missed deadlines at 1x and its warning came too late (the bench tests failed under
CI at the speed the probe chose). CPU time, not wall time, because a probe below real time
would otherwise count its own waiting. The second version probed at 0.5x always and applied
that cost at 1x: 1.4x where the cost at 1x gives 2.0x. The sum is the cost when both sides
share one core: the embedded bench's threads share one interpreter lock, and the two processes
of ``--can tcp`` share a core when the other one is busy. The prediction worker (its own
process, off the sample path) is not counted.

Policy (``check``): ``H < REFUSE_BELOW`` (1x: the pipeline would fall behind from the first
second) refuses the run (one line, exit 2; ``vdps bench --no-headroom-check`` runs anyway);
``H < WARN_BELOW`` (2x) runs with a warning; the summary states ``H`` either way;
``supported_speed`` is the highest speed with ``WARN_BELOW`` headroom (what ``--speed auto``
and the real-time tests run at).
"""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass, replace

__all__ = ["Headroom", "measure_headroom", "REFUSE_BELOW", "WARN_BELOW", "DEFAULT_PROBE_S", "PROBE_SPEED"]

REFUSE_BELOW = 1.0
"""A measured headroom below this refuses the run (module docstring)."""
WARN_BELOW = 2.0
"""A measured headroom below this runs with a warning (module docstring)."""
DEFAULT_PROBE_S = 0.6
"""Simulated seconds timed by the probe (after ``warm_s``)."""
PROBE_SPEED = 1.0
"""The highest speed the first probe runs at (module docstring)."""


@dataclass
class Headroom:
    """One measurement (module docstring); costs in CPU s per simulated s of the live bench
    (``sim_cpu``/``pipeline_cpu``: the same figures, kept under the names of the first probe's
    JSON); ``wall_s``: how long the measurement took; ``probe_speed``: the speed the probe ran
    at; ``probe_shed``: samples its pipeline still skipped (0 unless the machine is far slower
    than the probe's speed allows)."""

    speed: float
    probe_s: float
    sim_cost: float
    pipeline_cost: float
    wall_s: float
    sim_cpu: float = math.nan
    pipeline_cpu: float = math.nan
    probe_speed: float = math.nan
    probe_shed: int = 0

    @property
    def cpu_cost(self) -> float:
        return self.sim_cpu + self.pipeline_cpu

    @property
    def cost(self) -> float:
        return self.sim_cost + self.pipeline_cost

    @property
    def headroom(self) -> float:
        return 1.0 / (self.speed * self.cost) if self.cost > 0 else math.inf

    @property
    def supported_speed(self) -> float:
        """The highest speed with ``WARN_BELOW`` headroom (what a test on this machine runs at)."""
        return 1.0 / (WARN_BELOW * self.cost) if self.cost > 0 else math.inf

    def verdict(self) -> str:
        h = self.headroom
        return "refuse" if h < REFUSE_BELOW else "warn" if h < WARN_BELOW else "ok"

    def to_json(self) -> dict:
        return {"headroom": self.headroom, "speed": self.speed, "probe_s": self.probe_s,
                "simulator_cost_s_per_s": self.sim_cost, "pipeline_cost_s_per_s": self.pipeline_cost,
                "measure_wall_s": self.wall_s, "verdict": self.verdict(), "simulator_cpu_s_per_s": self.sim_cpu,
                "pipeline_cpu_s_per_s": self.pipeline_cpu, "probe_speed": self.probe_speed,
                "probe_samples_skipped": self.probe_shed, "refuse_below": REFUSE_BELOW, "warn_below": WARN_BELOW}

    def describe(self) -> str:
        return (f"headroom {self.headroom:.1f}x at speed {self.speed:g}x, measured on this machine before the run "
                f"(a {self.probe_speed:.2g}x probe run of the bench: simulator {1e3 * self.sim_cost:.0f} ms + "
                f"pipeline {1e3 * self.pipeline_cost:.0f} ms of CPU per simulated second)")


def measure_headroom(bench, probe_s: float = DEFAULT_PROBE_S, warm_s: float = 0.3,
                     probe_speed: float | None = None) -> Headroom:
    """Measure the headroom of ``bench`` (a :class:`~vdps_hil.hil.bench.Bench`) at its speed by
    running it briefly (module docstring). The probe never shortens: a drive shorter than
    ``warm_s + probe_s`` is probed over its whole length after ``warm_s``. ``probe_speed``: the
    first probe's speed (default: the bench's, at most ``PROBE_SPEED``). Raises the bench's own
    ``BenchError`` when the probe run cannot run."""
    c = bench.config
    total_s = min(warm_s + probe_s, bench.drive.duration_s)
    warm_s = min(warm_s, 0.5 * total_s)
    w0 = time.perf_counter()
    speed = min(float(c.speed), PROBE_SPEED) if probe_speed is None else float(probe_speed)
    sim_cost, pipe_cost, speed, shed = _probe(bench, total_s, warm_s, speed)
    cost = sim_cost + pipe_cost
    slower = 1.0 / (WARN_BELOW * cost) if cost > 0 else math.inf
    if not shed and probe_speed is None and 1.0 / (c.speed * cost) < WARN_BELOW and slower < 0.9 * speed:
        # the run will go slower (--speed auto, a loaded machine): the cost there, where the
        # bench spends more per simulated second (fewer items per pass and per wake-up)
        again = _probe(bench, total_s, warm_s, _floor_2_digits(slower))
        if not again[3]:
            sim_cost, pipe_cost, speed, shed = again
    return Headroom(float(c.speed), total_s - warm_s, sim_cost, pipe_cost, time.perf_counter() - w0,
                    sim_cost, pipe_cost, probe_speed=speed, probe_shed=int(shed))


def _floor_2_digits(x: float) -> float:
    """``x`` > 0 rounded down to two significant digits (0.897 -> 0.89): the second probe's speed
    stays at or below the speed with ``WARN_BELOW`` headroom (rounding to nearest made 0.897 a
    0.9x probe, no slower than the first's 0.9 limit)."""
    q = 10.0 ** (math.floor(math.log10(x)) - 1)
    return float(f"{math.floor(x / q + 1e-9) * q:.2g}")


def _probe(bench, total_s: float, warm_s: float, speed: float) -> tuple[float, float, float, int]:
    """One probe (repeated at half the speed, twice at most, while its pipeline skipped work):
    (simulator cost, pipeline cost, the speed it ran at, samples it skipped)."""
    c = bench.config
    for attempt in range(3):
        marks: list[tuple[float, float, float]] = []  # (simulated s, simulator CPU s, pipeline CPU s)
        cross = [False]
        seen: dict[int, float] = {}  # simulator-side thread -> its CPU s when last seen

        def status(s, marks=marks):
            if s["final"]:
                return
            pids = s["pids"]
            cross[0] = pids["pipeline"] != pids["simulator"]
            marks.append((s["t_s"], *_cpu_s(pids["pipeline"], cross[0], seen)))

        probe = type(bench)(replace(c, speed=speed, duration_s=total_s, react=False, output=None))
        probe.status_period_s = min(0.25, 0.05 / speed)
        doc = probe.run(status).to_json()
        shed = doc["deadline_misses"]["samples"]
        if not shed or attempt == 2:
            break
        speed /= 2
    return (*_cost(marks, warm_s), speed, int(shed))


_SIM_THREADS = ("bench-sim", "bench-can-rx")
"""The simulator side's threads in the bench's process (``hil.bench``, ``hil.simside``)."""


def _cpu_s(pipeline_pid: int, cross_process: bool, seen: dict[int, float]) -> tuple[float, float]:
    """(simulator side, pipeline side) CPU seconds so far (module docstring); per thread from
    ``/proc`` on Linux (``seen`` keeps a thread's last figure after it ended: the process total
    still holds its time), else the whole process counts as the pipeline side."""
    total = time.process_time()
    if cross_process:
        return total, _proc_cpu_s(f"/proc/{pipeline_pid}/stat")
    for th in threading.enumerate():
        if th.name in _SIM_THREADS and th.native_id is not None:
            cpu = _proc_cpu_s(f"/proc/self/task/{th.native_id}/stat")
            seen[th.native_id] = max(cpu, seen.get(th.native_id, 0.0))
    sim = sum(seen.values())
    return sim, total - sim


def _proc_cpu_s(path: str) -> float:
    """utime + stime of a ``/proc/.../stat`` file [s]; 0 when it cannot be read."""
    try:
        with open(path) as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def _cost(marks: list[tuple[float, float, float]], warm_s: float) -> tuple[float, float]:
    """(simulator, pipeline) CPU s per simulated s between the first mark at or after
    ``warm_s`` and the last."""
    if not marks:
        return 0.0, 0.0
    first = next((m for m in marks if m[0] >= warm_s), marks[0])
    last = marks[-1]
    dt = last[0] - first[0]
    return ((last[1] - first[1]) / dt, (last[2] - first[2]) / dt) if dt > 0 else (0.0, 0.0)
