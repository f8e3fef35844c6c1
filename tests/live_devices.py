"""Helpers for the cross-process logger tests: the device emulator of tools/bench_logger.py
(slcan CAN adapter, MTi IMU and NMEA receiver on pseudo-terminals) in one process, ``vdps log``
in another."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TOOL = REPO / "tools" / "bench_logger.py"
VDPS = "import sys; from vdps_hil.cli.main import entry; sys.argv[0] = 'vdps'; entry()"


def wait_for(path: Path, timeout: float) -> bool:
    t_end = time.monotonic() + timeout
    while not path.exists():
        if time.monotonic() > t_end:
            return False
        time.sleep(0.02)
    return True


def vdps(*args, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", VDPS, *map(str, args)], capture_output=True,
                          text=True, timeout=120, **kw)


class Rig:
    """Emulator + logger. ``start()`` returns when both run and the stream has begun."""

    def __init__(self, d: Path, seconds: float, *, extra_fps: int = 0, flush_s: float = 0.5,
                 logger_args: tuple = ()):
        self.d = d
        self.seconds = seconds
        self.out = d / "out.mcap"
        self.emu = subprocess.Popen([sys.executable, str(TOOL), "emulate", "--dir", str(d),
                                     "--seconds", str(seconds), "--extra-fps", str(extra_fps),
                                     "--linger", "60", "--wait", "240"])
        # start-up is not real-time: on a loaded machine imports alone can take a minute
        if not wait_for(d / "ready.json", 180):
            self.emu.kill()
            self.emu.wait()
            raise AssertionError("emulator did not start")
        self.logger = subprocess.Popen(
            [sys.executable, "-c", VDPS, "log",
             "--can", f"vdps=slcan:{d / 'can'},sleep_after_open=0",
             "--serial", f"imu={d / 'imu'}@921600", "--serial", f"gnss={d / 'gnss'}@115200",
             "-o", str(self.out), "--flush-s", str(flush_s), "--quiet",
             "--json", str(d / "log.json"), *map(str, logger_args)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        rotating = any(str(a).startswith("--rotate") for a in logger_args)
        if not wait_for(d / "out_0000.mcap" if rotating else self.out, 180):
            self.logger.kill()
            self.close()
            raise AssertionError(f"logger did not start: {self.logger.stderr.read()[-800:]}")
        time.sleep(0.3)
        (d / "go").touch()

    def sent(self, timeout: float = 60) -> dict:
        assert wait_for(self.d / "sent.json", timeout), "emulator did not finish"
        return json.loads((self.d / "sent.json").read_text())

    def end_stream(self, timeout: float = 60) -> dict:
        """End the emulator's stream now (``DIR/end``, tools/bench_logger.py: the ptys stay open
        until :meth:`close`) and return what it sent (``sent``)."""
        (self.d / "end").touch()
        return self.sent(timeout)

    def progress(self) -> list[dict]:
        return [json.loads(ln) for ln in (self.d / "progress.jsonl").read_text().splitlines()]

    def close(self) -> None:
        """The logger first, then the devices: a logger that outlived its ptys would reconnect
        by path, and the kernel may meanwhile have given a pty of that number to another test's
        emulator (its own logger then could not lock the port: seen once in a fresh-clone run)."""
        if self.logger.poll() is None:
            self.logger.kill()
            self.logger.wait()
        (self.d / "stop").touch()
        try:
            self.emu.wait(30)
        except subprocess.TimeoutExpired:
            self.emu.kill()
            self.emu.wait()


def raw_serial(reader) -> tuple[list[int], int]:
    """The IMU packet counters and the number of GGA sentences in a recording's raw serial
    topics (``imu``, ``gnss``), decoded again here: the raw topics are the recording."""
    from vdps_hil.codecs.imu_decoder import ImuDecoder

    raw = {"imu": bytearray(), "gnss": bytearray()}
    for dev, _, data in reader.iter_raw_serial():
        raw.setdefault(dev, bytearray()).extend(data)
    dec = ImuDecoder("imu")
    seq = [int(smp.fields["seq_counter"]) for smp in dec.feed(0, bytes(raw["imu"])) + dec.flush()]
    return seq, bytes(raw["gnss"]).count(b"GGA,")
