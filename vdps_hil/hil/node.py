"""The pipeline's side of the bench: the real adapters on the bench's wires, the VDPS system
fed live, its warning frames sent back on CAN.

What runs (threads: one reader per adapter, one pipeline loop)
--------------------------------------------------------------
* ``CanAdapter("vdps", SPEC)`` with the chassis decoder (``dbc/vdps.dbc``), ``ImuAdapter`` on
  the IMU pty (921600 Bd), ``NmeaAdapter`` on the GNSS pty (115200 Bd) -- exactly what ``vdps
  log`` opens on a car -- all stamping with the bench clock (``hil.pacing``);
* one bounded queue (``Subscription``) from the three adapters to the pipeline loop, which takes
  the events in arrival order: a raw record is recorded (``-o``) and counted; a sample is
  recorded under ``/decoded/`` and handed to ``system.handle(sample)``; the outputs are sent
  (``CanFrame`` VDPS_Warning -> ``CanAdapter.send``, which also records it as a ``tx`` frame)
  or recorded under ``/est/`` (``Estimate`` -> ``/est/ekf``, ``IdentReport`` -> ``/est/ident``,
  ``PredictionReport`` -> ``/est/prediction``).

The order in which samples reached ``system.handle`` is the system's own ``input_log``; the
node also writes it to the recording as the metadata record ``hil.input_order`` (topic index
per sample, in order), so a replay can feed the recorded ``/decoded/`` samples in exactly the
live order (``input_order_samples``).

Output cycles (``hil.latency``): every ``handle`` that returned outputs adds a row to
``cycles`` with the input's index in its stream (CAN frames received so far, or the offset of
the last serial byte read so far) and the time the outputs were out.

The node never opens truth: it has the model vehicle, the wires and the bench clock.
"""

from __future__ import annotations

import base64
import json
import threading
import time
import zlib
from typing import Any, Callable

from vdps_hil.adapters.base import RawCan, RawSerial, Subscription
from vdps_hil.adapters.can_adapter import CanAdapter
from vdps_hil.adapters.imu_adapter import ImuAdapter
from vdps_hil.adapters.nmea_adapter import NmeaAdapter
from vdps_hil.adapters.session import Recorder
from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.can_codec import VdpsCanDecoder

from .latency import SOURCES, CycleLog

__all__ = ["PipelineNode", "INPUT_ORDER_METADATA", "input_order_samples", "IMU_BAUD", "GNSS_BAUD"]

IMU_BAUD = 921600
GNSS_BAUD = 115200
INPUT_ORDER_METADATA = "hil.input_order"

_SRC_CODE = {"can": 0, "imu": 1, "gnss": 2}


def _estimate_values(est) -> tuple[dict, dict]:
    from vdps_hil.estimation.states import STATE_NAMES

    values = dict(zip(STATE_NAMES, est.x))
    sigmas = dict(zip(STATE_NAMES, est.sigma))
    for name, v, s in zip(("roll_v_rad", "pitch_v_rad", "yaw_v_rad"), est.vehicle_angles_rad,
                          est.vehicle_angles_sigma_rad):
        values[name] = v
        sigmas[name] = s
    return values, sigmas


