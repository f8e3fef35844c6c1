"""Logger benchmark and device emulator: what rate does ``vdps log`` sustain without loss?

Two subcommands.

``emulate`` -- a simulator-like device emulator in its own process. It opens three
pseudo-terminals and acts as the devices on their far side:

* ``can``: an slcan (Lawicel) USB-CAN adapter. It answers the adapter commands python-can
  sends (``C``, ``S6``, ``O`` ... -> CR) and emits received frames as ``tIIILDD..\\r`` lines:
  the chassis frames of ``dbc/vdps.dbc`` at the sensor profile's rates (Table 1: wheel speeds
  2 x 1 kHz, torque 100 Hz, steering 100 Hz, suspension 1 Hz), each with its rolling counter and E2E CRC,
  plus ``--extra-fps`` filler frames (ID 0x7E0, a 32-bit sequence number) for load tests;
* ``imu``: the Xsens MTi at ``--imu-hz`` (1 kHz), packet counter 0, 1, 2 ...;
* ``gnss``: NMEA at ``--gnss-hz`` (5 Hz): GGA + PASHR per epoch.

Writes are non-blocking like a UART: when the pty cannot take more (the reader is behind by
more than the kernel buffer plus ``--fifo`` bytes), whole messages are dropped and counted --
so lost data shows up as sequence gaps in the recording, as it would on a real link.
Symlinks ``DIR/can``, ``DIR/imu``, ``DIR/gnss`` name the devices; ``DIR/ready.json`` says they
exist; streaming starts when ``DIR/go`` appears; ``DIR/progress.jsonl`` gets a line every
100 ms (monotonic time and counts sent so far, for crash tests); ``DIR/sent.json`` the totals;
the ptys stay open until ``DIR/stop`` appears (or ``--linger`` s); a ``DIR/end`` or
``DIR/stop`` that appears while streaming ends the stream early (``sent.json`` then has what was
sent); after ``DIR/end`` the ptys stay open, so a reader still running never sees its devices
vanish (a reader that reconnects by path could otherwise open a pty number the kernel has given
to another process in the meantime).

The emulator warms its encoders up before it says it is ready, and reports its own longest
stall (``emulator_max_stall_s``): on a loaded machine the emulator itself can stop for a while
and then make a burst larger than the device buffers. Messages it makes more than ``LATE_S``
after their due time are queued beyond the FIFO, not dropped, and counted
(``emulator_late_msgs``): a real device would have sent them while the emulator was not
running, so the burst is not charged to the reader; messages on time still meet the FIFO limit.

``bench`` -- runs the emulator and ``vdps log`` (two processes) at increasing CAN loads (until
the first loss, unless ``--all``) and reports the highest load with zero loss -- the headroom
-- then the same input through python-can's own logger (``python -m can.logger`` on the slcan
pty writing ``.log``), the ratio of the two, and the CPU share of ``vdps log`` (its reader
processes included, measured from /proc over the streaming window) at Table 1 rates. Lossless
means: every frame, IMU packet and GGA sentence sent is in the recording's raw topics (the
IMU packets and sentences found by decoding the raw bytes again) and none was dropped at the
device; ``imu_decoded_missing`` says how many IMU samples the logger's own decoding skipped.
``--hog`` runs a CPU-bound process on the last core meanwhile, ``--pipeline`` runs
``vdps log --pipeline``; every row gives the 1-minute load average at its start::

    .venv/bin/python tools/bench_logger.py bench [--seconds 5] [--loads 0,17750,27750,37750]
    .venv/bin/python tools/bench_logger.py bench --seconds 60 --loads 0 --hog --no-python-can
    .venv/bin/python tools/bench_logger.py emulate --dir /tmp/dev --seconds 3
"""

from __future__ import annotations

import argparse
import errno
import fcntl
import json
import os
import pty
import signal
import subprocess
import sys
import time
import tty
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

EXTRA_ID = 0x7E0
LATE_S = 0.05
"""A message the emulator makes more than this after its due time (the emulator was stalled)
is queued beyond the FIFO instead of dropped."""
VDPS_MAIN = "import sys; from vdps_hil.cli.main import entry; sys.argv[0] = 'vdps'; entry()"
"""``python -c VDPS_MAIN ARGS...`` runs the ``vdps`` command with this interpreter."""


