"""The bench's headroom on this machine, measured before the run (``vdps bench`` prints it and
refuses a run that cannot keep up).

Measurement (``measure_headroom``, about ``probe_s`` + 1 s of wall time on an ordinary machine)
------------------------------------------------------------------------------------------------
The bench's own drive (scenario, vehicle, profile, faults, seed) is simulated offline for
``warm_s + probe_s`` simulated seconds into a temporary recording, and the recording is decoded
and fed through the bench's own pipeline (``make_system``: the model vehicle, the start
parameters), as fast as this machine runs them now, under whatever else it runs now. The first
``warm_s`` simulated seconds of each part are not timed (they load the compiled kernels); of the
rest::

    c_sim  = wall s per simulated s of the simulator (physics, sensors, wire encoding, writing)
    c_pipe = wall s per simulated s of the pipeline (decoding, the system's handle, /est/ docs)
    H      = 1 / (X (c_sim + c_pipe))          headroom at speed X

The sum is the cost when both share one core: the embedded bench (one process), or the two
processes of ``--can tcp`` on a machine whose other core is busy; on two free cores they have
up to twice ``H``. The live pipeline also reads its wires (the adapters' threads, ptys,
sockets) and the bench paces and times every send, which the probe leaves out: hence the 2x
the bench wants.

Policy (``check``): ``H < REFUSE_BELOW`` (1x: the pipeline would fall behind from the first
second) refuses the run (one line, exit 2; ``vdps bench --no-headroom-check`` runs anyway);
``H < WARN_BELOW`` (2x) runs with a warning; the summary states ``H`` either way.
"""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Headroom", "measure_headroom", "REFUSE_BELOW", "WARN_BELOW", "DEFAULT_PROBE_S"]

REFUSE_BELOW = 1.0
"""A measured headroom below this refuses the run (module docstring)."""
WARN_BELOW = 2.0
"""A measured headroom below this runs with a warning (module docstring)."""
DEFAULT_PROBE_S = 1.0
"""Simulated seconds timed by the probe (after ``warm_s``)."""


@dataclass
class Headroom:
    """One measurement (module docstring); costs in wall s per simulated s."""

    speed: float
    probe_s: float
    sim_cost: float
    pipeline_cost: float
    wall_s: float
    sim_cpu: float = math.nan
    pipeline_cpu: float = math.nan
    """CPU s (this process) per simulated s of each part: on a machine with nothing else
    running the wall costs are about these."""

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
                "pipeline_cpu_s_per_s": self.pipeline_cpu,
                "refuse_below": REFUSE_BELOW, "warn_below": WARN_BELOW}

    def describe(self) -> str:
        return (f"headroom {self.headroom:.1f}x at speed {self.speed:g}x, measured on this machine before the run "
                f"(simulator {1e3 * self.sim_cost:.0f} ms + pipeline {1e3 * self.pipeline_cost:.0f} ms of wall "
                f"time per simulated second; {1e3 * self.cpu_cost:.0f} ms of CPU)")


def measure_headroom(bench, probe_s: float = DEFAULT_PROBE_S, warm_s: float = 0.3) -> Headroom:
    """Measure the headroom of ``bench`` (a :class:`~vdps_hil.hil.bench.Bench`) at its speed
    (module docstring). The probe never shortens: a drive shorter than ``warm_s + probe_s`` is
    probed over its whole length after ``warm_s``."""
    from vdps_hil.sim.drive import Drive

    c = bench.config
    d = bench.drive
    total_s = min(warm_s + probe_s, d.duration_s)
    warm_s = min(warm_s, 0.5 * total_s)
    w0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="vdps-headroom-") as tmp:
        rec = Path(tmp) / "probe.mcap"
        marks: list[tuple[float, float, float]] = []
        probe = Drive(d.scenario, profile=d.profile, seed=d.seed, vehicle=d.vehicle, effects=c.effects,
                      faults=c.faults, duration_s=total_s, block_s=c.block_s)
        probe.run(rec, progress=lambda t_s, _end: marks.append((t_s, time.perf_counter(), time.process_time())))
        sim_cost, sim_cpu = _cost(marks, warm_s)
        pipe_cost, pipe_cpu = _pipeline_cost(bench, rec, warm_s)
    return Headroom(float(c.speed), total_s - warm_s, sim_cost, pipe_cost, time.perf_counter() - w0,
                    sim_cpu, pipe_cpu)


def _cost(marks: list[tuple[float, float, float]], warm_s: float) -> tuple[float, float]:
    """(wall s, CPU s) per simulated s between the first mark at or after ``warm_s`` and the
    last."""
    first = next((m for m in marks if m[0] >= warm_s), marks[0])
    last = marks[-1]
    dt = last[0] - first[0]
    return ((last[1] - first[1]) / dt, (last[2] - first[2]) / dt) if dt > 0 else (0.0, 0.0)


def _pipeline_cost(bench, rec: Path, warm_s: float) -> tuple[float, float]:
    from vdps_hil.app.est_topics import est_docs
    from vdps_hil.pipeline.outputs import CanFrame
    from vdps_hil.record.decode import decode_recording

    from .bench_config import make_system

    sp = bench.drive.profile.suspension
    system = make_system(bench.model, sp.rate_hz, sp.sigma_m, bench.config.params)
    warm_ns = int(warm_s * 1e9)
    marks: list[tuple[float, float]] = []
    samples = decode_recording(rec)
    try:
        for s in samples:
            if not marks and s.t_ns >= warm_ns:
                marks.append((s.t_ns / 1e9, time.perf_counter(), time.process_time()))
            for o in system.handle(s):
                if not isinstance(o, CanFrame):
                    for _ in est_docs(o):
                        pass
            t_last = s.t_ns
    finally:
        samples.close()
    marks.append((t_last / 1e9, time.perf_counter(), time.process_time()))
    return _cost(marks, warm_s)
