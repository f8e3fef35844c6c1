"""Tests of hil.node: the pipeline node hands every sample to the system in arrival order, sends
the system's VDPS_Warning frames on CAN, records raw/decoded/est and the input order, and logs
one output cycle per sample with the index of the frame or byte that carried it."""

from __future__ import annotations

import io
import os
import pty
import threading
import time
import tty

import can
import numpy as np
import pytest

from vdps_hil.bus.clocks import wall_minus_monotonic_ns
from vdps_hil.hil.bench_config import make_system
from vdps_hil.hil.latency import SOURCES
from vdps_hil.hil.node import INPUT_ORDER_METADATA, PipelineNode, input_order_samples
from vdps_hil.hil.pacing import BenchClock
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.schemas import DEFAULT_SIM_EPOCH_NS
from vdps_hil.record.writer import RecordingWriter
from vdps_hil.sim.drive import Drive


@pytest.fixture(scope="module")
def drive_recording():
    buf = io.BytesIO()
    Drive("paper", seed=2, duration_s=1.2).run(buf)
    buf.seek(0)
    return buf.getvalue()


def _feed(node, recording: bytes, before=None):
    """Feed a recording's raw CAN frames and serial chunks to the node's adapters in time order,
    as their readers would, the node handling what they published after each; yields (source,
    t_ns, payload) after each; ``before(t_ns)`` is called before each is fed."""
    with RecordingReader(io.BytesIO(recording)) as r:
        raw = [("can", t, m) for t, m in ((round(m.timestamp * 1e9), m) for _, m in r.iter_raw_can("vdps"))]
        raw += [(dev, t, d) for dev, t, d in r.iter_raw_serial()]
    raw.sort(key=lambda x: x[1])
    adapters = {"can": node.can, "imu": node.imu, "gnss": node.gnss}
    for src, t, payload in raw:
        if before is not None:
            before(t)
        adapters[src].ingest([(t, payload)])
        node._handle_events(node.sub.drain())
        yield src, t, payload


def test_node_handles_records_and_logs_every_sample_in_arrival_order(drive_recording):
    system = make_system("sedan-model", 1000.0, 0.001)
    out = io.BytesIO()
    writer = RecordingWriter(out, sim_epoch_ns=DEFAULT_SIM_EPOCH_NS)
    node = PipelineNode(system, "virtual:test-node", "/dev/null-imu", "/dev/null-gnss", BenchClock(1.0),
                        writer=writer)
    listener = can.Bus(interface="virtual", channel="test-node")
    node.can.open()  # the serial adapters are fed directly below, as their readers would
    try:
        n_frames, n_bytes = 0, {"imu": 0, "gnss": 0}
        for src, t, payload in _feed(node, drive_recording):  # arrival order: time order here
            if src == "can":
                n_frames += 1
            else:
                n_bytes[src] += len(payload)
        held = len(node.sequencer)
        node.release_held()
        node.finish_recording()
        writer.close()
        sent_on_bus = []
        while (m := listener.recv(0.05)) is not None:
            sent_on_bus.append(m)
    finally:
        listener.shutdown()
        node.can.close()
    assert node.received_counts() == {"can_frames": n_frames, "imu_bytes": n_bytes["imu"],
                                      "gnss_bytes": n_bytes["gnss"], "samples": len(system.input_log)}
    # one cycle per sample, its input index the count of its stream so far
    a = node.cycles.arrays()
    assert len(a["src"]) == len(system.input_log) > 1000
    can_idx = a["idx"][a["src"] == SOURCES.index("can")]
    assert can_idx.min() >= 0 and can_idx.max() == n_frames - 1 and (can_idx[1:] >= can_idx[:-1]).all()
    imu_idx = a["idx"][a["src"] == SOURCES.index("imu")]
    assert imu_idx.max() == n_bytes["imu"] - 1
    # the system's frames went onto the bus, in order, and are logged against their cycles
    assert node.outputs["frames"] == len(node.frames_sent) == len(sent_on_bus) > 0
    assert [bytes(m.data) for m in sent_on_bus] == [bytes(m.data) for _, m in node.frames_sent]
    assert a["n_frames"].sum() == len(node.frames_sent)
    # every measurement reached the system once the IMU had arrived up to its time: the next IMU
    # sample in the input is at or after it (held ones go just before the IMU sample that
    # released them; after the last IMU sample only the end of the input releases)
    nxt, early = None, 0
    for smp in reversed(system.input_log):
        if smp.kind == "imu":
            nxt = smp.t_ns
        elif nxt is not None and smp.t_ns > nxt:
            early += 1
    assert node.sequencer.held_total > 1000 and held > 0 and early == 0
    # the recording replays the exact input sequence
    out.seek(0)
    with RecordingReader(out) as r:
        topics = r.topics()
        assert INPUT_ORDER_METADATA in r.metadata()
        again = input_order_samples(r)
    assert [(s.t_ns, s.source, s.kind, s.fields) for s in again] == \
        [(s.t_ns, s.source, s.kind, s.fields) for s in system.input_log]
    assert topics["/est/can/vdps"].count == len(node.frames_sent)
    assert sum(1 for _, m in RecordingReader(io.BytesIO(out.getvalue())).iter_raw_can("vdps")
               if not m.is_rx) == len(node.frames_sent)