class PtyDevice:
    """The device side of a pseudo-terminal: non-blocking writes with a small FIFO."""

    def __init__(self, link: Path, fifo: int):
        self.master, self.slave = pty.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        fl = fcntl.fcntl(self.master, fcntl.F_GETFL)
        fcntl.fcntl(self.master, fcntl.F_SETFL, fl | os.O_NONBLOCK)
        self.name = os.ttyname(self.slave)
        self.link = link
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(self.name)
        self.fifo = fifo
        self.pending = bytearray()
        self.dropped = 0
        self.bytes = 0
        self.late_bytes = 0  # late bytes still pending: they do not take FIFO room

    def send(self, msg: bytes, late: bool = False) -> bool:
        """Queue one whole message; False (dropped, counted) if the FIFO is full. A ``late``
        message (the emulator itself was stalled past its due time) is queued regardless: the
        device would have sent it while the emulator was not running, so its burst is not
        charged to the reader (nor are later messages queued behind it)."""
        if late:
            self.pending += msg
            self.late_bytes += len(msg)
            self.pump()
            return True
        if len(self.pending) - self.late_bytes + len(msg) > self.fifo:
            self.pump()
            if len(self.pending) - self.late_bytes + len(msg) > self.fifo:
                self.dropped += 1
                return False
        self.pending += msg
        return True

    def pump(self) -> None:
        while self.pending:
            try:
                n = os.write(self.master, self.pending)
            except OSError as e:
                if e.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                    return
                raise
            self.bytes += n
            self.late_bytes = max(0, self.late_bytes - n)
            del self.pending[:n]

    def read_commands(self) -> bytes:
        try:
            return os.read(self.master, 4096)
        except OSError:
            return b""


