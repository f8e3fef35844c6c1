"""The bench's pipeline side, in this process (:class:`LocalPipeline`: a ``PipelineNode`` in a
thread, python-can's virtual bus or an interface string) or in a child process
(:class:`ChildPipeline`: ``python -P -m vdps_hil.hil.child`` over a pty or loopback TCP). Both have
the interface :class:`~vdps_hil.hil.bench.Bench` drives: ``open``, ``start(mono0)``, ``failed``,
``error``, ``received``, ``stop``, ``kill``, ``results``, ``finish_recording`` and ``pid``."""

from __future__ import annotations

import json
import os
import subprocess
import threading
from pathlib import Path

import numpy as np

from vdps_hil.adapters.base import AdapterError
from vdps_hil.app.children import child_environ, python_module_command
from vdps_hil.record import schemas as S

from .bench_config import BenchError, make_system, warm_pipeline_kernels
from .latency import CycleLog

__all__ = ["LocalPipeline", "ChildPipeline"]


class LocalPipeline:
    def __init__(self, bench: "Bench", can_dev, serial, clock, writer):
        from .node import PipelineNode

        try:
            sp = bench.drive.profile.suspension
            system = make_system(bench.model, sp.rate_hz, sp.sigma_m, bench.config.params, live=True)
        except (ValueError, OSError) as e:
            raise BenchError(str(e).splitlines()[0]) from None
        self.node = PipelineNode(system, can_dev.pipeline_spec, serial["imu"].port, serial["gnss"].port, clock,
                                 writer=writer, readers=bench.config.readers)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error = ""

    pid = os.getpid()

    def open(self) -> None:
        try:
            self.node.open()
        except AdapterError as e:
            raise BenchError(str(e)) from None
        warm_pipeline_kernels()

    def start(self, mono0: int) -> None:
        self._thread = threading.Thread(target=self._run, name="bench-pipeline", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self.node.run(self._stop)
        except Exception as e:  # noqa: BLE001 - reported by the bench
            self._error = f"{type(e).__name__}: {e}"

    def failed(self) -> bool:
        return bool(self._error)

    def kill(self) -> None:
        """Stop the pipeline thread if the bench ends early (an error)."""
        self._stop.set()

    def error(self) -> str:
        return self._error

    def received(self) -> dict:
        return self.node.received_counts()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30.0)
        self.node.system.close()  # its prediction worker (the system's owner closes it)
        if self._error:
            raise BenchError(f"pipeline failed: {self._error}")

    def results(self) -> dict:
        n = self.node
        return {"cycles": n.cycles, "frames_sent": len(n.frames_sent), "counters": n.counters(),
                "outputs": dict(n.outputs), "errors": list(n.errors)}

    def finish_recording(self, doc: dict, writer) -> None:
        self.node.finish_recording({"bench": doc})
        writer.add_metadata("hil.bench", {"result": json.dumps(S.clean_json(doc), sort_keys=True)})


