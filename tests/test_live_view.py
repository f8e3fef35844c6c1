"""Tests of vdps_hil.app.live_view (``--serve``): a real WebSocket client (the ``websockets``
package, Foxglove's protocol) connects to the foxglove-sdk server, sees the advertised channels
with the recording's JSON schemas, subscribes and receives the messages as written, with their
log times; nothing listens on another address than 127.0.0.1; ``vdps replay --serve 0`` waits for
a subscriber and serves the same /est/ bytes its -o output holds."""

from __future__ import annotations

import json
import re
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from websockets.sync.client import connect

from vdps_hil.app.live_view import LAYOUT_TOPICS, LiveServer, LiveServerError, TeeWriter
from vdps_hil.bus.samples import Sample
from vdps_hil.record import schemas as S
from vdps_hil.record.writer import RecordingWriter
from vdps_hil.sim.drive import Drive

PROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def _advertised(ws, wanted: set[str], timeout_s: float = 5.0) -> dict[str, dict]:
    chans: dict[str, dict] = {}
    while not wanted <= set(chans):
        m = json.loads(ws.recv(timeout=timeout_s))
        if m["op"] == "advertise":
            chans.update({c["topic"]: c for c in m["channels"]})
    return chans


def _subscribe(ws, chans: dict[str, dict], topics) -> dict[int, str]:
    subs = {i: t for i, t in enumerate(topics, 1)}
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": chans[t]["id"]}
                                                              for i, t in subs.items()]}))
    return subs


def _message(frame: bytes) -> tuple[int, int, bytes]:
    """(subscription id, log time, payload) of a binary messageData frame (opcode 1)."""
    op, sub, log_time = struct.unpack_from("<BIQ", frame)
    assert op == 1
    return sub, log_time, frame[13:]


def _collect(ws, subs: dict[int, str], got: dict[str, list], at_least: int, timeout_s: float) -> None:
    """Parsed messages into ``got[topic]`` until every topic there has ``at_least``."""
    while min(len(v) for v in got.values()) < at_least:
        frame = ws.recv(timeout=timeout_s)
        if isinstance(frame, bytes):
            sub, _, payload = _message(frame)
            got[subs[sub]].append(json.loads(payload))


def _listening_addresses(port: int) -> list[str]:
    """Local addresses of the listening TCP sockets on ``port`` (/proc/net/tcp, tcp6)."""
    out = []
    for name in ("tcp", "tcp6"):
        p = Path("/proc/net") / name
        if not p.exists():
            continue
        for line in p.read_text().splitlines()[1:]:
            f = line.split()
            addr, hexport = f[1].rsplit(":", 1)
            if int(hexport, 16) == port and f[3] == "0A":  # TCP_LISTEN
                out.append(addr)
    return out


def test_binds_only_127_0_0_1():
    with LiveServer(0) as live:
        addrs = _listening_addresses(live.port)
        assert addrs == ["0100007F"], addrs  # 127.0.0.1, little-endian hex; no 0.0.0.0, no ::
        others = {ai[4][0] for ai in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)} - {"127.0.0.1"}
        for host in others:
            if host.startswith("127."):
                continue
            with pytest.raises(OSError):
                socket.create_connection((host, live.port), timeout=2).close()
        with pytest.raises(LiveServerError, match="cannot listen"):
            LiveServer(live.port)  # the port is taken: one line