def _publish(path: Path, doc: dict) -> None:
    """Write ``doc`` as JSON so that ``path`` appears complete (others wait for it to exist)."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc))
    os.replace(tmp, path)


def emulate(args) -> int:
    import numpy as np

    from vdps_hil.adapters.can_adapter import slcan_line
    from vdps_hil.codecs.can_encode import (
        encode_steer, encode_suspension, encode_wheel_speeds, encode_wheel_torques,
    )
    from vdps_hil.codecs.imu_mtdata2 import encode_imu_packet
    from vdps_hil.codecs.nmea.attitude import format_attitude
    from vdps_hil.codecs.nmea.position import format_gga

    d = Path(args.dir)
    d.mkdir(parents=True, exist_ok=True)
    # first calls load the DBC (about 1 s): warm up before the logger is told to start
    encode_wheel_speeds([20.0] * 4, 0)
    encode_imu_packet(0, [0.0, 0.0, 9.81], [0.0] * 3, 0)
    devs = {"can": PtyDevice(d / "can", args.fifo), "imu": PtyDevice(d / "imu", args.fifo),
            "gnss": PtyDevice(d / "gnss", args.fifo)}
    _publish(d / "ready.json", {k: v.name for k, v in devs.items()})
    rng = np.random.default_rng(args.seed)
    can_dev, imu_dev, gnss_dev = devs["can"], devs["imu"], devs["gnss"]
    streams = {  # name -> rate [Hz]
        "wheel_speed": 1000.0 * args.scale, "wheel_torque": 100.0 * args.scale,
        "steer": 100.0 * args.scale, "suspension": 1.0 * args.scale,
        "extra": float(args.extra_fps), "imu": float(args.imu_hz),
        "gnss": float(args.gnss_hz)}
    sent = {k: 0 for k in streams}
    dropped = {k: 0 for k in streams}
    frames_sent = 0

    late = False  # the message being made is overdue by more than LATE_S (emulator stalled)

    def can_send(name, msgs):
        nonlocal frames_sent
        blob = b"".join(slcan_line(m.arbitration_id, bytes(m.data)) for m in msgs)
        if can_dev.send(blob, late):
            frames_sent += len(msgs)
        else:
            dropped[name] += 1

    def make(name, k):
        if name == "wheel_speed":
            return can_send(name, encode_wheel_speeds(rng.uniform(20, 30, 4), k % 256))
        if name == "wheel_torque":
            return can_send(name, encode_wheel_torques(rng.uniform(-100, 300, 4), k % 256))
        if name == "steer":
            return can_send(name, [encode_steer(float(rng.uniform(-1, 1)), k % 256)])
        if name == "suspension":
            return can_send(name, [encode_suspension(rng.uniform(-0.02, 0.02, 4), k % 256)])
        if name == "extra":
            if not can_dev.send(slcan_line(EXTRA_ID, k.to_bytes(4, "little") + b"\0\0\0\0"),
                                late):
                dropped[name] += 1
            return None
        if name == "imu":
            pkt = encode_imu_packet(k * 1_000_000, rng.normal(0, 1, 3) + [0, 0, 9.81],
                                    rng.normal(0, 0.05, 3), k)
            if not imu_dev.send(pkt, late):
                dropped[name] += 1
            return None
        if name == "gnss":
            t = 43200.0 + k / max(args.gnss_hz, 1e-9)
            blob = format_gga(t, 56.1 + 1e-6 * k, 10.2, 50.0) + \
                format_attitude("PASHR", utc_time_s=t, yaw_rad=0.5, pitch_rad=0.01,
                                roll_rad=-0.02)
            if not gnss_dev.send(blob, late):
                dropped[name] += 1
            return None
        raise KeyError(name)

    t_wait = time.monotonic() + args.wait
    while not (d / "go").exists():  # answer the adapter's commands while waiting
        if can_dev.read_commands():
            can_dev.send(b"\r")
            can_dev.pump()
        if time.monotonic() > t_wait:
            print("emulator: no go", file=sys.stderr)
            return 3
        time.sleep(0.01)
    t0 = time.monotonic()
    t_end = t0 + args.seconds
    next_progress = t0
    prog = open(d / "progress.jsonl", "w")
    last = t0
    max_gap = 0.0  # the emulator's own longest stall (a loaded machine): bursts follow it
    late_msgs = 0
    while True:
        now = time.monotonic()
        max_gap = max(max_gap, now - last)
        last = now
        el = min(now, t_end) - t0  # stalled past the end: the messages due until then, late
        for name, rate in streams.items():
            due = min(int(el * rate) + (1 if rate > 0 else 0), int(args.seconds * rate))  # the first at t0
            while sent[name] < due:
                late = now - t0 - sent[name] / rate > LATE_S
                late_msgs += late
                make(name, sent[name])
                sent[name] += 1
        for dev in devs.values():
            dev.pump()
        if can_dev.read_commands():
            can_dev.send(b"\r")
        if now >= next_progress:
            prog.write(json.dumps({"t": now, "sent": sent, "dropped": dropped}) + "\n")
            prog.flush()
            next_progress += 0.1
            if (d / "stop").exists() or (d / "end").exists():  # ended early by the caller (10 Hz)
                break
        if now >= t_end:
            break
        time.sleep(0.0005)
    t_stop = time.monotonic()
    t_flush = t_stop + 2.0
    while any(dev.pending for dev in devs.values()) and time.monotonic() < t_flush:
        for dev in devs.values():
            dev.pump()
        time.sleep(0.001)
    prog.write(json.dumps({"t": time.monotonic(), "sent": sent, "dropped": dropped}) + "\n")
    prog.close()
    result = {"seconds": t_stop - t0, "sent": sent, "dropped_at_device": dropped,
              "emulator_max_stall_s": max_gap, "emulator_late_msgs": late_msgs,
              "unsent_bytes": {k: len(v.pending) for k, v in devs.items()},
              "can_frames": frames_sent, "rates_hz": streams}
    _publish(d / "sent.json", result)
    t_linger = time.monotonic() + args.linger
    while not (d / "stop").exists() and time.monotonic() < t_linger:
        can_dev.read_commands()
        time.sleep(0.02)
    return 0


# --- bench ----------------------------------------------------------------------------------

def _wait_for(path: Path, timeout: float) -> bool:
    t_end = time.monotonic() + timeout
    while not path.exists():
        if time.monotonic() > t_end:
            return False
        time.sleep(0.02)
    return True


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system) used so far by ``pid`` and all its descendants (the
    logger and its reader processes), from /proc; 0.0 for a process that is gone."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    todo = [pid]
    while todo:
        p = todo.pop()
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split()]
        except (OSError, IndexError, ValueError):
            continue
    return total


def start_hog() -> subprocess.Popen:
    """A CPU-bound process (``python3 -c 'while 1: pass'``) on the last core."""
    hog = subprocess.Popen([sys.executable, "-c", "while 1: pass"])
    try:
        os.sched_setaffinity(hog.pid, {max(os.sched_getaffinity(0))})
    except OSError:
        pass
    return hog


def run_pair(d: Path, seconds: float, extra_fps: int, *, logger: str = "vdps",
             imu_hz: float = 1000.0, scale: float = 1.0, pipeline: bool = False) -> dict:
    """Emulator + logger in two processes; returns the emulator's counts, the output file, and
    the logger's CPU seconds over the streaming window (between ``go`` and the emulator's
    end) with that window's length."""
    d.mkdir(parents=True, exist_ok=True)
    for f in ("go", "end", "stop", "sent.json", "ready.json"):
        (d / f).unlink(missing_ok=True)
    py = sys.executable
    emu = subprocess.Popen([py, __file__, "emulate", "--dir", str(d), "--seconds", str(seconds),
                            "--extra-fps", str(extra_fps), "--imu-hz", str(imu_hz),
                            "--scale", str(scale), "--linger", "60"])
    lg = None
    try:
        if not _wait_for(d / "ready.json", 30):
            raise RuntimeError("emulator did not start")
        out = d / ("out.mcap" if logger == "vdps" else "out.log")
        out.unlink(missing_ok=True)
        if logger == "vdps":
            cmd = [py, "-c", VDPS_MAIN, "log",
                   "--can", f"vdps=slcan:{d / 'can'},sleep_after_open=0",
                   "--serial", f"imu={d / 'imu'}@921600", "--serial", f"gnss={d / 'gnss'}@115200",
                   "-o", str(out), "--quiet", "--json", str(d / "log.json")]
            if pipeline:
                cmd.append("--pipeline")
        else:  # python-can's own logger on the CAN stream only
            cmd = [py, "-m", "can.logger", "-i", "slcan", "-c", str(d / "can"), "-f", str(out),
                   "--sleep-after-open=0"]
        lg = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        if not _wait_for(out, 60):
            lg.kill()
            raise RuntimeError(f"logger did not open its file: {lg.stderr.read().decode()[-500:]}")
        time.sleep(0.5)
        cpu0, t0 = _cpu_s(lg.pid), time.monotonic()
        (d / "go").touch()
        if not _wait_for(d / "sent.json", seconds + 30):
            raise RuntimeError("emulator did not finish")
        cpu1, t1 = _cpu_s(lg.pid), time.monotonic()
        time.sleep(1.0)  # let the logger drain what is in flight
        lg.send_signal(signal.SIGTERM if logger == "vdps" else signal.SIGINT)
        err = lg.communicate(timeout=120)[1].decode(errors="replace")
        if lg.returncode not in (0, -signal.SIGINT, 130, 1) and logger == "vdps":
            raise RuntimeError(f"logger failed ({lg.returncode}): {err[-500:]}")
    finally:
        if lg is not None and lg.poll() is None:  # the logger before its devices (module docstring)
            lg.kill()
            lg.wait()
        (d / "stop").touch()
        try:
            emu.wait(30 if (d / "sent.json").exists() else 0.5)
        except subprocess.TimeoutExpired:
            emu.kill()
            emu.wait()
    sent = json.loads((d / "sent.json").read_text())
    return {"sent": sent, "out": str(out), "cpu_s": cpu1 - cpu0, "wall_s": t1 - t0}


