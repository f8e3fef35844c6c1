"""``vdps recover``: kill -9 a logger in the middle of a run (devices streaming from another
process), recover its file, and find everything but at most the last ~1 s."""

import json
import os
import signal
import time

from live_devices import Rig, raw_serial, vdps

from vdps_hil.record.reader import RecordingReader


def test_kill_9_then_recover_loses_at_most_the_last_second(tmp_path):
    rig = Rig(tmp_path, seconds=2.8, flush_s=0.5)
    try:
        time.sleep(2.0)
        os.kill(rig.logger.pid, signal.SIGKILL)
        t_kill = time.monotonic()  # CLOCK_MONOTONIC is shared by the processes
        rig.logger.wait(60)
        rig.sent()
        progress = rig.progress()
    finally:
        rig.close()
    with RecordingReader(rig.out) as r:
        assert r.truncated  # no summary: the process died
    fixed = tmp_path / "fixed.mcap"
    p = vdps("recover", rig.out, "-o", fixed, "--json", tmp_path / "rec.json")
    assert p.returncode == 0, p.stderr
    rep = json.loads((tmp_path / "rec.json").read_text())
    assert not rep["properly_closed"] and rep["messages"] > 0
    with RecordingReader(fixed) as r:
        assert not r.truncated
        imu = raw_serial(r)[0]  # the raw topic: decoding may lag on a loaded machine
        can = sum(1 for _ in r.iter_raw_can())
    # what the emulator had sent one second before the kill must all be there
    before = [p for p in progress if p["t"] <= t_kill - 1.0]
    assert before, "the run was too short"
    n_imu = before[-1]["sent"]["imu"]
    n_ws = before[-1]["sent"]["wheel_speed"]
    assert imu[:n_imu] == list(range(n_imu))  # complete and in order up to then
    assert can >= 2 * n_ws  # two wheel-speed frames per ms, at least
    assert len(imu) < progress[-1]["sent"]["imu"]  # and the run really was cut
    at_kill = [p for p in progress if p["t"] <= t_kill][-1]["sent"]["imu"]
    print(f"IMU packets lost with the logger: {at_kill - len(imu)} of {at_kill} "
          f"(~{(at_kill - len(imu)) / 1000:.2f} s at 1 kHz)")


def test_recover_cli_errors(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not mcap at all")
    p = vdps("recover", junk, "-o", tmp_path / "out.mcap")
    assert p.returncode == 2 and "not an MCAP" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    p = vdps("recover", tmp_path / "missing.mcap", "-o", tmp_path / "out.mcap")
    assert p.returncode == 2 and "cannot open" in p.stderr
