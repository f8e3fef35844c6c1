"""Logger benchmark and device emulator: what rate does ``vdps log`` sustain without loss?

Two subcommands.

``emulate`` -- a simulator-like device emulator in its own process. It opens three
pseudo-terminals and acts as the devices on their far side:

* ``can``: an slcan (Lawicel) USB-CAN adapter. It answers the adapter commands python-can
  sends (``C``, ``S6``, ``O`` ... -> CR) and emits received frames as ``tIIILDD..\\r`` lines:
  the chassis frames of ``dbc/vdps.dbc`` at the sensor profile's rates (Table 1: wheel speeds
  2 x 1 kHz, torque 100 Hz, steering 100 Hz, suspension 1 Hz), each with its 8-bit counter,
  plus ``--extra-fps`` filler frames (ID 0x7E0, a 32-bit sequence number) for load tests;
* ``imu``: the Xsens MTi at ``--imu-hz`` (1 kHz), packet counter 0, 1, 2 ...;
* ``gnss``: NMEA at ``--gnss-hz`` (5 Hz): GGA + PASHR per epoch.

Writes are non-blocking like a UART: when the pty cannot take more (the reader is behind by
more than the kernel buffer plus ``--fifo`` bytes), whole messages are dropped and counted --
so lost data shows up as sequence gaps in the recording, as it would on a real link.
Symlinks ``DIR/can``, ``DIR/imu``, ``DIR/gnss`` name the devices; ``DIR/ready.json`` says they
exist; streaming starts when ``DIR/go`` appears; ``DIR/progress.jsonl`` gets a line every
100 ms (monotonic time and counts sent so far, for crash tests); ``DIR/sent.json`` the totals;
the ptys stay open until ``DIR/stop`` appears (or ``--linger`` s).

``bench`` -- runs the emulator and ``vdps log`` (two processes) at increasing CAN loads and
reports the highest load with zero loss, then the same input through python-can's own logger
(``python -m can.logger`` on the slcan pty writing ``.log``), and MCAP read throughput::

    .venv/bin/python tools/bench_logger.py bench [--seconds 5] [--loads 0,2750,7750,17750]
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

    def send(self, msg: bytes) -> bool:
        """Queue one whole message; False (dropped, counted) if the FIFO is full."""
        if len(self.pending) + len(msg) > self.fifo:
            self.pump()
            if len(self.pending) + len(msg) > self.fifo:
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
            del self.pending[:n]

    def read_commands(self) -> bytes:
        try:
            return os.read(self.master, 4096)
        except OSError:
            return b""


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
    (d / "ready.json").write_text(json.dumps({k: v.name for k, v in devs.items()}))
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

    def can_send(name, msgs):
        nonlocal frames_sent
        blob = b"".join(slcan_line(m.arbitration_id, bytes(m.data)) for m in msgs)
        if can_dev.send(blob):
            frames_sent += len(msgs)
        else:
            dropped[name] += 1

    def make(name, k):
        if name == "wheel_speed":
            return can_send(name, encode_wheel_speeds(rng.uniform(20, 30, 4), k % 256))
        if name == "wheel_torque":
            return can_send(name, [encode_wheel_torques(rng.uniform(-100, 300, 4), k % 256)])
        if name == "steer":
            return can_send(name, [encode_steer(float(rng.uniform(-1, 1)), k % 256)])
        if name == "suspension":
            return can_send(name, [encode_suspension(rng.uniform(-0.02, 0.02, 4), k % 256)])
        if name == "extra":
            if not can_dev.send(slcan_line(EXTRA_ID, k.to_bytes(4, "little") + b"\0\0\0\0")):
                dropped[name] += 1
            return None
        if name == "imu":
            pkt = encode_imu_packet(k * 1_000_000, rng.normal(0, 1, 3) + [0, 0, 9.81],
                                    rng.normal(0, 0.05, 3), k)
            if not imu_dev.send(pkt):
                dropped[name] += 1
            return None
        if name == "gnss":
            t = 43200.0 + k / max(args.gnss_hz, 1e-9)
            blob = format_gga(t, 56.1 + 1e-6 * k, 10.2, 50.0) + \
                format_attitude("PASHR", utc_time_s=t, yaw_rad=0.5, pitch_rad=0.01,
                                roll_rad=-0.02)
            if not gnss_dev.send(blob):
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
    while True:
        now = time.monotonic()
        max_gap = max(max_gap, now - last)
        last = now
        if now >= t_end:
            break
        el = now - t0
        for name, rate in streams.items():
            due = int(el * rate) + (1 if rate > 0 else 0)  # the first at t0
            while sent[name] < due:
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
              "emulator_max_stall_s": max_gap,
              "unsent_bytes": {k: len(v.pending) for k, v in devs.items()},
              "can_frames": frames_sent, "rates_hz": streams}
    (d / "sent.json").write_text(json.dumps(result))
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


def run_pair(d: Path, seconds: float, extra_fps: int, *, logger: str = "vdps",
             imu_hz: float = 1000.0, scale: float = 1.0) -> dict:
    """Emulator + logger in two processes; returns sent/received counts."""
    d.mkdir(parents=True, exist_ok=True)
    for f in ("go", "stop", "sent.json", "ready.json"):
        (d / f).unlink(missing_ok=True)
    py = sys.executable
    emu = subprocess.Popen([py, __file__, "emulate", "--dir", str(d), "--seconds", str(seconds),
                            "--extra-fps", str(extra_fps), "--imu-hz", str(imu_hz),
                            "--scale", str(scale), "--linger", "60"])
    try:
        if not _wait_for(d / "ready.json", 20):
            raise RuntimeError("emulator did not start")
        out = d / ("out.mcap" if logger == "vdps" else "out.log")
        out.unlink(missing_ok=True)
        if logger == "vdps":
            cmd = [py, "-c", VDPS_MAIN, "log",
                   "--can", f"vdps=slcan:{d / 'can'},sleep_after_open=0",
                   "--serial", f"imu={d / 'imu'}@921600", "--serial", f"gnss={d / 'gnss'}@115200",
                   "-o", str(out), "--quiet", "--json", str(d / "log.json")]
        else:  # python-can's own logger on the CAN stream only
            cmd = [py, "-m", "can.logger", "-i", "slcan", "-c", str(d / "can"), "-f", str(out),
                   "--sleep-after-open=0"]
        t_start = time.monotonic()
        lg = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        if not _wait_for(out, 30):
            lg.kill()
            raise RuntimeError(f"logger did not open its file: {lg.stderr.read().decode()[-500:]}")
        time.sleep(0.3)
        (d / "go").touch()
        if not _wait_for(d / "sent.json", seconds + 30):
            raise RuntimeError("emulator did not finish")
        time.sleep(1.0)  # let the logger drain what is in flight
        lg.send_signal(signal.SIGTERM if logger == "vdps" else signal.SIGINT)
        lg.wait(60)
        startup_s = None
        del t_start
    finally:
        (d / "stop").touch()
        try:
            emu.wait(30 if (d / "sent.json").exists() else 0.5)
        except subprocess.TimeoutExpired:
            emu.kill()
            emu.wait()
    sent = json.loads((d / "sent.json").read_text())
    return {"sent": sent, "out": str(out), "startup_s": startup_s}


def count_vdps(path: str) -> dict:
    from vdps_hil.record.reader import RecordingReader

    got = {"extra": [], "imu": 0, "gnss_att": 0, "can_frames": 0}
    per_id: dict[int, int] = {}
    with RecordingReader(path) as r:
        for _, msg in r.iter_raw_can():
            got["can_frames"] += 1
            per_id[msg.arbitration_id] = per_id.get(msg.arbitration_id, 0) + 1
            if msg.arbitration_id == EXTRA_ID:
                got["extra"].append(int.from_bytes(bytes(msg.data[:4]), "little"))
        for s in r.iter_samples():
            if s.kind == "imu":
                got["imu"] += 1
            elif s.kind == "gnss_att":
                got["gnss_att"] += 1
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
           "emulator_max_stall_s": round(sent.get("emulator_max_stall_s", 0.0), 4)}
    if with_serial:
        out["imu_missing"] = s["imu"] - got["imu"]
        out["gnss_missing"] = s["gnss"] - got["gnss_att"]
    out["lossless"] = (out["can_frames_got"] >= out["can_frames_sent"] and
                       out["extra_missing"] == 0 and out["dropped_at_device"] == 0 and
                       out.get("imu_missing", 0) == 0 and out.get("gnss_missing", 0) == 0)
    return out


def read_throughput(path: str) -> dict:
    from vdps_hil.record.reader import RecordingReader

    out = {}
    t = time.perf_counter()
    with RecordingReader(path) as r:
        n = sum(1 for _ in r.iter_records())
    out["iter_records_msgs_per_s"] = n / (time.perf_counter() - t)
    t = time.perf_counter()
    with RecordingReader(path) as r:
        n = sum(1 for _ in r.iter_raw_can())
    out["iter_raw_can_msgs_per_s"] = n / (time.perf_counter() - t)
    t = time.perf_counter()
    with RecordingReader(path) as r:
        n = sum(1 for _ in r.iter_samples())
    out["iter_samples_per_s"] = n / (time.perf_counter() - t) if n else 0.0
    out["file_mb"] = os.path.getsize(path) / 1e6
    return out


def bench(args) -> int:
    import tempfile

    loads = [int(x) for x in args.loads.split(",")]
    results = {"seconds": args.seconds, "vdps": [], "python_can": []}
    base_fps = 2 * 1000 + 100 + 100 + 1  # Table 1 chassis frames
    with tempfile.TemporaryDirectory() as tmp:
        for extra in loads:
            d = Path(tmp) / f"v{extra}"
            r = run_pair(d, args.seconds, extra)
            got = count_vdps(r["out"])
            row = {"can_fps": base_fps + extra, "imu_hz": 1000, **loss(r["sent"], got, True)}
            if extra == loads[-1] or extra == max(loads):
                row["read"] = read_throughput(r["out"])
            results["vdps"].append(row)
            print(f"vdps log  : {row['can_fps']:6d} CAN frames/s + IMU 1 kHz + GNSS 5 Hz -> "
                  f"{'lossless' if row['lossless'] else 'LOSS'} {json.dumps(row)}", flush=True)
            if args.python_can:
                d2 = Path(tmp) / f"p{extra}"
                r2 = run_pair(d2, args.seconds, extra, logger="python-can")
                got2 = count_python_can(r2["out"])
                row2 = {"can_fps": base_fps + extra, **loss(r2["sent"], got2, False)}
                results["python_can"].append(row2)
                print(f"can.logger: {row2['can_fps']:6d} CAN frames/s (CAN only, .log) -> "
                      f"{'lossless' if row2['lossless'] else 'LOSS'} {json.dumps(row2)}",
                      flush=True)
    ok = [r["can_fps"] for r in results["vdps"] if r["lossless"]]
    okp = [r["can_fps"] for r in results["python_can"] if r["lossless"]]
    results["vdps_max_lossless_can_fps"] = max(ok) if ok else 0
    results["python_can_max_lossless_can_fps"] = max(okp) if okp else None
    print(json.dumps({k: v for k, v in results.items() if k.endswith("fps")}))
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
    b.add_argument("--loads", default="0,2750,7750,17750",
                   help="extra CAN frames/s on top of Table 1's 2201 frames/s")
    b.add_argument("--no-python-can", dest="python_can", action="store_false")
    b.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    return emulate(args) if args.cmd == "emulate" else bench(args)


if __name__ == "__main__":
    sys.exit(main())