def count_vdps(path: str) -> dict:
    """What the recording holds: CAN frames (filler sequence numbers), IMU packets and GGA
    sentences found in the raw bytes (decoded again here: the raw topics are the recording),
    and the decoded IMU samples ``vdps log`` wrote itself."""
    from vdps_hil.codecs.imu_decoder import ImuDecoder
    from vdps_hil.record.reader import RecordingReader

    got = {"extra": [], "imu": 0, "gnss_att": 0, "can_frames": 0, "imu_decoded": 0}
    per_id: dict[int, int] = {}
    with RecordingReader(path) as r:
        for _, msg in r.iter_raw_can():
            got["can_frames"] += 1
            per_id[msg.arbitration_id] = per_id.get(msg.arbitration_id, 0) + 1
            if msg.arbitration_id == EXTRA_ID:
                got["extra"].append(int.from_bytes(bytes(msg.data[:4]), "little"))
        serial = {"imu": bytearray(), "gnss": bytearray()}
        for dev, _, data in r.iter_raw_serial():
            if dev in serial:
                serial[dev] += data
        topics = r.topics()
        got["imu_decoded"] = topics["/decoded/imu/imu"].count if "/decoded/imu/imu" in topics else 0
    dec = ImuDecoder("imu")
    got["imu"] = len(dec.feed(0, bytes(serial["imu"])) + dec.flush())
    got["imu_seq_gaps"] = dec.counters["seq_gaps"]
    got["gnss_att"] = bytes(serial["gnss"]).count(b"GGA,")
    got["per_id"] = per_id
    return got


