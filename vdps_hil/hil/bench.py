"""The hardware-in-the-loop bench: the simulated vehicle on live wires, paced to the wall clock,
the VDPS pipeline answering on CAN, a simulated ECU reacting, everything timed.

::

    Drive (truth simulator + sensor models + faults)                       SimulatorSide
        |  CAN frames at their receive times, serial read chunks             (hil.simside)
        v  paced: sent when the bench clock reaches them                     (hil.pacing)
    [ CAN transport ] [ IMU pty 921600 Bd ] [ GNSS pty 115200 Bd ]         (hil.transports)
        |                      |                     |
    CanAdapter             ImuAdapter           NmeaAdapter                 PipelineNode
        \\____________________  |  _________________/                       (hil.node)
                             VdpsSystem.handle(sample)  -->  /est, VDPS_Warning
                                                              |
    Ecu  <----------------------- CAN -------------------------+            (hil.ecu)
      |  --react: cut drive torque, brake (dead time, pressure ramp)
      v
    Simulator.set_input_override

Processes: ``--can virtual`` (``BenchConfig``'s default; ``vdps bench`` defaults to ``tcp``)
runs everything in this process (python-can's virtual bus: one process by definition);
``--can pty`` and ``--can tcp`` run the pipeline in a child
process (``python -m vdps_hil.hil.child``) reached over a pseudo-terminal (slcan) or a
loopback-only TCP socket (socketcand protocol); an interface string (``socketcan:vcan0``) opens
that bus on both sides in this process. The child gets the device paths and the bench clock's
start instant on its command line and stdin; it reports progress on stdout and leaves its
results (cycle log, sent frames, counters, its part of the recording) in a work directory.

Cross-process transport, measured (``tools/bench_hil.py``, fishhook-suv, 2-core machine): the
TCP path (socketcand protocol on 127.0.0.1) had the lower median latency in every measurement
(0.2-4 ms against 2-21 ms for the slcan pty at 1x, machine load 3-9: python-can's slcan reader
waits out its 1 ms serial timeout after every frame of a batch, so it must read in small
batches and costs more per frame); the highest lossless speeds were alike (2-4x). So ``tcp`` is
the cross-process path the tests run; ``pty`` stays for what it models, a USB-CAN adapter
speaking slcan (both are tested).

Real time in one Python process: the simulator side and the pipeline (which reads its three
adapters in its own loop, ``hil.node``; with ``readers="threads"`` a thread each) share one
interpreter lock. The bench lowers the interpreter's switch interval to 1 ms (a
thread waiting for the lock gets it within about a millisecond instead of 5 ms) and freezes the
garbage collector's view of everything built before the start (no 50 ms collections mid-run);
at 1x the embedded bench needs about 0.7 of a CPU core, so a loaded machine shows up as late
sends, latency and, at worst, lost serial data -- all reported, never hidden.

End of a run: when the drive has ended and every item is sent, the bench waits until the
pipeline has received as much as was sent (``drain_timeout_s`` at most), lets it finish what is
queued and stops it. Lost data (``dropped``) is counted per stream from the devices' and the
pipeline's counts: CAN frames, IMU packets, NMEA lines, plus overflows of the pipeline's queue;
the sequence counters cross-check it (``seq_counters``: breaks of the CAN frames' rolling
counters as received, IMU packet counter gaps) -- without injected faults both are zero on a
bench that loses nothing; a ``dropped_frames`` or ``serial_disconnect`` fault shows in the
counters only, since it acts before the wires.

Results (``BenchResult.to_json``): the ``--json`` keys of ``vdps bench`` (``hil`` issue):
``frames_sent``, ``frames_received``, ``lines_sent``, ``lines_received``, ``dropped``,
``warning_latency_ms`` {p50, p99}, ``warning_lead_time_s``, ``warning_lead_to_tipup_s``,
``rolled_over`` (the point of no return reached in this run), ``realtime_factor`` (simulated
seconds per wall second achieved), ``late_sends``; plus details (IMU packets, pipeline keeps
up, ECU actions, first warning, truth events, transport).

Warning validity: the pipeline is the system's (:class:`vdps_hil.pipeline.node.VdpsSystem`) with its
default rule: started from the model file's priors its frames say "not converged" until the
cornering problem has converged (a few seconds of driving; never within a 3.7 s fishhook), so
lead times count no frame; ``params`` (``--params FILE``, a file saved by ``vdps replay
--save-params``) starts it from identified parameters, as a car after its first drive, and its
frames are valid at once.

The pipeline *keeps up* when nothing was lost, it missed no deadline (``deadline_misses``: a
pipeline short of CPU skips its own work rather than falling behind, ``hil.node``) and its
slowest output cycle was out within ``max_lag_s`` (default 0.25 s wall) of its input.
``headroom``: what ``hil.headroom`` measured before the run (``Bench.measure_headroom``), or
None. ``scheduling``: the policy the run's threads and processes had (``rt_priority``,
``hil.scheduling``: SCHED_FIFO when asked for and permitted, else the default and why).
"""