class PipelineNode:
    """The pipeline side (module docstring).

    ``system``: an object with ``handle(sample) -> list`` (``vdps_hil.system.VdpsSystem``);
    ``can_spec``: the interface string of the bench's CAN; ``imu_port``/``gnss_port``: pty
    paths; ``clock``: the bench clock; ``writer``: a RecordingWriter for ``-o`` (or None).
    ``run(stop)`` processes until ``stop`` is set and everything queued is handled."""

    def __init__(self, system, can_spec: str, imu_port: str, gnss_port: str, clock, *, writer=None,
                 bus: str = "vdps", queue_size: int = 1_000_000, poll_s: float = 0.02):
        self.system = system
        self.clock = clock
        self.bus = bus
        self.can = CanAdapter(bus, can_spec, decoder=VdpsCanDecoder(source=f"can.{bus}"), clock=clock)
        self.imu = ImuAdapter("imu", imu_port, IMU_BAUD, clock=clock)
        self.gnss = NmeaAdapter("gnss", gnss_port, GNSS_BAUD, clock=clock)
        self.adapters = [self.can, self.imu, self.gnss]
        self.sub = Subscription("pipeline", queue_size)
        for a in self.adapters:
            a.subscribe(self.sub)
        self.writer = writer
        self.recorder = Recorder(writer) if writer is not None else None
        self.poll_s = poll_s
        self.cycles = CycleLog()
        self.frames_sent: list[tuple[int, Any]] = []  # (monotonic ns after send, can.Message)
        self.received = {"can_frames": 0, "imu_bytes": 0, "gnss_bytes": 0, "samples": 0}
        self._src_of = {self.can.name: "can", "imu": "imu", "gnss": "gnss"}
        self._last_idx = {"can": -1, "imu": -1, "gnss": -1}
        self._order_topics: dict[str, int] = {}
        self._order: bytearray = bytearray()
        self._stop_adapters = threading.Event()
        self._threads: list[threading.Thread] = []
        self.errors: list[str] = []
        self.last_estimate = None
        self.outputs = {"estimates": 0, "frames": 0, "predictions": 0, "other": 0}
        self.on_output: Callable[[Any], None] | None = None

    # --- lifecycle ------------------------------------------------------------------------------
    def open(self) -> None:
        opened = []
        try:
            for a in self.adapters:
                a.open()
                opened.append(a)
        except Exception:
            for a in opened:
                a.close()
            raise

    def _reader(self, a) -> None:
        try:
            a.run(self._stop_adapters, self.poll_s)
        except Exception as e:  # noqa: BLE001 - reported, never a silent thread death
            self.errors.append(f"{a.name}: {type(e).__name__}: {e}")

    def start_readers(self) -> None:
        for a in self.adapters:
            th = threading.Thread(target=self._reader, args=(a,), name=f"bench-reader-{a.name}", daemon=True)
            th.start()
            self._threads.append(th)

    def run(self, stop: threading.Event) -> None:
        """Handle events until ``stop`` is set and the queue is empty; then stop the readers and
        handle what they still delivered."""
        if not self._threads:
            self.start_readers()
        sub = self.sub
        try:
            while True:
                if sub.wait(0.005):
                    self._handle_events(sub.drain(2000))
                elif stop.is_set():
                    break
        finally:
            self._stop_adapters.set()
            for th in self._threads:
                th.join(timeout=5.0)
            self._flush_imu()
            while len(sub):
                self._handle_events(sub.drain(100_000))

    def _flush_imu(self) -> None:
        """The IMU decoder may hold a complete packet until it has seen the bytes after it (a
        preamble byte inside the packet's tail): release it at the end of the run."""
        try:
            held = self.imu.protocol.flush()
        except Exception as e:  # noqa: BLE001 - a decoder bug must not lose the run
            self.errors.append(f"imu flush: {type(e).__name__}: {e}")
            return
        for s in held:
            self.imu._publish_sample(s, s.t_ns, self.clock.wall(s.t_ns), False)

    def received_counts(self) -> dict:
        return dict(self.received)

    # --- the loop body --------------------------------------------------------------------------
    def _handle_events(self, events) -> None:
        rec = self.recorder
        received = self.received
        last = self._last_idx
        for ev in events:
            if isinstance(ev, Sample):
                if rec is not None:
                    rec.write(ev)
                    self._note_order(ev)
                received["samples"] += 1
                self._cycle(ev)
            elif isinstance(ev, RawCan):
                if rec is not None:
                    rec.write(ev)
                if ev.direction == "rx":
                    received["can_frames"] += 1
                    last["can"] = received["can_frames"] - 1
            elif isinstance(ev, RawSerial):
                if rec is not None:
                    rec.write(ev)
                key = f"{ev.source}_bytes"
                if key in received:
                    received[key] += len(ev.data)
                    last[ev.source] = received[key] - 1

    def _note_order(self, s: Sample) -> None:
        topic = f"/decoded/{s.source}/{s.kind}"
        k = self._order_topics.get(topic)
        if k is None:
            k = self._order_topics[topic] = len(self._order_topics)
        self._order.append(k)

    def _cycle(self, s: Sample) -> None:
        outs = self.system.handle(s)
        n_frames = 0
        first = len(self.frames_sent)
        for o in outs:
            if self._dispatch(o):
                n_frames += 1
        src = self._src_of.get(s.source)
        if src is not None:
            self.cycles.add(_SRC_CODE[src], self._last_idx[src], time.monotonic_ns(), n_frames,
                            first if n_frames else -1)

    def _dispatch(self, o) -> bool:
        """Send or record one output; True when a frame went onto the bus."""
        name = type(o).__name__
        if self.on_output is not None:
            self.on_output(o)
        if name == "CanFrame":
            import can

            msg = can.Message(arbitration_id=o.arbitration_id, data=o.data, dlc=len(o.data),
                              is_extended_id=False, is_rx=False, check=False)
            self.can.send(msg)
            self.frames_sent.append((time.monotonic_ns(), msg))
            self.outputs["frames"] += 1
            return True
        w = self.writer
        if name == "Estimate":
            self.last_estimate = o
            self.outputs["estimates"] += 1
            if w is not None:
                values, sigmas = _estimate_values(o)
                self._write(lambda: w.write_estimate("ekf", o.t_ns, values, sigmas))
        elif name == "IdentReport":
            if w is not None:
                self._write(lambda: w.write_estimate("ident", o.t_ns, dict(o.params), dict(o.sigmas)))
        elif name == "PredictionReport":
            self.outputs["predictions"] += 1
            if w is not None:
                nan = float("nan")
                v = {"time_to_point_of_no_return_s": nan if o.time_to_point_of_no_return_s is None
                     else o.time_to_point_of_no_return_s,
                     "time_to_tip_up_s": nan if o.time_to_tip_up_s is None else o.time_to_tip_up_s,
                     "peak_ltr": o.peak_ltr, "peak_roll_rad": o.peak_roll_rad, "horizon_s": o.horizon_s}
                self._write(lambda: w.write_estimate("prediction", o.t0_ns, v))
        else:
            self.outputs["other"] += 1
        return False

    def _write(self, fn) -> None:
        try:
            fn()
        except (ValueError, TypeError, KeyError) as e:
            self.recorder._fail("est", e)

    # --- end ------------------------------------------------------------------------------------
    def finish_recording(self, extra: dict | None = None) -> None:
        """Health of every source and the input order into the recording (not closed here)."""
        rec = self.recorder
        if rec is None:
            return
        rec.write_health(self.adapters)
        rec.write_final_health(self.adapters, extra)
        topics = sorted(self._order_topics, key=self._order_topics.get)
        self.writer.add_metadata(INPUT_ORDER_METADATA, {
            "topics": json.dumps(topics), "count": str(len(self._order)),
            "order_zlib_b64": base64.b64encode(zlib.compress(bytes(self._order), 9)).decode("ascii")})

    def status(self) -> dict:
        return {a.name: a.status() for a in self.adapters}

    def counters(self) -> dict:
        """Received and lost data per stream (decoders' sequence checks included)."""
        can_c = self.can.health.all_counters()
        imu_c = self.imu.health.all_counters()
        gnss_c = self.gnss.health.all_counters()
        return {"can": {"frames": self.received["can_frames"], "lost_frames": can_c.get("lost_frames", 0),
                        "rejected": self.can.health.error_total(), "queue_overflow": can_c.get("queue_overflow", 0)},
                "imu": {"bytes": self.received["imu_bytes"], "packets": imu_c.get("samples", 0),
                        "seq_gaps": imu_c.get("seq_gaps", 0), "rejected": imu_c.get("rejected", 0),
                        "queue_overflow": imu_c.get("queue_overflow", 0)},
                "gnss": {"bytes": self.received["gnss_bytes"], "lines": gnss_c.get("lines", 0),
                         "rejected": gnss_c.get("rejected", 0), "queue_overflow": gnss_c.get("queue_overflow", 0)},
                "subscription_overflows": self.sub.overflows, "reader_errors": list(self.errors)}


def input_order_samples(reader) -> list[Sample]:
    """The ``/decoded/`` samples of a bench recording in the order the live system received them
    (metadata ``hil.input_order``): what ``VdpsSystem.replay`` needs to reproduce the live run."""
    md = reader.metadata().get(INPUT_ORDER_METADATA)
    if md is None:
        raise ValueError(f"no {INPUT_ORDER_METADATA} metadata in this recording (not a bench recording)")
    topics = json.loads(md["topics"])
    order = zlib.decompress(base64.b64decode(md["order_zlib_b64"]))
    per_topic: dict[str, list] = {t: [] for t in topics}
    for rec in reader.iter_records(topics=topics):
        per_topic[rec.topic].append(rec.data)
    pos = [0] * len(topics)
    out = []
    for k in order:
        data = per_topic[topics[k]][pos[k]]
        pos[k] += 1
        out.append(Sample.from_json(json.loads(data)))
    return out
