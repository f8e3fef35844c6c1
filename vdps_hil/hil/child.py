"""The bench's pipeline as a separate process (``--can pty`` / ``--can tcp``).

``python -m vdps_hil.hil.child --can-spec SPEC --imu-port PTY --gnss-port PTY --model FILE
--susp-rate-hz F --susp-sigma-m S --speed X --work DIR [--output PART.mcap]``

Protocol with the parent (``hil.bench``), one JSON document per stdout line:
``{"ready": true}`` once the adapters are open (or ``{"error": "..."}`` and exit status 2);
then the parent writes ``go <m0>`` (the bench clock's start instant, CLOCK_MONOTONIC ns, shared
by the processes of a host) on stdin; ``{"received": {...}}`` about every 0.1 s; on ``stop`` the
node handles what is queued, writes ``DIR/cycles.npz`` (the output-cycle log) and
``DIR/result.json`` (counters, outputs, frames sent), closes its recording part and prints
``{"done": true}``.

The child reads no truth and never imports ``vdps_hil.sim``: it has the model vehicle file, the
suspension sensor's rate and noise (a data sheet), the wires and the clock.
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import sys
import threading
from pathlib import Path

import numpy as np


def _say(doc: dict) -> None:
    sys.stdout.write(json.dumps(doc) + "\n")
    sys.stdout.flush()


def _parse(argv) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m vdps_hil.hil.child")
    for name in ("--can-spec", "--imu-port", "--gnss-port", "--model", "--work"):
        ap.add_argument(name, required=True)
    for name in ("--susp-rate-hz", "--susp-sigma-m", "--speed"):
        ap.add_argument(name, type=float, required=True)
    ap.add_argument("--output", default=None)
    ap.add_argument("--params", default=None)
    ap.add_argument("--switch-interval", type=float, default=None)
    ap.add_argument("--readers", choices=("inline", "threads"), default="inline")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    a = _parse(argv)
    # python-can's socketcand client logs every TCP read that splits a frame ("Got incomplete
    # message"): normal on a stream, not an error; keep real errors only
    logging.getLogger("can").setLevel(logging.ERROR)
    if a.switch_interval:
        sys.setswitchinterval(a.switch_interval)

    from vdps_hil.adapters.base import AdapterError
    from vdps_hil.record import schemas as S
    from vdps_hil.record.writer import RecordingWriter

    from .bench_config import make_system, warm_pipeline_kernels
    from .node import PipelineNode
    from .pacing import BenchClock

    work = Path(a.work)
    clock = BenchClock(a.speed)
    writer = None
    try:
        system = make_system(a.model, a.susp_rate_hz, a.susp_sigma_m, a.params, live=True)
        if a.output:
            writer = RecordingWriter(a.output, metadata={"source": "vdps bench (pipeline process)"},
                                     sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
        node = PipelineNode(system, a.can_spec, a.imu_port, a.gnss_port, clock, writer=writer, readers=a.readers)
        node.open()
        warm_pipeline_kernels()
    except (AdapterError, ValueError, OSError) as e:
        _say({"error": str(e).splitlines()[0] if str(e) else type(e).__name__})
        return 2
    gc.collect()
    gc.freeze()  # as the bench's own process: what exists now is never scanned again mid-run
    _say({"ready": True})
    stop = threading.Event()
    started = threading.Event()

    def control():
        for line in sys.stdin:
            cmd = line.split()
            if cmd and cmd[0] == "go" and len(cmd) == 2:
                clock.start(int(cmd[1]))
                started.set()
            elif cmd and cmd[0] == "stop":
                stop.set()
                return
        stop.set()  # the parent went away

    threading.Thread(target=control, name="child-control", daemon=True).start()
    while not started.wait(0.05):
        if stop.is_set():
            return 1
    runner = threading.Thread(target=node.run, args=(stop,), name="child-pipeline", daemon=True)
    runner.start()
    while runner.is_alive():
        _say({"received": node.received_counts()})
        runner.join(0.1)
    _say({"received": node.received_counts()})
    system.close()  # its prediction worker: no executor left for the interpreter's exit to wake
    arr = node.cycles.arrays()
    np.savez(work / "cycles.npz", **arr)
    (work / "result.json").write_text(json.dumps({
        "frames_sent": len(node.frames_sent), "frames_sent_mono_ns": [m for m, _ in node.frames_sent],
        "counters": node.counters(), "outputs": node.outputs, "errors": node.errors}))
    if writer is not None:
        node.finish_recording()
        writer.close()
    _say({"done": True})
    return 0


if __name__ == "__main__":
    sys.exit(main())