from __future__ import annotations

import gc
import math
import os
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from vdps_hil.adapters.base import AdapterError
from vdps_hil.record import schemas as S
from vdps_hil.units import NS_PER_S

from .bench_config import BenchConfig, BenchError, model_for, params_not_settled
from .ecu import Ecu
from .latency import cycle_latencies, latency_summary, lead_times, reference_events
from .pacing import BenchClock
from .pipelines import ChildPipeline, LocalPipeline
from . import scheduling
from .serial_device import PtySerialDevice
from .transports import parse_transport

__all__ = ["Bench", "BenchResult", "IMU_PACKET_BYTES"]

IMU_PACKET_BYTES = 47
"""Bytes of one simulated Xsens MTData2 packet (``sim.wire``)."""


@dataclass
class BenchResult:
    """Everything a run measured (``to_json``: module docstring)."""

    doc: dict
    frames_on_bus: list = field(default_factory=list, repr=False)
    truth_events: list = field(default_factory=list)

    def to_json(self) -> dict:
        return self.doc

    def __getitem__(self, key):
        return self.doc[key]


class Bench:
    """One bench run (module docstring). ``run(status)`` returns a :class:`BenchResult`;
    ``status(doc)`` (optional) gets a live status dict every ``status_period_s`` (wall s)."""

    status_period_s = 0.25

    mirror = None
    """``RecordingWriter.mirror`` of the ``-o`` recording (``vdps bench --serve``), or None."""
    headroom = None
    scheduling = None  # what scheduling.request gave the last run
    """The :class:`~vdps_hil.hil.headroom.Headroom` measured before the run (``measure_headroom``),
    or None; it goes into the result."""

    def measure_headroom(self, probe_s: float | None = None):
        """Measure this bench's headroom on this machine now (``hil.headroom``) and keep it."""
        from .headroom import DEFAULT_PROBE_S, measure_headroom

        self.headroom = measure_headroom(self, DEFAULT_PROBE_S if probe_s is None else probe_s)
        return self.headroom

    def __init__(self, config: BenchConfig | None = None):
        from vdps_hil.sim.drive import CONFIG_ERRORS, DEFAULT_PROFILE, Drive

        self.config = c = config or BenchConfig()
        if not (math.isfinite(c.speed) and c.speed > 0):
            raise BenchError(f"--speed must be a positive number, got {c.speed!r}")
        if c.rt_priority is not None and (isinstance(c.rt_priority, bool) or not isinstance(c.rt_priority, int)
                                          or not 0 <= c.rt_priority <= 99):
            raise BenchError(f"--rt-priority must be an integer 0..99 (0: off), got {c.rt_priority!r}")
        try:
            self.transport = parse_transport(c.can, c.sim_can)
        except AdapterError as e:
            raise BenchError(str(e)) from None
        try:
            self.drive = Drive(c.scenario, profile=c.profile or DEFAULT_PROFILE, seed=c.seed, vehicle=c.vehicle,
                               effects=c.effects, faults=c.faults, duration_s=c.duration_s, block_s=c.block_s)
        except CONFIG_ERRORS as e:
            raise BenchError(str(e).splitlines()[0] if str(e) else type(e).__name__) from None
        truth = c.vehicle or self.drive.scenario.raw.get("vehicle") or self.drive.vehicle.name
        self.truth_vehicle = str(truth)  # the file or name the simulator drives (calibrate() drives it too)
        self.model = c.model or model_for(str(truth))
        self.params_not_settled: dict = {}  # what --params had not settled (bench_config.params_not_settled)
        if c.params is not None:
            try:
                self.params_not_settled = params_not_settled(self.model, c.params)
            except (ValueError, OSError) as e:
                raise BenchError(str(e).splitlines()[0]) from None

    # ------------------------------------------------------------------------------------------
    def run(self, status: Callable[[dict], None] | None = None) -> BenchResult:
        c = self.config
        old_switch = sys.getswitchinterval()
        if c.switch_interval_s:
            sys.setswitchinterval(c.switch_interval_s)
        self.scheduling, prev_sched = scheduling.request(c.rt_priority)  # inherited by what _run starts
        try:
            return self._run(status)
        finally:
            scheduling.restore(prev_sched)
            sys.setswitchinterval(old_switch)

    def _make_writer(self):
        from vdps_hil.record.writer import RecordingWriter

        c = self.config
        if not c.output:
            return None
        try:
            w = RecordingWriter(c.output, metadata={"source": "vdps bench"},
                                content_hashes={"dbc.vdps": self.drive.dbc_path}, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
            w.mirror = self.mirror
            return w
        except OSError as e:
            raise BenchError(f"cannot write {c.output}: {e.strerror or e}") from None

    def _run(self, status) -> BenchResult:
        c = self.config
        reference = reference_events(self.drive) if c.react else None
        can_dev = self.transport.make()
        serial = {"imu": PtySerialDevice("imu"), "gnss": PtySerialDevice("gnss")}
        writer = None
        work = None
        pipe = None
        side = None
        try:
            try:
                can_dev.open()
            except AdapterError as e:
                raise BenchError(str(e)) from None
            clock = BenchClock(c.speed)
            ecu = Ecu(c.actuator, c.react)
            if self.transport.cross_process:
                work = Path(tempfile.mkdtemp(prefix="vdps-bench-"))
            writer = self._open_writer(work)
            side = self._simulator_side(can_dev, serial, clock, ecu, writer)
            side.prepare()
            side.start_receiver()
            if work is not None:
                pipe = ChildPipeline(self, can_dev, serial, work)
            else:
                pipe = LocalPipeline(self, can_dev, serial, clock, writer)
            pipe.open()
            gc.collect()
            gc.freeze()  # what exists now is never scanned again: no long collections mid-run
            mono0 = time.monotonic_ns() + int(c.start_delay_s * NS_PER_S)
            clock.start(mono0)
            pipe.start(mono0)
            self._drive_until_done(side, pipe, clock, status)
            side.flush()
            self._drain(side, pipe)
            pipe.stop()
            side.stop_receiver()
            if status is not None:
                status(self._status(side, pipe, clock, final=True))
            result = self._result(side, pipe, clock, ecu, reference)
            if c.output:
                pipe.finish_recording(result.doc, writer)
            return result
        finally:
            gc.unfreeze()
            if pipe is not None:
                pipe.kill()
            if side is not None:
                side.stop_receiver()
            for d in serial.values():
                d.close()
            can_dev.close()
            if writer is not None and not writer.closed:
                writer.close()
            if work is not None:
                shutil.rmtree(work, ignore_errors=True)

    def _open_writer(self, work: Path | None):
        """The recording of ``--output``: the file itself (pipeline in this process), or the
        truth part in the work directory of a cross-process bench (merged with the child's part
        at the end, ``ChildPipeline.finish_recording``); None without ``--output``."""
        if work is None:
            return self._make_writer()
        truth_path = work / "truth.mcap" if self.config.output else None
        from vdps_hil.record.writer import RecordingWriter

        return (RecordingWriter(truth_path, metadata={"source": "vdps bench"},
                                sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS) if truth_path else None)

    def _simulator_side(self, can_dev, serial, clock, ecu, writer):
        """The vehicle's side of the wires, its truth and metadata going to ``writer``."""
        from .simside import SimulatorSide

        c = self.config
        lock = threading.Lock()

        def on_truth(topic, t_ns, doc):
            if writer is not None:
                with lock:
                    writer.write_truth(topic, t_ns, doc)

        def on_metadata(name, data):
            if writer is not None:
                writer.add_metadata(name, data)

        return SimulatorSide(self.drive, can_dev, serial, clock, ecu, lookahead_s=c.lookahead_s,
                             late_tolerance_s=c.late_tolerance_s, on_truth=on_truth, on_metadata=on_metadata)

    def _drive_until_done(self, side, pipe, clock, status) -> None:
        """Run the simulator side in its thread until the drive has ended (or Ctrl-C: then
        ``interrupted``), reporting ``status`` about four times a second; a failed pipeline or
        simulator side raises BenchError."""
        sim_stop = threading.Event()
        sim_thread = threading.Thread(target=self._sim_thread, args=(side, sim_stop), name="bench-sim",
                                      daemon=True)
        sim_thread.start()
        t_status = 0.0
        self.interrupted = False
        try:
            while not side.done.wait(0.05):
                if status is not None and time.monotonic() - t_status >= self.status_period_s:
                    t_status = time.monotonic()
                    status(self._status(side, pipe, clock))
                if pipe.failed():
                    sim_stop.set()
                    sim_thread.join(timeout=10.0)
                    raise BenchError(f"pipeline failed: {pipe.error()}")
        except KeyboardInterrupt:  # Ctrl-C: end the drive here and report what happened so far
            self.interrupted = True
            sim_stop.set()
        sim_thread.join(timeout=10.0)
        if side.error:
            raise BenchError(f"simulator side failed: {side.error}")

    def _sim_thread(self, side, stop) -> None:
        try:
            side.run(stop)
        except Exception:  # noqa: BLE001 - side.error has it; the bench raises it
            pass

    def _drain(self, side, pipe) -> None:
        sent = side.sent_counts()
        imu_bytes = side.serial["imu"].log.total
        gnss_bytes = side.serial["gnss"].log.total
        t_end = time.monotonic() + self.config.drain_timeout_s
        while time.monotonic() < t_end:
            r = pipe.received()
            if (r.get("can_frames", 0) >= sent["frames_sent"] and r.get("imu_bytes", 0) >= imu_bytes
                    and r.get("gnss_bytes", 0) >= gnss_bytes):
                break
            if pipe.failed():
                break
            time.sleep(0.01)
            side.serve_ecu()

    # ------------------------------------------------------------------------------------------
    def _status(self, side, pipe, clock, final: bool = False) -> dict:
        s = side.sent_counts()
        r = pipe.received()
        truth = side.sink.last_truth or {}
        ecu = side.ecu
        t_s = clock.now_ns() / NS_PER_S if not final else side.session.t_ns / NS_PER_S
        return {"t_s": max(0.0, min(t_s, side.session.t_ns / NS_PER_S)), "duration_s": self.drive.duration_s,
                "frames_sent": s["frames_sent"], "frames_received": r.get("can_frames", 0),
                "imu_bytes_sent": side.serial["imu"].log.total, "imu_bytes_received": r.get("imu_bytes", 0),
                "late_sends": side.pacer.late_sends, "roll_deg": math.degrees(truth.get("roll_v_rad", 0.0)),
                "speed_mps": truth.get("speed_mps", math.nan),
                "warning_level": ecu.max_level,
                "first_warning_t_s": None if ecu.first_warning_ns is None else ecu.first_warning_ns / NS_PER_S,
                "brake_fraction": ecu.brake_fraction(side.session.t_ns / NS_PER_S),
                "events": [e["kind"] for e in side.sink.events if e.get("kind") in ("tip_up", "point_of_no_return")],
                "pids": {"simulator": os.getpid(), "pipeline": pipe.pid}, "final": final}

    def _result(self, side, pipe, clock, ecu, reference) -> BenchResult:
        c = self.config
        p = pipe.results()
        sent = side.sent_counts()
        counters = p["counters"]
        # --- data on the wires
        imu_packets_sent = side.serial["imu"].bytes_in // IMU_PACKET_BYTES
        imu_packets_received = counters["imu"]["packets"]
        lines_sent = side.serial["gnss"].lines
        lines_received = counters["gnss"]["lines"]
        frames_generated = sent["frames_sent"] + sent["frames_dropped_at_device"]
        frames_received = counters["can"]["frames"]
        # lost on the bench's wires: what the devices were given minus what the pipeline decoded
        # (a fault injected into the drive -- dropped_frames, serial_disconnect -- removes data
        # before the devices: it shows in the sequence counters, not here)
        lost = {"can_frames": max(frames_generated - frames_received, 0),
                "imu_packets": max(imu_packets_sent - imu_packets_received, 0),
                "gnss_lines": max(lines_sent - lines_received, 0)}
        dropped = sum(lost.values()) + counters["subscription_overflows"]
        # --- latency
        logs = {"can": side.can.log, "imu": side.serial["imu"].log, "gnss": side.serial["gnss"].log}
        bus_times = [m for m, _ in side.frames_from_pipeline]
        lat = cycle_latencies(p["cycles"], logs, bus_times if len(bus_times) == p["frames_sent"] else None)
        ls = latency_summary(lat)
        # --- lead times on the bus (the ECU's receptions), bench time
        frames_on_bus = []
        for m, msg in side.frames_from_pipeline:
            msg.timestamp = clock.t_of(m) / NS_PER_S
            frames_on_bus.append(msg)
        events = [e for e in side.sink.events if e.get("kind") in ("tip_up", "point_of_no_return")]
        lt = lead_times(frames_on_bus, events, reference)
        rolled = any(e.get("kind") == "point_of_no_return" for e in events)
        pace = side.pacer.stats()
        wall = side.wall_s
        sim_s = side.sim_s
        lat_max = ls["warning_latency_ms"]["max"]
        misses = counters.get("deadline_misses") or {"samples": 0, "episodes": 0}
        keeps_up = (dropped == 0 and misses["samples"] == 0
                    and (not math.isfinite(lat_max) or lat_max <= c.max_lag_s * 1e3))
        ecu_sum = ecu.summary()
        doc = {
            "scenario": self.drive.scenario.name, "vehicle": self.drive.vehicle.name, "model": self.model,
            "profile": self.drive.profile.name, "seed": self.drive.seed, "transport": self.transport.name,
            "can": side.can.describe(), "speed": c.speed, "react": c.react, "params": c.params,
            **self.params_not_settled,
            "effects": list(self.drive.effect_set.names), "faults": [str(f) for f in c.faults],
            "duration_s": sim_s, "wall_time_s": wall,
            "realtime_factor": sim_s / wall if wall > 0 else math.nan,
            "frames_sent": frames_generated, "frames_received": frames_received,
            "lines_sent": lines_sent, "lines_received": lines_received,
            "imu_packets_sent": imu_packets_sent, "imu_packets_received": imu_packets_received,
            "dropped": dropped, "lost": lost, "seq_counters": {
                "can_counter_breaks": counters["can"]["counter_breaks"], "imu_seq_gaps": counters["imu"]["seq_gaps"],
                "can_decoder_lost_frames": counters["can"]["decoder_lost_frames"]},
            "dropped_at_device": {"can_frames": sent["frames_dropped_at_device"],
                                  "imu_chunks": sent["imu_dropped_at_device"],
                                  "gnss_chunks": sent["gnss_dropped_at_device"]},
            "rejected": {"can": counters["can"]["rejected"], "imu": counters["imu"]["rejected"],
                         "gnss": counters["gnss"]["rejected"]},
            "warning_latency_ms": {k: ls["warning_latency_ms"][k] for k in ("p50", "p99", "max")},
            "warning_frame_latency_ms": {k: ls["warning_frame_latency_ms"][k] for k in ("p50", "p99", "max")},
            "output_cycles": ls["cycles"], "output_cycles_unmatched": ls["cycles_unmatched"],
            "warning_frames": p["frames_sent"], "warning_frames_on_bus": len(frames_on_bus),
            **lt,
            "rolled_over": rolled, "truth_events": events,
            "max_abs_roll_deg": math.degrees(side.sink.max_abs_roll_v_rad),
            "reference_events": [e for e in (reference or []) if e.get("kind") in ("tip_up", "point_of_no_return")],
            "late_sends": pace["late_sends"], "sends": pace["sends"], "late_tolerance_ms": pace["late_tolerance_ms"],
            "send_lateness_ms": pace["lateness_ms"],
            "pipeline_keeps_up": keeps_up, "max_lag_s": c.max_lag_s, "deadline_misses": misses,
            "warning_status": counters.get("warning_status", {}),
            "warning_unhealthy": counters.get("unhealthy", {}), "predictions": counters.get("predictions", {}),
            "headroom": None if self.headroom is None else self.headroom.to_json(),
            "scheduling": self.scheduling,
            "ecu": ecu_sum, "pipeline": {"outputs": p["outputs"], "errors": p["errors"]},
            "stop_reason": ("interrupted" if getattr(self, "interrupted", False)
                            else side.session.sim.stop_reason or "duration"),
            "output": c.output,
        }
        return BenchResult(doc, frames_on_bus, events)

