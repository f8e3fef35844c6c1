"""The pipeline's side of the bench: the real adapters on the bench's wires, the VDPS system
fed live, its warning frames sent back on CAN.

What runs (one loop reading the adapters and handling what they deliver, ``readers="inline"``,
the bench's default; or a reader thread per adapter and the loop, ``readers="threads"``)
--------------------------------------------------------------------------------------------
* ``CanAdapter("vdps", SPEC)`` with the chassis decoder (``dbc/vdps.dbc``), stamping each frame
  with the interface's own time stamp (:class:`InterfaceTimeCanAdapter`); serial adapters on the
  IMU pty (921600 Bd, Xsens MTData2) and the GNSS pty (115200 Bd, NMEA), stamping each message
  by the device's own clock (:class:`DeviceTimeProtocol`, the codecs of ``ImuAdapter`` and
  ``NmeaAdapter`` with the clock alignment of ``vdps replay``; ``device_time=False``: the
  adapters' receive-time rule) -- all on the bench clock (``hil.pacing``);
* one bounded queue (``Subscription``) from the three adapters to the pipeline loop, which takes
  the events in arrival order: a raw record is recorded (``-o``) and counted; a sample is
  recorded under ``/decoded/`` and handed to ``system.handle(sample)``; the outputs are sent
  (``CanFrame`` VDPS_Warning -> ``CanAdapter.send``, which also records it as a ``tx`` frame)
  or recorded under ``/est/`` in the layout of ``vdps replay`` (``/est/state``,
  ``/est/innovation/<kind>``, ``/est/filtered``, ``/est/ident``, ``/est/prediction``, and the
  frames the system output on ``/est/can/<bus>``; on the wire they are ``/raw/can/<bus>`` tx).

Sequencing (``sequence_s``, default 0.05 s): the estimator takes the IMU as its input and
predicts to a measurement's time with the IMU samples it has; live, a CAN frame arrives up to a
serial read window (5 ms) -- more when a reader thread is held up -- before the IMU packets of
the same instant, and the filter would then run ahead on stale inputs (on paper-left-turn that
turned the borderline "caution" predictions into false warnings). So a measurement later than
the newest IMU sample is held until the IMU has caught up with it (at most ``sequence_s`` of
bench time, in case the IMU is lost), and held ones go in time order -- what a replay's
time-ordered input gives. The hold is part of the measured latency. ``sequence_s=None``: raw
arrival order.

The order in which samples reached ``system.handle`` is the system's own ``input_log``; the
node also writes it to the recording as the metadata record ``hil.input_order`` (topic index
per sample written, in order; ``record.input_order``), so a replay can feed the recorded
``/decoded/`` samples in exactly the live order (``input_order_samples``).

Deadline misses (``deadline_s``, default 0.1 s wall; ``hil.deadline``): a pipeline that falls
behind skips its own work until it is back, counted (``counters()["deadline_misses"]``), and its
warnings say "sensor missing" meanwhile. ``deadline_s=None``: never skip.

Output cycles (``hil.latency``): every ``handle`` adds a row to ``cycles`` with the index of
the raw record that carried the sample in its stream (the CAN frames received up to it, or the
offset of the last serial byte read up to it) and the time its outputs were out.

The node never opens truth: it has the model vehicle, the wires and the bench clock.
"""

from __future__ import annotations

import select
import threading
import time
from typing import Any, Callable

from vdps_hil.adapters.base import EndOfInput
from vdps_hil.adapters.imu_adapter import ImuAdapter, ImuProtocol
from vdps_hil.adapters.nmea_adapter import NmeaAdapter, NmeaProtocol
from vdps_hil.adapters.serial_adapter import SerialAdapter
from vdps_hil.app.est_topics import est_docs  # the /est/ layout of ``vdps replay``
from vdps_hil.app.foxglove_view import FoxgloveView
from vdps_hil.bus.raw import RawCan, RawSerial
from vdps_hil.bus.samples import Sample
from vdps_hil.bus.subscription import Subscription
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.record import schemas as S
from vdps_hil.record.input_order import INPUT_ORDER_METADATA, InputOrder, input_order_samples
from vdps_hil.record.recorder import Recorder

from .deadline import DEFAULT_DEADLINE_S, DeadlineGuard
from .latency import CycleLog
from .sequencer import InputSequencer
from .stamping import DeviceTimeProtocol, InterfaceTimeCanAdapter