def test_a_client_subscribes_and_receives_what_is_written(tmp_path):
    epoch = S.DEFAULT_SIM_EPOCH_NS
    with LiveServer(0, epoch_ns=epoch) as live:
        live.advertise(LAYOUT_TOPICS)
        with connect(live.url, subprotocols=PROTOCOLS) as ws:
            chans = _advertised(ws, set(LAYOUT_TOPICS))
            for topic, schema_name in LAYOUT_TOPICS.items():
                c = chans[topic]
                assert (c["schemaName"], c["encoding"], c["schemaEncoding"]) == (schema_name, "json", "jsonschema")
                assert json.loads(c["schema"]) == S.SCHEMAS[schema_name]
            subs = _subscribe(ws, chans, ["/est/state", S.GNSS_FIX_TOPIC])
            assert live.wait_for_subscriber(5.0)
            gnss = Sample(2_000, "gnss", "gnss_pos", {"gnss_lat_deg": 24.78, "gnss_lon_deg": 121.0}, 0, True)
            fix = S.location_fix_doc(gnss, stamp_ns=epoch + 2_000)
            with RecordingWriter(tmp_path / "r.mcap", sim_epoch_ns=epoch) as w:
                tee = TeeWriter(w, live)
                tee.write_estimate("/est/state", 1_000, {"x_g_m": 1.5, "phi_v_rad": 0.01}, {"x_g_m": 0.1})
                tee.write_json(S.GNSS_FIX_TOPIC, S.LOCATION_FIX, 2_000, fix)
            got = [_message(ws.recv(timeout=5.0)) for _ in range(2)]
            assert tee.refused == 0
    with open(tmp_path / "r.mcap", "rb") as f:
        recorded = {c.topic: (m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()}
    for sub, log_time, payload in got:
        assert (log_time, payload) == recorded[subs[sub]]  # the recording's bytes and log time
    assert json.loads(got[0][2])["values"] == {"x_g_m": 1.5, "phi_v_rad": 0.01}


def test_vdps_replay_serve_waits_and_serves_the_output_s_messages(tmp_path):
    drive, out = tmp_path / "paper.mcap", tmp_path / "out.mcap"
    Drive("paper", seed=5, duration_s=2.0).run(drive)
    vdps = Path(sys.executable).with_name("vdps")
    proc = subprocess.Popen([str(vdps), "replay", str(drive), "-o", str(out), "--serve", "0", "-q"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()
        m = re.search(r"serving on (ws://127\.0\.0\.1:(\d+))", line)
        assert m, line
        assert "waiting for a client" in line
        topics = ["/est/state", S.EST_FIX_TOPIC, S.EST_TF_TOPIC]
        got: list[tuple[str, int, bytes]] = []
        with connect(m.group(1), subprotocols=PROTOCOLS) as ws:
            chans = _advertised(ws, set(topics))
            assert proc.poll() is None  # nothing replayed before a subscriber
            subs = _subscribe(ws, chans, topics)
            while True:
                try:
                    frame = ws.recv(timeout=120)
                except Exception:  # the server stopped at the end of the replay
                    break
                if isinstance(frame, bytes):
                    sub, log_time, payload = _message(frame)
                    got.append((subs[sub], log_time, payload))
        assert proc.wait(timeout=120) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    recorded: dict[str, set] = {t: set() for t in topics}
    with open(out, "rb") as f:
        for _, c, msg in make_reader(f).iter_messages(topics=topics):
            recorded[c.topic].add((msg.log_time, bytes(msg.data)))
    for t in topics:
        served = [(lt, p) for tt, lt, p in got if tt == t]
        assert served, t
        assert set(served) <= recorded[t], t  # the same bytes and log times as the -o output
        assert len(served) >= 0.5 * len(recorded[t])  # a slow client may drop some; most arrive


def _collect_until(ws, sub_id: int, got: list, at_least: int, deadline: float) -> None:
    """Parsed messages of subscription ``sub_id`` into ``got`` until it has ``at_least`` or the
    monotonic ``deadline`` passes (text frames, e.g. later advertisements, are skipped)."""
    while len(got) < at_least:
        left = deadline - time.monotonic()
        if left <= 0:
            return
        try:
            frame = ws.recv(timeout=left)
        except TimeoutError:
            return
        if isinstance(frame, bytes):
            sub, _, payload = _message(frame)
            if sub == sub_id:
                got.append(json.loads(payload))


def _summary(path: Path) -> str:
    """The logger's --json summary for a failure message (its loss and health counters say
    whether it read, decoded and wrote the two devices), or why it cannot be read."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        return f"no summary ({e})"
    doc.pop("files", None)
    return json.dumps(doc)[:4000]


def test_vdps_log_serve_streams_the_decoded_topics_and_gnss_fix(tmp_path):
    """``vdps log --serve 0`` on an emulated slcan bus and two pseudo-terminals (tests/live_devices.py):
    a client subscribed to /gnss/fix and one subscribed to the decoded IMU receive them while the
    logger runs; the /raw/ topics are not served. One client per topic: the server keeps a
    bounded backlog per client and drops its oldest messages when a client reads slowly, so on a
    loaded machine the 1 kHz IMU would crowd the 5 Hz fixes out of a shared client."""
    import signal

    from live_devices import Rig

    # up to 120 s of data, ended as soon as the clients have their messages: a client that
    # subscribes late on a loaded machine still sees the stream running (with 4 s, and once
    # with 8 s beside the full suite, it subscribed after the emulator had finished)
    rig = Rig(tmp_path, seconds=120.0, logger_args=("--serve", "0"))
    try:
        url = None
        while url is None:
            line = rig.logger.stderr.readline()
            assert line, "logger ended before serving"
            m = re.search(r"serving on (ws://127\.0\.0\.1:\d+)", line)
            url = m and m.group(1)
        imu = "/decoded/imu/imu"
        got: dict[str, list] = {S.GNSS_FIX_TOPIC: [], imu: []}
        # close_timeout: a client that stopped reading a 1 kHz stream has the server's close frame
        # queued behind data it will not read; its close would wait the default 10 s
        with connect(url, subprotocols=PROTOCOLS, close_timeout=2) as ws_fix, \
                connect(url, subprotocols=PROTOCOLS, close_timeout=2) as ws_imu:
            chans = _advertised(ws_fix, {S.GNSS_FIX_TOPIC, imu}, timeout_s=60)
            assert not any(t.startswith(S.RAW_PREFIX) for t in chans)
            _advertised(ws_imu, {imu}, timeout_s=60)  # the same server: the same channel ids
            _subscribe(ws_fix, chans, [S.GNSS_FIX_TOPIC])
            _subscribe(ws_imu, chans, [imu])
            deadline = time.monotonic() + 90.0  # the stream runs 120 s from the logger's start
            _collect_until(ws_imu, 1, got[imu], 5, deadline)
            _collect_until(ws_fix, 1, got[S.GNSS_FIX_TOPIC], 5, deadline)
            sent = rig.end_stream()  # before the clients close: a close under a 1 kHz stream waits
        if min(map(len, got.values())) < 5:
            rig.logger.send_signal(signal.SIGTERM)
            rig.logger.wait(60)
            pytest.fail(f"served {[(t, len(v)) for t, v in got.items()]} of 5 each; emulator sent "
                        f"{sent}; logger: {_summary(tmp_path / 'log.json')}")
        assert all(S.validate(d, S.SCHEMAS[S.LOCATION_FIX]) == [] for d in got[S.GNSS_FIX_TOPIC])
        assert all("specific_force_mps2_z" in d["fields"] for d in got[imu])
        assert sent["seconds"] < 120.0  # ended by end_stream, not by running out
        rig.logger.send_signal(signal.SIGTERM)
        assert rig.logger.wait(30) == 0
    finally:
        if rig.logger.poll() is None:
            rig.logger.kill()
        rig.close()


def test_vdps_bench_serve_streams_the_estimates(tmp_path):
    """``vdps bench -o FILE --serve 0`` (virtual CAN, the default with --serve; pipeline in this
    process; no headroom check: what is tested is the stream, at any headroom): a client
    subscribed to /est/state and /est/tf receives the live estimates; --serve without -o is a
    one-line error."""
    vdps = Path(sys.executable).with_name("vdps")
    bad = subprocess.run([str(vdps), "bench", "--serve", "0", "--duration", "1"], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "-o" in bad.stderr
    proc = subprocess.Popen([str(vdps), "bench", "--duration", "4", "-o", str(tmp_path / "b.mcap"), "--serve", "0",
                             "--no-headroom-check", "--quiet"], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        m = re.search(r"serving on (ws://127\.0\.0\.1:\d+)", proc.stderr.readline())
        assert m
        topics = ["/est/state", S.EST_TF_TOPIC]
        got: dict[str, list] = {t: [] for t in topics}
        with connect(m.group(1), subprotocols=PROTOCOLS) as ws:
            subs = _subscribe(ws, _advertised(ws, set(topics), timeout_s=30), topics)
            _collect(ws, subs, got, 5, 60)
        assert all(S.validate(d, S.SCHEMAS[S.FRAME_TRANSFORM]) == [] for d in got[S.EST_TF_TOPIC])
        assert all("phi_v_rad" in d["values"] for d in got["/est/state"])
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