class ChildPipeline:
    """The pipeline in ``python -m vdps_hil.hil.child`` (``hil.bench`` docstring: processes)."""

    def __init__(self, bench: "Bench", can_dev, serial, work: Path):
        self.bench = bench
        self.work = work
        c = bench.config
        self.part = work / "pipeline.mcap" if c.output else None
        args = ["--can-spec", can_dev.pipeline_spec,
                "--imu-port", serial["imu"].port, "--gnss-port", serial["gnss"].port, "--model", bench.model,
                "--susp-rate-hz", repr(bench.drive.profile.suspension.rate_hz),
                "--susp-sigma-m", repr(bench.drive.profile.suspension.sigma_m),
                "--speed", repr(c.speed), "--work", str(work)]
        if self.part is not None:
            args += ["--output", str(self.part)]
        if c.params is not None:
            args += ["--params", str(c.params)]
        if c.switch_interval_s:
            args += ["--switch-interval", repr(c.switch_interval_s)]
        args += ["--readers", c.readers]
        cmd = python_module_command("vdps_hil.hil.child", args)  # -P: nothing from the working directory
        env = child_environ()
        self._err_path = work / "child.err"
        self._err = open(self._err_path, "w")  # a file, never a pipe that could fill and block the child
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err,
                                     env=env, text=True, bufsize=1)
        self._progress: dict = {}
        self._lines: list[dict] = []
        self._ready = threading.Event()
        self._done = threading.Event()
        self._reader = threading.Thread(target=self._read, name="bench-child-out", daemon=True)
        self._reader.start()
        self.can_dev = can_dev

    @property
    def pid(self) -> int:
        return self.proc.pid

    def _read(self) -> None:
        for line in self.proc.stdout:
            try:
                doc = json.loads(line)
            except ValueError:
                continue
            if doc.get("ready"):
                self._ready.set()
            if "received" in doc:
                self._progress = doc["received"]
            if doc.get("done"):
                self._done.set()
            self._lines.append(doc)
        self._ready.set()
        self._done.set()

    def open(self) -> None:
        if not self._ready.wait(60.0) or self.proc.poll() is not None:
            err = self._stderr()
            raise BenchError(f"pipeline process did not start: {err}")
        if any(d.get("error") for d in self._lines):
            raise BenchError(f"pipeline process: {next(d['error'] for d in self._lines if d.get('error'))}")

    def _stderr(self) -> str:
        try:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait(10.0)
            err = self._err_path.read_text(errors="replace")
        except (OSError, ValueError, subprocess.TimeoutExpired):
            err = ""
        lines = [ln for ln in (err or "").strip().splitlines() if ln.strip()]
        return lines[-1] if lines else f"exit status {self.proc.poll()}"

    def start(self, mono0: int) -> None:
        self._send(f"go {mono0}")

    def _send(self, text: str) -> None:
        try:
            self.proc.stdin.write(text + "\n")
            self.proc.stdin.flush()
        except (OSError, ValueError):
            pass

    def failed(self) -> bool:
        return self.proc.poll() is not None and not self._done.is_set()

    def error(self) -> str:
        return self._stderr()

    def kill(self) -> None:
        """End the child if it is still running (the bench ended early); close its stderr file."""
        if self.proc.poll() is None:
            self.proc.kill()
            try:
                self.proc.wait(10.0)
            except subprocess.TimeoutExpired:
                pass
        if not self._err.closed:
            self._err.close()

    def received(self) -> dict:
        return dict(self._progress)

    def stop(self) -> None:
        self._send("stop")
        if not self._done.wait(60.0):
            self.proc.kill()
            raise BenchError("pipeline process did not stop")
        try:
            self.proc.wait(30.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self._err.close()
        if self.proc.returncode != 0:
            raise BenchError(f"pipeline process failed: {self._stderr()}")

    def results(self) -> dict:
        d = np.load(self.work / "cycles.npz")
        doc = json.loads((self.work / "result.json").read_text())
        err = [ln for ln in self._err_path.read_text(errors="replace").splitlines() if ln.strip()]
        return {"cycles": CycleLog.from_arrays(d), "frames_sent": doc["frames_sent"], "counters": doc["counters"],
                "outputs": doc["outputs"], "errors": doc["errors"] + [f"stderr: {ln}" for ln in err[-5:]]}

    def finish_recording(self, doc: dict, writer) -> None:
        """Merge the child's recording (raw as received, /decoded, /est) with the truth."""
        from vdps_hil.record.reader import RecordingReader
        from vdps_hil.record.writer import RecordingWriter

        from . import node  # noqa: F401 - registers the schemas the pipeline process wrote (health, view)

        c = self.bench.config
        writer.close()
        out = RecordingWriter(c.output, metadata={"source": "vdps bench"},
                              content_hashes={"dbc.vdps": self.bench.drive.dbc_path},
                              sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
        try:
            for path in (self.part, writer.path):
                with RecordingReader(path) as r:
                    topics = r.topics()
                    for name, md in r.metadata().items():
                        if name != S.METADATA_NAME:
                            out.add_metadata(name, md)
                    for rec in r.iter_records():
                        doc_ = json.loads(rec.data)
                        out.write_json(rec.topic, topics[rec.topic].schema, rec.t_ns, doc_,
                                       wall_time_ns=rec.log_time_ns, channel_metadata=r.channel_metadata(rec.topic))
            out.add_metadata("hil.bench", {"result": json.dumps(S.clean_json(doc), sort_keys=True)})
        finally:
            out.close()
