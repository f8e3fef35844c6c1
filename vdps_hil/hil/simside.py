"""The vehicle's side of the bench: the simulated drive's sensor output put on live wires at its
own times, paced to the wall clock, and the ECU listening on the CAN bus.

Loop (one thread; ``hil.pacing`` for the time axis)
---------------------------------------------------
::

    repeat
        now = t(m)                                     bench time
        while the simulation is behind now + lookahead: advance it one block (the drive's block_s)
        send every queued item with t_item <= now, in time order      (late ones counted)
        hand warning frames received on CAN to the ECU; ECU timeouts
        sleep until the next item is due, but at least ``send_tick_s`` (wall, 1 ms)
        after this pass began and at most 1 ms
    until the drive has ended and every item is sent

The tick batches the items due within it into one pass, as a USB-CAN adapter delivers frames in
its 1 ms USB frames: a pass per due item cost the simulator side ~3,900 passes per simulated
second (frames 0.3 ms apart) and a third of its CPU. An item is at most one tick late (the late
tolerance is 2 ms); its time stamp is still its scheduled time.

A CAN frame carries its scheduled time on the bus as its time stamp (to interfaces that pass
one on: the virtual bus, socketcand), as a hardware time stamp would: a late send delays the
frame's delivery, not its time stamp.

The simulation runs ``lookahead_s`` (default 20 ms) ahead of the wall clock, less than the ECU's
actuator dead time (>= 100 ms), so an intervention always starts in the simulator's future
(``hil.ecu``). Items are the drive's CAN frames (sent at their receive time ``t_wire``: the
moment their last bit reached the receiver) and serial read chunks (at the arrival of their last
byte); a ``clock_jump`` fault on ``can`` only moves recorded stamps, so it has no effect here.

A second thread blocks on the CAN device side and stamps every frame the pipeline sends the
moment it arrives (``frames_from_pipeline``: (monotonic ns, message)); the loop hands them to
the ECU in order. Truth goes to ``on_truth(topic, t_ns, doc)`` (the recorder; the pipeline never
sees it).
"""

from __future__ import annotations

import collections
import math
import threading
import time
from typing import Any, Callable, Mapping

import numpy as np

from vdps_hil.bus.clocks import wall_minus_monotonic_ns
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.sinks import DriveSink
from vdps_hil.units import NS_PER_S

from .can_devices import CanDeviceSide
from .ecu import Ecu
from .pacing import BenchClock, Pacer
from .serial_device import PtySerialDevice

__all__ = ["LiveSink", "SimulatorSide"]


class LiveSink(DriveSink):
    """A DriveSink that queues the drive's output for sending (and forwards truth)."""

    def __init__(self, on_truth: Callable[[str, int, Mapping[str, Any]], None] | None = None,
                 on_metadata: Callable[[str, Mapping[str, Any]], None] | None = None):
        self.on_truth = on_truth
        self.on_metadata = on_metadata
        self.can_q: collections.deque = collections.deque()  # (t_wire array, ids, dlcs, data) blocks
        self.serial_q: dict[str, collections.deque] = {}
        self.events: list[dict] = []
        self.last_truth: dict | None = None
        self.max_abs_roll_v_rad = 0.0
        self._specs: list[tuple[int, int]] = []
        self._ids = np.zeros(0, np.int64)
        self._dlcs = np.zeros(0, np.int64)
        self.counts = {"can_frames": 0, "serial_chunks": 0}
        self.baud: dict[str, int] = {}
        self.fmt: dict[str, str] = {}

    def metadata(self, name, data) -> None:
        if self.on_metadata is not None:
            self.on_metadata(name, data)

    def truth(self, topic, t_ns, doc) -> None:
        if topic == "events":
            self.events.append(dict(doc))
        else:
            self.last_truth = doc
            r = abs(doc.get("roll_v_rad", 0.0))
            if r > self.max_abs_roll_v_rad:
                self.max_abs_roll_v_rad = r
        if self.on_truth is not None:
            self.on_truth(topic, t_ns, doc)

    def can_block(self, bus, t_ns, t_wire_ns, route, data, specs) -> None:
        if len(route) == 0:
            return
        if specs is not self._specs:
            self._specs = specs
            self._ids = np.array([s[0] for s in specs], np.int64)
            self._dlcs = np.array([s[1] for s in specs], np.int64)
        self.can_q.append([np.array(t_wire_ns, np.int64), self._ids[route], self._dlcs[route],
                           np.array(data, np.uint8), 0])
        self.counts["can_frames"] += len(route)

    def serial_chunks(self, device, baud, fmt, chunks) -> None:
        q = self.serial_q.setdefault(device, collections.deque())
        q.extend(chunks)
        self.baud[device], self.fmt[device] = baud, fmt
        self.counts["serial_chunks"] += len(chunks)

    def next_due_ns(self) -> float:
        t = math.inf
        if self.can_q:
            blk = self.can_q[0]
            t = float(blk[0][blk[4]])
        for q in self.serial_q.values():
            if q:
                t = min(t, float(q[0][0]))
        return t

    @property
    def empty(self) -> bool:
        return not self.can_q and not any(self.serial_q.values())