__all__ = ["PipelineNode", "InputSequencer", "InterfaceTimeCanAdapter", "DeviceTimeProtocol",
           "INPUT_ORDER_METADATA", "input_order_samples", "IMU_BAUD", "GNSS_BAUD", "LIVE_CLOCK_JUMP_S"]

IMU_BAUD = 921600
GNSS_BAUD = 115200
LIVE_CLOCK_JUMP_S = 0.25
"""Device clock alignment on the bench: a change of host-minus-device time below this is a host
delay (a reader held up by the GIL or the machine's load), not a device clock step (``vdps
replay`` uses 20 ms for the IMU, 100 ms for GNSS: a file has no host stalls). A device clock
stepping back by less than this is then not followed (stamps early by the step)."""

_SRC_CODE = {"can": 0, "imu": 1, "gnss": 2}


class PipelineNode:
    """The pipeline side (module docstring).

    ``system``: an object with ``handle(sample) -> list`` (``vdps_hil.pipeline.node.VdpsSystem``);
    ``can_spec``: the interface string of the bench's CAN; ``imu_port``/``gnss_port``: pty
    paths; ``clock``: the bench clock; ``writer``: a RecordingWriter for ``-o`` (or None).
    ``run(stop)`` processes until ``stop`` is set and everything queued is handled."""

    def __init__(self, system, can_spec: str, imu_port: str, gnss_port: str, clock, *, writer=None,
                 bus: str = "vdps", queue_size: int = 1_000_000, poll_s: float = 0.02, device_time: bool = True,
                 imu_rate_hz: float = 1000.0, sequence_s: float | None = 0.05,
                 deadline_s: float | None = DEFAULT_DEADLINE_S, readers: str = "threads"):
        if readers not in ("threads", "inline"):
            raise ValueError(f"readers must be 'threads' or 'inline', not {readers!r}")
        self.readers = readers
        self.system = system
        self.clock = clock
        self.deadline = DeadlineGuard(clock, deadline_s, sequence_s or 0.0)
        self.bus = bus
        # slcan: python-can's serial timeout (1 ms) restarts with every byte, so a batch read
        # only returns when the batch is full at a steady frame rate (256 frames = 85 ms at
        # 3 kHz); 16 frames bound that to 5 ms while keeping the reads few enough to keep up
        # (tools/bench_hil.py). Other interfaces return at once when nothing is waiting.
        batch = 16 if can_spec.split(":", 1)[0].strip() == "slcan" else 256
        self.can = InterfaceTimeCanAdapter(bus, can_spec, decoder=VdpsCanDecoder(source=f"can.{bus}"),
                                           clock=clock, batch=batch)
        if device_time:
            from vdps_hil.record.device_clock import ClockAligner, DeviceStamper  # the replay's device clocks
            from vdps_hil.record.streams import ImuStream, NmeaStream

            imu_stream = ImuStream("imu", IMU_BAUD, True, imu_rate_hz)
            gnss_stream = NmeaStream("gnss", GNSS_BAUD, True)
            for st in (imu_stream, gnss_stream):  # live: a host stall is not a device clock step
                st.stamper = DeviceStamper(ClockAligner(jump_s=LIVE_CLOCK_JUMP_S, confirm_s=0.2))
            self.imu = SerialAdapter("imu", imu_port, IMU_BAUD, DeviceTimeProtocol(imu_stream, ImuProtocol.fmt),
                                     clock=clock)
            self.gnss = SerialAdapter("gnss", gnss_port, GNSS_BAUD,
                                      DeviceTimeProtocol(gnss_stream, NmeaProtocol.fmt), clock=clock)
        else:
            self.imu = ImuAdapter("imu", imu_port, IMU_BAUD, clock=clock)
            self.gnss = NmeaAdapter("gnss", gnss_port, GNSS_BAUD, clock=clock)
        self.adapters = [self.can, self.imu, self.gnss]
        self.sub = Subscription("pipeline", queue_size)
        for a in self.adapters:
            a.subscribe(self.sub)
        self.writer = writer
        self.recorder = Recorder(writer) if writer is not None else None
        # the Foxglove view of the outputs (/est/fix, /est/tf, /est/pose, /est/warning), on the writer's clock
        self.view = None if writer is None else FoxgloveView(lambda: system.pipeline.origin,
                                                             epoch_ns=getattr(writer, "sim_epoch_ns", None))
        self.sequencer = InputSequencer(sequence_s) if sequence_s else None
        self._counter_of = {aid: (sp.dlc, sp.counter.start_bit, (1 << sp.counter.length_bits) - 1)  # id -> counter
                            for aid, sp in self.can.decoder.dbc.by_id.items() if sp.is_sensor}
        self._counters_seen: dict[int, int] = {}
        self.counter_breaks = 0
        self.poll_s = poll_s
        self.cycles = CycleLog()
        self.frames_sent: list[tuple[int, Any]] = []  # (monotonic ns after send, can.Message)
        self.received = {"can_frames": 0, "imu_bytes": 0, "gnss_bytes": 0, "samples": 0}
        self._src_of = {self.can.name: "can", "imu": "imu", "gnss": "gnss"}
        self._last_idx = {"can": -1, "imu": -1, "gnss": -1}
        self.input_order = InputOrder()
        self._stop_adapters = threading.Event()
        self._threads: list[threading.Thread] = []
        self.errors: list[str] = []
        self.last_estimate = None
        self.outputs = {"estimates": 0, "frames": 0, "predictions": 0, "other": 0}
        self.on_output: Callable[[Any], None] | None = None

    # --- lifecycle ------------------------------------------------------------------------------
    def open(self) -> None:
        from vdps_hil.app.session import open_all

        open_all(self.adapters, errors=(Exception,))

    def _reader(self, a, drain_s: float = 2.0) -> None:
        """A reader thread: poll ``a`` until the adapters are told to stop, then read what the
        device already holds (at most ``drain_s``): a reader thread held up on a busy machine
        lags the wire, and a pty holds kilobytes unread (20 KiB here); the inline loop reads until
        the ports are empty too. The CAN bus stays open after reading stops: the last frames go out."""
        stop = self._stop_adapters
        try:
            try:
                while not stop.is_set():
                    a.poll(self.poll_s)
                end = time.monotonic() + drain_s
                while a.poll(0.0) and time.monotonic() < end:
                    pass
            except EndOfInput:
                pass
            finally:
                if a is not self.can:
                    a.close()
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
        if self.readers == "inline":
            return self._run_inline(stop)
        if not self._threads:
            self.start_readers()
        sub = self.sub
        try:
            while True:
                if sub.wait(0.005):
                    self._handle_events(sub.drain(2000))
                elif stop.is_set():
                    break
                self._expire()
        finally:
            self._stop_adapters.set()
            for th in self._threads:
                th.join(timeout=5.0)
            self._finish_input()

    def _run_inline(self, stop: threading.Event, idle_s: float = 0.002) -> None:
        """``readers="inline"``: this thread reads the adapters itself and handles what they
        delivered. The serial ports are read when ``select`` says they hold bytes, CAN at every
        pass (python-can gives no descriptor for every interface); when nothing came, the next
        ``select`` waits up to ``idle_s`` for serial bytes (the bench sends a 1 ms tick's CAN
        frames and IMU bytes together, so the IMU's bytes wake it; CAN alone waits at most
        ``idle_s``. Side by side, three rounds each: 2 ms took 288-305 ms of CPU per simulated
        second against 341-359 with 0.5 ms, and 270-305 against 305-341 with 1 ms, with the same
        frame latency). No reader threads: no queue hand-over, no wake-up per sample, no
        interpreter lock passed between threads every switch interval (tools/bench_make_run.py
        measures both). The stamps do not depend on when a frame is read
        (interface time on CAN, device time on serial)."""
        sub = self.sub
        live = list(self.adapters)
        wait_s = 0.0
        try:
            while True:
                n = self._poll_inline(self.can, live) if self.can in live else 0
                for a in self._readable_serial(live, wait_s):
                    n += self._poll_inline(a, live)
                if len(sub):
                    self._handle_events(sub.drain(2000))
                    wait_s = 0.0
                elif n == 0:
                    if stop.is_set() or not live:
                        break
                    wait_s = idle_s
                else:
                    wait_s = 0.0
                self._expire()
        finally:
            for a in (self.imu, self.gnss):
                a.close()
            self._finish_input()

    def _finish_input(self) -> None:
        """After the reading stopped: what the serial decoders hold, what is still queued and
        what the sequencer holds go to the system; then the CAN bus closes."""
        self._flush_serial()
        while len(self.sub):
            self._handle_events(self.sub.drain(100_000))
        self.release_held()
        self.can.close()

    def _readable_serial(self, live: list, wait_s: float) -> list:
        """The serial adapters to read now: those whose port holds bytes (waiting up to
        ``wait_s``), and any without a descriptor (closed and reconnecting, or a URL port),
        read after the wait: a lost port must not turn the loop into a spin."""
        fds, out = {}, []
        for a in (self.imu, self.gnss):
            if a in live:
                fd = a.reader_fd() if a.is_open else None
                if fd is None:
                    out.append(a)
                else:
                    fds[fd] = a
        if fds:
            try:
                ready, _, _ = select.select(list(fds), [], [], wait_s)
            except (OSError, ValueError):  # a port closed under us: poll it, it reports the loss
                ready = list(fds)
            out += [fds[fd] for fd in ready]
        elif wait_s:
            time.sleep(wait_s)
        return out

    def _poll_inline(self, a, live: list) -> int:
        """One read of ``a`` without waiting; an adapter that fails is reported and left out."""
        try:
            return a.poll(0.0)
        except EndOfInput:
            live.remove(a)
            return 0
        except Exception as e:  # noqa: BLE001 - reported, never a silent thread death
            self.errors.append(f"{a.name}: {type(e).__name__}: {e}")
            live.remove(a)
            return 0

    def _flush_serial(self) -> None:
        """At the end of the run release what the serial decoders hold: an IMU packet waits for
        the bytes after it when a preamble byte sits in its tail; the clock alignment holds
        messages while it watches a possible clock step."""
        for a in (self.imu, self.gnss):
            flush = getattr(a.protocol, "flush", None)
            if flush is None:
                continue
            try:
                held = flush()
            except Exception as e:  # noqa: BLE001 - a decoder bug must not lose the run
                self.errors.append(f"{a.name} flush: {type(e).__name__}: {e}")
                continue
            for s in held:
                a._publish_sample(s, s.t_ns, self.clock.wall(s.t_ns), False)

    def received_counts(self) -> dict:
        return dict(self.received)

    # --- the loop body --------------------------------------------------------------------------
    def _handle_events(self, events) -> None:
        rec = self.recorder
        received = self.received
        last = self._last_idx
        for ev in events:
            if isinstance(ev, Sample):
                received["samples"] += 1
                src = self._src_of.get(ev.source)
                item = (ev, src, last[src] if src is not None else -1)
                if self.sequencer is None:
                    self._cycle(item)
                else:
                    now = self.clock.now_ns()
                    for it in self.sequencer.push(item, ev.t_ns, ev.kind, now):
                        self._cycle(it, now)
            elif isinstance(ev, RawCan):
                if rec is not None:
                    rec.write(ev)
                if ev.direction == "rx":
                    received["can_frames"] += 1
                    last["can"] = received["can_frames"] - 1
                    self._check_counter(ev.msg)
            elif isinstance(ev, RawSerial):
                if rec is not None:
                    rec.write(ev)
                key = f"{ev.source}_bytes"
                if key in received:
                    received[key] += len(ev.data)
                    last[ev.source] = received[key] - 1

    def _check_counter(self, msg) -> None:
        """Rolling counters of the sensor frames as received, frame to frame: a step other than
        +1 (mod 2^bits) is a break (a frame lost, repeated or reordered on the way). Exact, with
        no time-based guess (the decoder's ``lost_frames`` unwraps long silences by time, which a
        stall of the bench itself can fake)."""
        aid = msg.arbitration_id
        spec = self._counter_of.get(aid)
        data = msg.data
        if spec is None or msg.is_extended_id or len(data) < spec[0]:
            return
        dlc, start, mask = spec
        value = (int.from_bytes(data[:dlc], "little") >> start) & mask
        prev = self._counters_seen.get(aid)
        if prev is not None and (value - prev) & mask != 1:
            self.counter_breaks += 1
        self._counters_seen[aid] = value

    def release_held(self) -> None:
        """Hand the system every sample the sequencer still holds (end of the input)."""
        self._expire(everything=True)

    def _expire(self, everything: bool = False) -> None:
        if self.sequencer is not None:
            items = self.sequencer.flush() if everything else self.sequencer.expire(self.clock.now_ns())
            for it in items:
                self._cycle(it)

    def _cycle(self, item, now_ns: int | None = None) -> None:
        """Hand one sample to the system (recording it and its place in the input order), send or
        record the outputs, log the cycle against the raw record that carried the sample; a
        sample past its deadline is skipped and counted instead (never recorded under
        ``/decoded/``, so the input order stays the system's)."""
        s, src, idx = item
        if self.deadline.skip(s, now_ns):
            return
        if self.recorder is not None and self.recorder.write(s):
            self.input_order.note(s)
        outs = self.system.handle(s)
        n_frames = 0
        first = len(self.frames_sent)
        for o in outs:
            if self._dispatch(o):
                n_frames += 1
        if src is not None:
            self.cycles.add(_SRC_CODE[src], idx, time.monotonic_ns(), n_frames, first if n_frames else -1)

    def _dispatch(self, o) -> bool:
        """Send or record one output; True when a frame went onto the bus."""
        name = type(o).__name__
        if self.on_output is not None:
            self.on_output(o)
        w = self.writer
        if name == "CanFrame":
            import can

            if not self.can.is_open:  # only after the end of the run (or a lost bus): counted
                self.outputs["frames_not_sent"] = self.outputs.get("frames_not_sent", 0) + 1
                return False
            msg = can.Message(arbitration_id=o.arbitration_id, data=o.data, dlc=len(o.data),
                              is_extended_id=False, is_rx=False, check=False)
            self.can.send(msg)
            self.frames_sent.append((time.monotonic_ns(), msg))
            self.outputs["frames"] += 1
            if w is not None:
                doc = S.raw_can_doc(o.t_ns, o.arbitration_id, o.data, direction="tx")
                self._write(lambda: w.write_json(f"/est/can/{o.bus}", S.RAW_CAN, o.t_ns, doc,
                                                 channel_metadata={"bus": o.bus}))
                self.view.outputs((o,), w)
            return True
        if name == "Estimate":
            self.last_estimate = o
            self.outputs["estimates"] += 1
        elif name == "PredictionReport":
            self.outputs["predictions"] += 1
        else:
            self.outputs["other"] += 1
        if w is not None:
            for topic, t, vals, sig in est_docs(o):
                self._write(lambda: w.write_estimate(topic, t, vals, sig))
            if name == "Estimate":
                self.view.outputs((o,), w)
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
        pred = self.system.status().get("prediction")  # its drops, for a replay (record.input_order)
        self.writer.add_metadata(INPUT_ORDER_METADATA, self.input_order.metadata(**({} if pred is None else
                                                                                     {"prediction": pred})))

    def status(self) -> dict:
        return {a.name: a.status() for a in self.adapters}

    def counters(self) -> dict:
        """Received and lost data per stream (decoders' sequence checks included)."""
        can_c = self.can.health.all_counters()
        imu_c = self.imu.health.all_counters()
        gnss_c = self.gnss.health.all_counters()
        return {"can": {"frames": self.received["can_frames"], "counter_breaks": self.counter_breaks,
                        "decoder_lost_frames": can_c.get("lost_frames", 0),
                        "rejected": self.can.health.error_total(), "queue_overflow": can_c.get("queue_overflow", 0)},
                "imu": {"bytes": self.received["imu_bytes"], "packets": imu_c.get("samples", 0),
                        "seq_gaps": imu_c.get("seq_gaps", 0), "rejected": imu_c.get("rejected", 0),
                        "queue_overflow": imu_c.get("queue_overflow", 0)},
                "gnss": {"bytes": self.received["gnss_bytes"], "lines": gnss_c.get("lines", 0),
                         "rejected": gnss_c.get("rejected", 0), "queue_overflow": gnss_c.get("queue_overflow", 0)},
                "subscription_overflows": self.sub.overflows, "reader_errors": list(self.errors),
                "deadline_misses": self.deadline.counts(),
                "warning_status": dict(getattr(self.system, "counters", {}).get("status", {})),
                "unhealthy": dict(getattr(self.system, "counters", {}).get("unhealthy", {})),
                "predictions": self._predictions()}

    def _predictions(self) -> dict:
        """The warning chain's predictions: started, used, dropped at their deadline, failed."""
        pred = self.system.status().get("prediction") if hasattr(self.system, "status") else None
        return {} if not pred else {k: pred[k] for k in ("worker", "latency_s", "started", "used", "dropped", "failed",
                                                         "param_sources", "require_converged") if k in pred}