def test_input_order_needs_a_bench_recording(drive_recording):
    with RecordingReader(io.BytesIO(drive_recording)) as r:
        with pytest.raises(ValueError, match="no hil.input_order metadata"):
            input_order_samples(r)


def test_a_node_past_its_deadline_skips_its_own_work_until_it_is_back_and_counts_it(drive_recording):
    """The bench clock reads 150 ms past every input of simulated 0.5-0.7 s (a pipeline held up
    for 0.2 s) and on time otherwise: with the 100 ms deadline the node skips every sample from
    the first late IMU sample until an IMU sample is within 50 ms again -- the IMU samples of
    0.5-0.7 s, one episode -- hands the system none of them, records none under /decoded/, and
    the estimator sees the skipped span as an IMU outage (a gap longer than its 20 ms timeout)."""
    now = [0]
    clock = BenchClock(1.0, mono0_ns=0, monotonic_ns=lambda: now[0])
    system = make_system("sedan-model", 1000.0, 0.001)
    out = io.BytesIO()
    writer = RecordingWriter(out, sim_epoch_ns=DEFAULT_SIM_EPOCH_NS)
    node = PipelineNode(system, "virtual:test-node-late", "/dev/null-imu", "/dev/null-gnss", clock, writer=writer)
    node.can.open()
    try:
        def held_up(t_ns):  # the clock 150 ms past the inputs of 0.5-0.7 s
            now[0] = t_ns + (150_000_000 if 0.5e9 <= t_ns < 0.7e9 else 0)

        for _ in _feed(node, drive_recording, held_up):
            pass
        node.release_held()
        node.finish_recording()
        writer.close()
    finally:
        node.can.close()
    m = node.counters()["deadline_misses"]
    assert m["episodes"] == 1 and m["deadline_ms"] == 100.0 and m["samples"] == sum(m["by_kind"].values())
    assert m["first_t_s"] == pytest.approx(0.5, abs=0.002)
    assert m["by_kind"]["imu"] == pytest.approx(200, abs=3)  # 0.5-0.7 s of the 1 kHz IMU
    assert m["by_kind"]["wheel_speed"] > 0 and m["by_kind"]["suspension"] > 0  # every kind goes
    handled_imu = [s.t_ns for s in system.input_log if s.kind == "imu"]
    assert not [t for t in handled_imu if 0.501e9 <= t < 0.699e9]
    assert len(handled_imu) + m["by_kind"]["imu"] == node.counters()["imu"]["packets"]
    with RecordingReader(io.BytesIO(out.getvalue())) as r:
        decoded = sum(v.count for k, v in r.topics().items() if k.startswith("/decoded/"))
        assert decoded == len(system.input_log) == len(input_order_samples(r))
    assert system.counters["unhealthy"]["imu_fault"] > 0  # the estimator saw the outage