def count_python_can(path: str) -> dict:
    import can

    got = {"extra": [], "can_frames": 0}
    for msg in can.LogReader(path):
        got["can_frames"] += 1
        if msg.arbitration_id == EXTRA_ID:
            got["extra"].append(int.from_bytes(bytes(msg.data[:4]), "little"))
    return got


CAN_STREAMS = ("wheel_speed", "wheel_torque", "steer", "suspension", "extra")


def loss(sent: dict, got: dict, with_serial: bool) -> dict:
    """Loss of one run. Device-side drops (the reader was too slow to empty the pty) count as
    loss of the logger; python-can's logger reads only CAN, so only CAN drops count for it."""
    s = sent["sent"]
    dev = sent["dropped_at_device"]
    streams = [*CAN_STREAMS, "imu", "gnss"] if with_serial else list(CAN_STREAMS)
    extra = got["extra"]
    out = {"can_frames_sent": sent["can_frames"] + s["extra"] - dev["extra"],
           "can_frames_got": got["can_frames"],
           "extra_missing": s["extra"] - len(set(extra)),
           "dropped_at_device": sum(dev[k] for k in streams),
           "emulator_max_stall_s": round(sent.get("emulator_max_stall_s", 0.0), 4),
           "emulator_late_msgs": sent.get("emulator_late_msgs", 0)}
    if with_serial:
        out["imu_missing"] = s["imu"] - got["imu"]
        out["gnss_missing"] = s["gnss"] - got["gnss_att"]
        out["imu_decoded_missing"] = s["imu"] - got["imu_decoded"]
    out["lossless"] = (out["can_frames_got"] >= out["can_frames_sent"] and
                       out["extra_missing"] == 0 and out["dropped_at_device"] == 0 and
                       out.get("imu_missing", 0) == 0 and out.get("gnss_missing", 0) == 0)
    return out


BASE_FPS = 2 * 1000 + 100 + 100 + 1
"""Table 1 chassis frames per second (two wheel-speed frames at 1 kHz, torque, steering,
suspension)."""


def _row(kind: str, d: Path, seconds: float, extra: int, pipeline: bool) -> dict:
    load = os.getloadavg()[0]
    r = run_pair(d, seconds, extra, logger=kind, pipeline=pipeline)
    if kind == "vdps":
        row = {"can_fps": BASE_FPS + extra, "imu_hz": 1000, **loss(r["sent"], count_vdps(r["out"]), True)}
    else:
        row = {"can_fps": BASE_FPS + extra, **loss(r["sent"], count_python_can(r["out"]), False)}
    row["cpu_share"] = round(r["cpu_s"] / r["wall_s"], 3) if r["wall_s"] > 0 else None
    row["load_avg_1min"] = round(load, 2)
    return row


