"""One run of a drive into a sink, block by block (:class:`DriveSession`, made by
``Drive.start``): the truth simulator steps, each sensor samples the block vectorised, the
faults act, the messages are encoded on the real wire formats (``sim.wire``) and handed to the
sink; and what the run produced (:class:`DriveSummary`). The topics, metadata and block rules
are in :mod:`vdps_hil.sim.drive`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from vdps_hil.geodesy import DEFAULT_ORIGIN
from vdps_hil.units import NS_PER_S

from .faults import FaultSet
from .sampling import StepRecorder
from .sensors import GnssModel, ImuModel, chassis_sensors
from .simulator import Simulator
from .sinks import DriveSink
from .wire import SerialLink, bus_offsets_ns, can_packers, frame_time_ns, pack_imu_packets

__all__ = ["DriveSession", "DriveSummary", "GNSS_FORMAT", "IMU_FORMAT"]

IMU_FORMAT = "xsens-mtdata2"
GNSS_FORMAT = "nmea"


@dataclass
class DriveSummary:
    """What a drive produced (``to_json`` is the CLI's ``--json`` document)."""

    scenario: str
    output: str | None
    profile: str
    seed: int
    duration_s: float
    stop_reason: str
    messages: dict[str, int]
    final_speed_mps: float
    max_abs_roll_rad: float
    max_abs_roll_rel_road_rad: float
    rollover_events: list[dict]
    effects: list[str]
    faults: list[str]
    wall_time_s: float
    timing_s: dict[str, float] = field(default_factory=dict)
    time_backwards: dict[str, int] = field(default_factory=dict)
    truth: dict = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        return self.duration_s / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def to_json(self) -> dict:
        return {"scenario": self.scenario, "output": self.output, "profile": self.profile,
                "seed": self.seed, "duration_s": self.duration_s, "stop_reason": self.stop_reason,
                "messages": dict(sorted(self.messages.items())),
                "messages_total": sum(self.messages.values()),
                "final_speed_mps": self.final_speed_mps,
                "max_abs_roll_rad": self.max_abs_roll_rad,
                "max_abs_roll_deg": math.degrees(self.max_abs_roll_rad),
                "max_abs_roll_rel_road_rad": self.max_abs_roll_rel_road_rad,
                "max_abs_roll_rel_road_deg": math.degrees(self.max_abs_roll_rel_road_rad),
                "rollover_events": list(self.rollover_events),
                "effects": list(self.effects), "faults": list(self.faults),
                "wall_time_s": self.wall_time_s, "real_time_factor": self.real_time_factor,
                "timing_s": dict(self.timing_s), "time_backwards": dict(self.time_backwards),
                "truth": dict(self.truth)}


class DriveSession:
    """One run of a :class:`~vdps_hil.sim.drive.Drive` into a :class:`DriveSink` (``Drive.start``).

    ``advance(until_s=None)`` steps the simulator to ``until_s`` (default: one ``block_s`` on;
    never past the drive's duration), samples the sensors over the steps taken, applies the
    faults, encodes and hands the block's output to the sink: every CAN frame received by the
    block's end and every serial read window ended by then (the rest waits for the next block;
    the last block delivers everything). Returns False once the drive has ended (duration
    reached or the simulator stopped). ``t_ns`` is the simulated time reached; ``sim`` the
    :class:`Simulator` (``set_input_override`` acts from the next step on).
    """

    def __init__(self, drive, sink: DriveSink):
        self.drive = drive
        self.sink = sink
        self.done = False
        timing = {"physics_and_recorder": 0.0, "truth_write": 0.0, "sensors": 0.0,
                  "can_write": 0.0, "serial_write": 0.0}
        self._timing = timing
        self.faults = FaultSet(drive.fault_specs, seed=drive.seed, dbc=drive.dbc)  # fresh state per run
        self._stats = {"final_speed_mps": math.nan, "max_roll": 0.0, "max_roll_v": 0.0, "t_s": 0.0}
        self._events: list[dict] = []
        self._fault_events = sorted(
            [(f.start_ns, {"kind": "fault_start", "fault": f.name, **f.params}) for f in self.faults]
            + [(f.end_ns, {"kind": "fault_end", "fault": f.name, **f.params}) for f in self.faults
               if f.end_ns < (1 << 61)], key=lambda e: e[0])
        if drive.truth is None:
            sim = Simulator(drive.vehicle, scenario=drive.scenario, effects=drive.effect_set,
                            record_truth=False, on_truth=self._on_truth, duration_s=drive.duration_s)
        else:
            sim = drive.truth.simulator(drive.scenario, drive.effect_set, record_truth=False,
                                        on_truth=self._on_truth, duration_s=drive.duration_s)
        self.sim = sim
        self._setup(sim)
        self._end_n = int(math.floor(drive.duration_s * NS_PER_S / sim.dt_ns + 1e-9))
        self._block_n = max(1, int(round(drive.block_s * NS_PER_S / sim.dt_ns)))
        sink.metadata("truth.drive", self._truth_config())

    @property
    def t_ns(self) -> int:
        return self.sim.t_ns

    @property
    def end_ns(self) -> int:
        return self._end_n * self.sim.dt_ns

    @property
    def events(self) -> list[dict]:
        """Rollover events so far (as written to ``/truth/events``)."""
        return list(self._events)

    def _truth_config(self) -> dict:
        d, p = self.drive, self.drive.profile
        return {"scenario": d.scenario.name, "scenario_path": d.scenario.path,
                "vehicle": d.vehicle.name, "vehicle_sha256": d.vehicle.source_sha256,
                "duration_s": d.duration_s, "seed": d.seed,
                "effects": [{"name": e.name, "family": e.family, **e.params} for e in d.effect_set],
                "faults": self.faults.describe(),
                "profile": {"name": p.name, "quantise_dbc": p.quantise_dbc,
                            "gnss": vars(p.gnss), "imu": vars(p.imu), "suspension": vars(p.suspension),
                            "tachometer": vars(p.tachometer), "wheel_torque": vars(p.wheel_torque),
                            "steering": vars(p.steering)},
                "imu_unit": self._imu.describe(),
                "enu_origin": {"lat_deg": DEFAULT_ORIGIN.lat_deg, "lon_deg": DEFAULT_ORIGIN.lon_deg,
                               "h_m": DEFAULT_ORIGIN.h_m},
                "bus": d.bus, "read_period_s": d.read_period_ns / NS_PER_S, "truth": self._truth_backend()}

    def _truth_backend(self) -> dict:
        d = self.drive
        return {"backend": "ours"} if d.truth is None else d.truth.describe(self.sim)

    def _setup(self, sim: Simulator) -> None:
        d = self.drive
        p, m, seed, dt = d.profile, d.vehicle.mounting, d.seed, sim.dt_ns
        meas = sim.effects.measurement
        self._imu = ImuModel(p.imu, m, meas, seed, dt)
        self._gnss = GnssModel(p.gnss, m, seed, dt)
        packers = can_packers(d.dbc)
        res = {f: s.resolution for name, spec in d.dbc.messages.items() if spec.is_sensor
               for f, s in zip(spec.field_names, spec.values)}
        self._chassis = chassis_sensors(p, seed, dt, res, meas)
        # messages fed by each chassis sensor (all of a message's fields from that sensor)
        self._routes = []
        for sensor in self._chassis:
            for name, pk in packers.items():
                if set(pk.field_names) <= set(sensor.fields):
                    cols = [sensor.fields.index(f) for f in pk.field_names]
                    self._routes.append((sensor, name, pk, cols))
        self._msg_names = [r[1] for r in self._routes]
        self._msg_index = {n: i for i, n in enumerate(self._msg_names)}
        self.frame_specs = [(pk.frame_id, pk.dlc) for _, _, pk, _ in self._routes]
        self._dur_ns = np.array([frame_time_ns(pk.dlc, d.dbc.bitrate_bps) for _, _, pk, _ in self._routes],
                                dtype=np.int64)
        self._ids = np.array([pk.frame_id for _, _, pk, _ in self._routes], dtype=np.int64)
        self._counters = [0] * len(self._routes)
        self._pend_t = np.zeros(0, np.int64)
        self._pend_m = np.zeros(0, np.int64)
        self._pend_d = np.zeros((0, 8), np.uint8)
        self._imu_link = SerialLink("imu", p.imu.baud, d.read_period_ns, self.faults.serial_keep_fn("imu"))
        self._gnss_link = SerialLink("gnss", p.gnss.baud, d.read_period_ns, self.faults.serial_keep_fn("gnss"))
        self._gnss_latency_ns = int(round(p.gnss.latency_s * NS_PER_S))
        self._recorder = StepRecorder(sim)

    # ------------------------------------------------------------------------------------------
    def _on_truth(self, s: dict) -> None:
        t0 = time.perf_counter()
        sink = self.sink
        t_ns = int(s["t_ns"])
        fe = self._fault_events
        while fe and fe[0][0] <= t_ns:
            tf, doc = fe.pop(0)
            sink.truth("events", max(tf, 0), doc)
        events = s.pop("events", None) or []
        for ev in events:
            self._events.append(ev)
            sink.truth("events", t_ns, ev)
        sink.truth("state", t_ns, s)
        st = self._stats
        st["final_speed_mps"] = s["speed_mps"]
        st["max_roll"] = max(st["max_roll"], abs(s["roll_g_rad"]))
        st["max_roll_v"] = max(st["max_roll_v"], abs(s["roll_v_rad"]))
        st["t_s"] = s["t_s"]
        self._timing["truth_write"] += time.perf_counter() - t0

    def advance(self, until_s: float | None = None) -> bool:
        """Step and deliver one block (class docstring); False once the drive has ended."""
        if self.done:
            return False
        sim = self.sim
        if until_s is None:
            target = sim.n + self._block_n
        else:
            target = int(math.floor(until_s * NS_PER_S / sim.dt_ns + 1e-9))
        target = min(target, self._end_n)
        t0 = time.perf_counter()
        tw0 = self._timing["truth_write"]
        sim.step_n(target)
        self._timing["physics_and_recorder"] += time.perf_counter() - t0 - (self._timing["truth_write"] - tw0)
        block = self._recorder.take()
        last = sim.stopped or sim.n >= self._end_n
        self._process(block, sim.t_ns, final=last)
        self.done = last
        return not last

    def _process(self, block, t_block_end_ns: int, final: bool) -> None:
        timing = self._timing
        t0 = time.perf_counter()
        faults = self.faults
        # --- IMU
        imu = self._imu.sample(block, faults)
        if len(imu.k):
            off = faults.clock_offset_ns("imu", imu.t_ns)
            t_dev = imu.t_ns if off is None else imu.t_ns + off
            self._imu_link.send(imu.t_ns, pack_imu_packets(t_dev, imu.k, imu.specific_force_mps2,
                                                           imu.angular_rate_radps))
        # --- GNSS
        t_ready, msgs = [], []
        for ep in self._gnss.sample(block, faults):
            lines = self._gnss.sentences(ep, faults)
            t_ready += [ep.t_ns + self._gnss_latency_ns] * len(lines)
            msgs += lines
        if msgs:
            self._gnss_link.send(np.array(t_ready, dtype=np.int64), msgs)
        # --- CAN
        t, m, d = self._can_frames(block, faults)
        n_out = len(t) if final else int(np.searchsorted(t, t_block_end_ns, side="right"))
        self._pend_t, self._pend_m, self._pend_d = t[n_out:], m[n_out:], d[n_out:]
        serial = [(link, fmt, link.chunks(t_block_end_ns, final=False))
                  for link, fmt in ((self._imu_link, IMU_FORMAT), (self._gnss_link, GNSS_FORMAT))]
        if final:
            serial = [(link, fmt, ch + link.chunks(1 << 62, final=True)) for link, fmt, ch in serial]
        t_wire = t[:n_out]
        off = faults.clock_offset_ns("can", t_wire)  # the interface's clock stamps the frames
        t_write = t_wire if off is None else np.maximum(t_wire + off, 0)
        t1 = time.perf_counter()
        timing["sensors"] += t1 - t0
        # --- deliver
        self.sink.can_block(self.drive.bus, t_write, t_wire, m[:n_out], d[:n_out], self.frame_specs)
        t2 = time.perf_counter()
        timing["can_write"] += t2 - t1
        for link, fmt, chunks in serial:
            if chunks:
                self.sink.serial_chunks(link.device, link.baud, fmt, chunks)
        timing["serial_write"] += time.perf_counter() - t2

    def _can_frames(self, block, faults: FaultSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The block's chassis samples packed into CAN frames (rolling counters, faults on values
        and frames), with the frames still pending from the last block: (receive times, message
        index, payloads), in reception order."""
        ts, ms, ds = [self._pend_t], [self._pend_m], [self._pend_d]
        samples = {}
        for sensor in self._chassis:
            samples[sensor.name] = sensor.sample(block)
        t_all, m_all, d_all = [], [], []
        for i, (sensor, name, pk, cols) in enumerate(self._routes):
            t_meas, v = samples[sensor.name]
            n = len(t_meas)
            if n == 0:
                continue
            vals = v[:, cols].copy()
            faults.can_values(name, pk.field_names, t_meas, vals)
            c0 = self._counters[i]
            self._counters[i] = c0 + n
            data = np.zeros((n, 8), np.uint8)
            data[:, :pk.dlc] = pk.pack(vals, np.arange(c0, c0 + n))
            t_all.append(t_meas)
            m_all.append(np.full(n, i, np.int64))
            d_all.append(data)
        if t_all:
            t = np.concatenate(t_all)
            m = np.concatenate(m_all)
            d = np.concatenate(d_all)
            t_rx = t + bus_offsets_ns(t, self._ids[m], self._dur_ns[m])
            keep = np.ones(len(t), bool)
            for i, name in enumerate(self._msg_names):
                sel = m == i
                if sel.any():
                    k = faults.can_keep(name, t_rx[sel])
                    if k is not None:
                        keep[np.flatnonzero(sel)[~k]] = False
            ts.append(t_rx[keep])
            ms.append(m[keep])
            ds.append(d[keep])
        t = np.concatenate(ts)
        m = np.concatenate(ms)
        d = np.concatenate(ds)
        order = np.argsort(t, kind="stable")
        return t[order], m[order], d[order]

    def summary(self, output=None, wall0: float | None = None) -> DriveSummary:
        """The :class:`DriveSummary` so far (``output``: what the sink wrote to, for the record)."""
        st, sim, d = self._stats, self.sim, self.drive
        out = os.fspath(output) if isinstance(output, (str, os.PathLike)) else getattr(output, "name", None)
        wall = 0.0 if wall0 is None else time.perf_counter() - wall0
        return DriveSummary(
            scenario=d.scenario.name, output=out if isinstance(out, str) else None,
            profile=d.profile.name, seed=d.seed, duration_s=sim.t_s,
            stop_reason=sim.stop_reason or "duration", messages=self.sink.messages,
            final_speed_mps=st["final_speed_mps"], max_abs_roll_rad=st["max_roll"],
            max_abs_roll_rel_road_rad=st["max_roll_v"], rollover_events=list(self._events),
            effects=list(d.effect_set.names), faults=[f.spec() for f in self.faults],
            wall_time_s=wall, timing_s=dict(self._timing),
            time_backwards=self.sink.time_backwards, truth=self._truth_backend())