def _paced_feed(recording: bytes, clock, channel: str, masters: dict, stop_after: threading.Event) -> None:
    """Send a recording's raw CAN frames on a virtual bus (stamped with their bench time on the
    wall clock, as the bench's interface does) and write its serial chunks into pty masters,
    each when the bench clock reaches its time."""
    with RecordingReader(io.BytesIO(recording)) as r:
        raw = [("can", round(m.timestamp * 1e9), m) for _, m in r.iter_raw_can("vdps")]
        raw += [(dev, t, d) for dev, t, d in r.iter_raw_serial()]
    raw.sort(key=lambda x: x[1])
    sender = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    w_m = wall_minus_monotonic_ns()
    try:
        for src, t, payload in raw:
            while clock.now_ns() < t:
                time.sleep(0.0005)
            if src == "can":
                stamp = (clock.mono0_ns + t + w_m) / 1e9
                sender.send(can.Message(timestamp=stamp, arbitration_id=payload.arbitration_id,
                                        data=payload.data, is_extended_id=False))
            else:
                os.write(masters[src], payload)
    finally:
        sender.shutdown()
        stop_after.set()


def _pty_node(channel: str, readers: str, **kw):
    """Raw pseudo-terminals for the IMU and the GNSS and a node of the sedan's system reading them
    and python-can's virtual bus ``channel``: (ptys {device: (master, slave)}, clock, node)."""
    ptys = {dev: pty.openpty() for dev in ("imu", "gnss")}
    for _, sl in ptys.values():
        tty.setraw(sl)
    clock = BenchClock(1.0)
    node = PipelineNode(make_system("sedan-model", 1000.0, 0.001), f"virtual:{channel}", os.ttyname(ptys["imu"][1]),
                        os.ttyname(ptys["gnss"][1]), clock, readers=readers, **kw)
    return ptys, clock, node


@pytest.mark.parametrize("readers", ["inline", "threads"])
def test_the_node_reads_real_ptys_and_a_can_bus_and_hands_over_every_sample(drive_recording, readers):
    """The node run live on python-can's virtual bus and real pseudo-terminals, the drive fed at
    its own pace: with the reads in the pipeline's own loop (``inline``, the bench's default) as
    with a reader thread per adapter, every frame and byte is received, every sample decoded is
    handed to the system once, and the system's input is the same set of samples as a replay's
    decoding of the same drive (the same values in the same time order; the stamps are the
    interface's and the devices' own: CAN within 2 us; the serial devices' clock alignment never
    earlier than the wire time, and as late as the host's read delays)."""
    from vdps_hil.record.decode import decode_recording

    channel = f"test-node-live-{readers}"
    # deadline_s=None: every sample, however loaded the machine
    ptys, clock, node = _pty_node(channel, readers, deadline_s=None)
    system = node.system
    node.open()
    fed, stop = threading.Event(), threading.Event()
    clock.start()
    feeder = threading.Thread(target=_paced_feed, args=(drive_recording, clock, channel,
                                                         {d: m for d, (m, _) in ptys.items()}, fed))
    runner = threading.Thread(target=node.run, args=(stop,))
    feeder.start()
    runner.start()
    t0 = time.monotonic()
    try:
        feeder.join(30)
        fed_s = time.monotonic() - t0
        time.sleep(0.3)  # the last bytes through the ptys
        stop.set()
        runner.join(30)
        assert not runner.is_alive() and not node.errors
        assert not feeder.is_alive(), f"the feeder still writing after {fed_s:.1f} s"
    finally:
        for m, sl in ptys.values():
            os.close(m)
            os.close(sl)
    with RecordingReader(io.BytesIO(drive_recording)) as r:
        n_frames = sum(1 for _ in r.iter_raw_can("vdps"))
        n_bytes = {dev: 0 for dev in ptys}
        for dev, _, d in r.iter_raw_serial():
            n_bytes[dev] += len(d)
    got = node.received_counts()
    # a short count has happened in CI runs (5,877 of 56,447 IMU bytes, once in ~40 runs): the
    # message carries what tells its mechanism (a lost device, a reader overflow, a slow feed)
    why = {a.name: (a.health.state, a.health.bytes, {k: v for k, v in a.health.counters.items() if v})
           for a in node.adapters}
    assert (got["can_frames"], got["imu_bytes"], got["gnss_bytes"]) == (n_frames, n_bytes["imu"], n_bytes["gnss"]), \
        f"fed in {fed_s:.2f} s; adapters {why}"

    def by_kind(samples):
        out = {}
        for s in sorted(samples, key=lambda s: (s.t_ns, s.source)):
            out.setdefault(s.kind, []).append((s.t_ns, s.fields))
        return out

    offline = by_kind(decode_recording(io.BytesIO(drive_recording)))
    live = by_kind(system.input_log)
    assert len(system.input_log) == got["samples"] == sum(map(len, offline.values())) > 3000
    assert {"imu", "wheel_speed", "suspension", "gnss_pos"} <= set(offline) == set(live)
    for kind, rows in offline.items():
        assert [f for _, f in live[kind]] == [f for _, f in rows], kind  # the same values, in time order
        dt_ns = np.array([t for t, _ in live[kind]]) - np.array([t for t, _ in rows])
        if kind in ("imu", "gnss_pos", "gnss_vel", "gnss_att"):
            # device time mapped onto the host by a leaky running minimum of host minus device
            # time: live, the host's read delays are in it until smaller ones are seen, so how
            # late depends on the machine's load (53 ms, and 261 ms with the reader threads, in
            # CI runs on a loaded machine); never earlier than the wire time
            assert dt_ns.min() >= -1e6, kind
        else:  # CAN: the interface's stamp on the bench axis, to its float seconds (~0.5 us)
            assert np.abs(dt_ns).max() <= 2_000, kind