class SimulatorSide:
    """Drives one :class:`~vdps_hil.sim.drive.Drive` onto live wires (module docstring).

    ``can``: the CAN device side; ``serial``: device name (``imu``, ``gnss``) -> pty device;
    ``clock``: the bench clock (started by :meth:`run` unless already started); ``ecu``: the
    :class:`~vdps_hil.hil.ecu.Ecu` (attached to the simulator). The simulation advances in the
    drive's ``block_s`` (the bench uses 20 ms: 10 ms blocks cost 54 against 34 ms of CPU per
    simulated second in the per-block work), so a seed gives the same wire content as
    ``Drive.run`` with that block length."""

    def __init__(self, drive: Drive, can: CanDeviceSide, serial: Mapping[str, PtySerialDevice], clock: BenchClock,
                 ecu: Ecu, *, lookahead_s: float = 0.02, late_tolerance_s: float = 0.002,
                 send_tick_s: float = 0.001, on_truth=None, on_metadata=None):
        if not 0 < lookahead_s < ecu.config.delay_s:
            raise ValueError("lookahead_s must be positive and below the ECU's dead time")
        if lookahead_s + drive.block_s >= ecu.config.delay_s:  # the simulation's largest lead
            raise ValueError("lookahead_s plus the drive's block_s must be below the ECU's dead time")
        self.drive = drive
        self.can = can
        self.serial = dict(serial)
        self.clock = clock
        self.ecu = ecu
        self.block_s = drive.block_s  # one block length: the faults' random draws follow the blocks
        self.lookahead_ns = int(round(lookahead_s * NS_PER_S))
        if not 0 <= send_tick_s < late_tolerance_s:
            raise ValueError("send_tick_s must be >= 0 and below the late tolerance")
        self.send_tick_ns = int(round(send_tick_s * NS_PER_S))  # wall
        self.pacer = Pacer(clock, late_tolerance_s)
        self.sink = LiveSink(on_truth, on_metadata)
        self.session = None
        self.frames_from_pipeline: list[tuple[int, Any]] = []
        self._inbox: collections.deque = collections.deque()
        self._rx_stop = threading.Event()
        self._rx_thread: threading.Thread | None = None
        self.done = threading.Event()
        self.error: str = ""
        self.counts = {"frames_sent": 0, "frames_dropped": 0, "serial_bytes": {}, "imu_packets_sent": 0,
                       "lines_sent": 0, "serial_dropped": {}}
        self.wall_s = 0.0
        self.sim_s = 0.0
        self.passes = 0  # of the send loop (at most one per send tick)
        self._wall_minus_mono_ns = wall_minus_monotonic_ns()

    # --- CAN receive thread ---------------------------------------------------------------------
    def _rx_loop(self) -> None:
        can = self.can
        while not self._rx_stop.is_set():
            items = can.poll(0.02)
            if items:
                self._inbox.extend(items)

    def start_receiver(self) -> None:
        self._rx_thread = threading.Thread(target=self._rx_loop, name="bench-can-rx", daemon=True)
        self._rx_thread.start()

    def prepare(self) -> None:
        """Build the drive session (simulator, sensors) before the clock starts."""
        self.session = self.drive.start(self.sink)
        self.ecu.attach(self.session.sim)

    # --- the loop -----------------------------------------------------------------------------
    def run(self, stop: threading.Event | None = None) -> None:
        try:
            self._run(stop or threading.Event())
        except Exception as e:  # noqa: BLE001 - reported by the bench, never a silent thread death
            self.error = f"{type(e).__name__}: {e}"
            raise
        finally:
            self.done.set()

    def _run(self, stop: threading.Event) -> None:
        if self.session is None:
            self.prepare()
        session, sink, clock, pacer = self.session, self.sink, self.clock, self.pacer
        if self._rx_thread is None:
            self.start_receiver()
        if not clock.started:
            clock.start()
        block_ns = int(round(self.block_s * NS_PER_S))
        m_start = time.monotonic_ns()
        tick_ns = self.send_tick_ns * clock.speed  # bench time
        while not stop.is_set():
            self.passes += 1
            now = clock.now_ns()
            while not session.done and session.t_ns < now + self.lookahead_ns:
                session.advance((session.t_ns + block_ns) / NS_PER_S)
            self._send_due(clock.now_ns())
            self.serve_ecu()
            if session.done and sink.empty:
                break
            nxt = min(sink.next_due_ns(), session.t_ns - self.lookahead_ns if not session.done else math.inf)
            if math.isfinite(nxt):
                pacer.wait_until(int(max(nxt, now + tick_ns)), 0.001)
        self.wall_s = (time.monotonic_ns() - max(m_start, clock.mono0_ns)) / NS_PER_S
        self.sim_s = session.t_ns / NS_PER_S

    def _send_due(self, now_ns: int) -> None:
        sink, pacer = self.sink, self.pacer
        # CAN: the due frames of the queued blocks, in order
        ids_l, dlcs_l, data_l, t_l = [], [], [], []
        q = sink.can_q
        while q:
            blk = q[0]
            t, ids, dlcs, data, k = blk
            j = int(np.searchsorted(t, now_ns, side="right"))
            if j > k:
                t_l.append(t[k:j])
                ids_l.append(ids[k:j])
                dlcs_l.append(dlcs[k:j])
                data_l.append(data[k:j])
                blk[4] = j
            if j >= len(t):
                q.popleft()
            else:
                break
        # serial chunks due, per device (each device's stream in order)
        serial_due = []
        for dev, sq in sink.serial_q.items():
            while sq and sq[0][0] <= now_ns:
                serial_due.append((sq[0][0], dev, sq.popleft()[1]))
        if t_l:
            one = len(t_l) == 1  # the usual pass: part of one block, no copies
            t = t_l[0] if one else np.concatenate(t_l)
            c = self.clock
            stamps = ((c.mono0_ns + t / c.speed) + self._wall_minus_mono_ns) / NS_PER_S  # on the bus, wall s
            n = self.can.send_frames((ids_l[0] if one else np.concatenate(ids_l)).tolist(),
                                     (dlcs_l[0] if one else np.concatenate(dlcs_l)).tolist(),
                                     data_l[0] if one else np.concatenate(data_l), stamps.tolist())
            self.counts["frames_sent"] += len(t)
            self.counts["frames_dropped"] += len(t) - n
            pacer.sent(t, time.monotonic_ns())
        if serial_due:
            serial_due.sort(key=lambda x: x[0])
            for t_c, dev, data in serial_due:
                self.serial[dev].write(data)
                pacer.sent((t_c,), time.monotonic_ns())
        self.can.pump()
        for d in self.serial.values():
            d.pump()

    def serve_ecu(self) -> None:
        inbox = self._inbox
        clock, ecu = self.clock, self.ecu
        while inbox:
            m, msg = inbox.popleft()
            self.frames_from_pipeline.append((m, msg))
            ecu.on_frame(clock.t_of(m), msg)
        ecu.poll(clock.now_ns())

    def flush(self, timeout_s: float = 2.0) -> None:
        """Push what the device FIFOs still hold (after the run) and collect late frames."""
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            self.can.pump()
            for d in self.serial.values():
                d.pump()
            if all(d.pending_bytes == 0 for d in self.serial.values()):
                break
            time.sleep(0.001)
        self.serve_ecu()

    def stop_receiver(self) -> None:
        self._rx_stop.set()
        if self._rx_thread is not None:
            self._rx_thread.join(timeout=2.0)
        self.serve_ecu()

    def sent_counts(self) -> dict:
        """What the vehicle put on the wires (and what its device FIFOs dropped)."""
        imu = self.serial.get("imu")
        gnss = self.serial.get("gnss")
        return {"frames_sent": self.counts["frames_sent"] - self.counts["frames_dropped"],
                "frames_dropped_at_device": self.counts["frames_dropped"],
                "imu_bytes_sent": imu.log.total if imu else 0,
                "imu_dropped_at_device": imu.dropped if imu else 0,
                "lines_sent": gnss.lines if gnss else 0,
                "gnss_dropped_at_device": gnss.dropped if gnss else 0}