def _print(kind: str, row: dict) -> None:
    what = "+ IMU 1 kHz + GNSS 5 Hz" if kind == "vdps" else "(CAN only, .log)"
    tag = "vdps log  " if kind == "vdps" else "can.logger"
    print(f"{tag}: {row['can_fps']:6d} CAN frames/s {what} -> "
          f"{'lossless' if row['lossless'] else 'LOSS'}, CPU {100 * (row['cpu_share'] or 0):.0f} % "
          f"of a core, load {row['load_avg_1min']}  {json.dumps(row)}", flush=True)


def bench(args) -> int:
    """Rows of increasing load for ``vdps log`` (stopping after the first loss unless
    ``--all``) and for python-can's ``can.logger``; the highest lossless load of each, their
    ratio, and the CPU share at Table 1 rates (the first vdps row of load 0)."""
    import tempfile

    loads = [int(x) for x in args.loads.split(",")]
    pc_loads = [int(x) for x in args.python_can_loads.split(",")]
    results = {"seconds": args.seconds, "hog": args.hog, "pipeline": args.pipeline,
               "cpus": os.cpu_count(), "vdps": [], "python_can": []}
    hog = start_hog() if args.hog else None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for extra in loads:
                row = _row("vdps", Path(tmp) / f"v{extra}", args.seconds, extra, args.pipeline)
                results["vdps"].append(row)
                _print("vdps", row)
                if not row["lossless"] and not args.all:
                    break
            for extra in (pc_loads if args.python_can else []):
                row = _row("python-can", Path(tmp) / f"p{extra}", args.seconds, extra, False)
                results["python_can"].append(row)
                _print("python-can", row)
                if not row["lossless"] and not args.all:
                    break
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
    ok = [r["can_fps"] for r in results["vdps"] if r["lossless"]]
    okp = [r["can_fps"] for r in results["python_can"] if r["lossless"]]
    results["vdps_max_lossless_can_fps"] = max(ok) if ok else 0
    results["python_can_max_lossless_can_fps"] = max(okp) if okp else None
    if ok and okp:
        results["ratio_to_python_can"] = round(max(ok) / max(okp), 2)
    t1 = [r for r in results["vdps"] if r["can_fps"] == BASE_FPS]
    results["cpu_share_at_table1"] = t1[0]["cpu_share"] if t1 else None
    print(json.dumps({k: v for k, v in results.items() if not isinstance(v, list)}))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("emulate", help="run the device emulator")
    e.add_argument("--dir", required=True)
    e.add_argument("--seconds", type=float, default=3.0)
    e.add_argument("--extra-fps", type=int, default=0)
    e.add_argument("--imu-hz", type=float, default=1000.0)
    e.add_argument("--gnss-hz", type=float, default=5.0)
    e.add_argument("--scale", type=float, default=1.0, help="multiply the chassis CAN rates")
    e.add_argument("--fifo", type=int, default=4096, help="device FIFO bytes beyond the pty")
    e.add_argument("--wait", type=float, default=60.0, help="seconds to wait for DIR/go")
    e.add_argument("--linger", type=float, default=30.0)
    e.add_argument("--seed", type=int, default=0)
    b = sub.add_parser("bench", help="find the highest lossless rate")
    b.add_argument("--seconds", type=float, default=5.0)
    b.add_argument("--loads", default="0,17750,27750,37750,57750",
                   help="extra CAN frames/s on top of Table 1's 2201 frames/s (vdps log)")
    b.add_argument("--python-can-loads", default="0,800,1800,2800,4800,7800",
                   help="the same for python-can's can.logger")
    b.add_argument("--all", action="store_true", help="go on after the first lossy load")
    b.add_argument("--hog", action="store_true",
                   help="a CPU-bound process (python3 -c 'while 1: pass') on the last core")
    b.add_argument("--pipeline", action="store_true", help="vdps log --pipeline")
    b.add_argument("--no-python-can", dest="python_can", action="store_false")
    b.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    return emulate(args) if args.cmd == "emulate" else bench(args)


if __name__ == "__main__":
    sys.exit(main())