def _thread_cpu_s(th: threading.Thread) -> float:
    """CPU time (user + system) of one thread of this process, from /proc (Linux)."""
    with open(f"/proc/self/task/{th.native_id}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_a_lost_serial_port_leaves_the_inline_loop_waiting_not_spinning():
    """The IMU's pty goes away mid-run (its master closed): the adapter says "lost" and keeps
    trying to reconnect at its own pace, and the inline loop still waits for input between
    passes: over 1 s of the outage the loop's thread uses under 0.15 s of CPU (the process used
    0.02-0.03 s, the thread 0.02 s; the loop that polled the lost port without waiting, 0.29-0.35 s)."""
    ptys, clock, node = _pty_node("test-node-lost", "inline")
    node.open()
    clock.start()
    stop = threading.Event()
    runner = threading.Thread(target=node.run, args=(stop,))
    runner.start()
    try:
        time.sleep(0.2)
        os.close(ptys["imu"][0])
        deadline = time.monotonic() + 5
        while node.imu.health.state != "lost" and time.monotonic() < deadline:
            time.sleep(0.01)
        assert node.imu.health.state == "lost"
        cpu0, wall0 = _thread_cpu_s(runner), time.monotonic()
        time.sleep(1.0)
        cpu_s, wall_s = _thread_cpu_s(runner) - cpu0, time.monotonic() - wall0
    finally:
        stop.set()
        runner.join(10)
        os.close(ptys["imu"][1])
        for m, sl in (ptys["gnss"],):
            os.close(m)
            os.close(sl)
    assert not runner.is_alive() and not node.errors
    assert cpu_s < 0.15 * wall_s


def test_a_reader_thread_told_to_stop_still_reads_what_the_port_holds(drive_recording):
    """``readers="threads"``: a reader thread held up on a busy machine lags the wire, so when the
    adapters are told to stop the IMU's pty may still hold seconds of bytes (a CI run beside a
    CPU hog received 16 KB of 56 KB). The thread reads what the port holds before it
    closes: here every byte written before the stop is received and decoded (the thread is run
    with the stop already set, so it reads nothing before it)."""
    with RecordingReader(io.BytesIO(drive_recording)) as r:
        chunks = [d for dev, _, d in r.iter_raw_serial() if dev == "imu"]
    blob = b"".join(chunks)
    ptys, clock, node = _pty_node("test-node-drain", "threads")
    try:
        node.open()
        clock.start()
        os.set_blocking(ptys["imu"][0], False)
        written = 0
        try:  # as much as the pty holds without a reader (4-20 KB here)
            while written < len(blob):
                written += os.write(ptys["imu"][0], blob[written:written + 512])
        except BlockingIOError:
            pass
        time.sleep(0.1)  # through the pty
        node._stop_adapters.set()
        node._reader(node.imu)
        node._handle_events(node.sub.drain(100_000))
    finally:
        node.can.close()
        for m, sl in ptys.values():
            os.close(m)
            os.close(sl)
    assert not node.errors
    assert written >= 3000
    assert node.received_counts()["imu_bytes"] == written
    assert node.received_counts()["samples"] >= written // 200  # an MTData2 packet is under 100 bytes
