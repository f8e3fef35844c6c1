"""``vdps log --pipeline``'s estimator in a process of its own, at a lower CPU priority and in a
scheduling group of its own, so that it can never take the CPU (or the GIL) the device readers
and the recording need.

The logger's side, :class:`TapProcess`, is a tap as ``app.session.LogSession`` takes one: the
session's tap thread calls it with the decoded samples (a blocking send on a pipe: when the
estimator is behind the pipe fills, the session's bounded tap queue fills behind it and drops,
counted -- never the recording; the input order is then not recorded). The child
(``multiprocessing`` spawn, safe-path mode as every child of ours: ``app.children``) moves to a
session of its own at ``nice`` (default ``TAP_NICE``; :func:`_lower_priority`), builds
:class:`~vdps_hil.app.pipeline_tap.PipelineTap` and feeds it. What the tap writes -- ``/est/``
messages and, at :meth:`TapProcess.finish`, the input order metadata -- comes back as writer
calls (``write_json``, ``write_estimate``, ``add_metadata``; nothing else is accepted), made on
the recording's writer by a receiver thread of the logger; while the disk reserve is reached
(``recording_allowed()`` false) they are counted, not written (``outputs_skipped_disk``). At
the end it gets ``WIND_DOWN_S`` to catch up (:meth:`TapProcess.wind_down`).

Messages on the pipes (pickled, between our own two processes only): to the child
``("samples", list)``, ``("lost", n)``, ``("finish",)`` (and SIGUSR1: skip the samples not fed
yet); from it ``("ready",)`` once SIGUSR1 is handled, ``("out", calls, status)`` after each
batch, ``("done", calls, status, summary)`` after the finish, ``("error", text)`` when the tap
raised (the child then ends).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time

__all__ = ["TapProcess", "TAP_NICE", "WIND_DOWN_S"]

TAP_NICE = 10
"""Nice increment of the estimator's process: the readers (nice 0) win every contended core."""

WIND_DOWN_S = 20.0
"""At the end of the recording the estimator gets this long to work through what it was sent;
then it skips the rest (``input_unfed``), writes its last outputs and the input order of what it
was fed (a prefix of the input: a replay reproduces it)."""

_WRITER_CALLS = ("write_json", "write_estimate", "add_metadata")


class _CallLog:
    """The child's stand-in for the recording writer: notes every call, to be sent back."""

    def __init__(self):
        self.calls: list = []

    def __getattr__(self, name):
        if name not in _WRITER_CALLS:
            raise AttributeError(name)
        return lambda *a, **kw: self.calls.append((name, a, kw))

    def take(self) -> list:
        calls, self.calls = self.calls, []
        return calls


def _lower_priority(nice: int) -> None:
    """This process at ``nice`` below the logger, in a scheduling group of its own: on Linux
    with autogroups (``/proc/sys/kernel/sched_autogroup_enabled``) the processes of one session
    share one group's CPU time, so an estimator in the logger's session -- at any nice value --
    would spend the time its readers need; in a session of its own (``os.setsid``) whose group
    is at ``nice`` too (``/proc/self/autogroup``) it only takes what no one else wants."""
    try:
        os.setsid()
    except OSError:
        pass
    try:
        with open("/proc/self/autogroup", "w") as f:
            f.write(str(nice))
    except OSError:
        pass
    try:
        os.nice(nice)
    except OSError:
        pass


def _child(conn_in, conn_out, vehicle: str, params: str | None, options: dict, nice: int) -> None:
    """The child's loop (module docstring). Ctrl-C reaches the whole process group: the logger
    decides when the estimator stops."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    hurry = []
    signal.signal(signal.SIGUSR1, lambda signum, frame: hurry.append(1))  # TapProcess.wind_down
    _lower_priority(nice)
    conn_out.send(("ready",))  # SIGUSR1 handled from now on
    from vdps_hil.app.pipeline_tap import PipelineTap
    from vdps_hil.model.params import load_vehicle

    writer = _CallLog()
    try:
        model = load_vehicle(vehicle, expect_kind="model")
        start, unsettled = None, ()
        if params is not None:
            from vdps_hil.identification.persistence import load_params, unsettled_problems

            saved = load_params(params, model)
            start, unsettled = saved.params, tuple(unsettled_problems(saved))
        tap = PipelineTap(model, writer, start, start_unsettled=unsettled, **options)
        unfed = 0
        while True:
            msg = conn_in.recv()
            if msg[0] == "samples":
                if hurry:
                    unfed += len(msg[1])
                else:
                    tap(msg[1])
                conn_out.send(("out", writer.take(), tap.status_line()))
            elif msg[0] == "lost":
                tap.input_lost(msg[1])
            else:
                tap.finish()
                conn_out.send(("done", writer.take(), tap.status_line(),
                               dict(tap.summary(), input_unfed=unfed)))
                return
    except EOFError:  # the logger is gone
        return
    except Exception as e:  # noqa: BLE001 - reported to the logger in one line
        conn_out.send(("error", f"{type(e).__name__}: {(str(e).splitlines() or [''])[0]}"))


class TapProcess:
    """The logger's handle of the estimator's process (module docstring). ``vehicle`` and
    ``params`` are the files ``vdps log --pipeline`` was given (checked by the caller, loaded
    again by the child); ``options`` go to ``PipelineTap`` (``record_order``, ``params_file``,
    ``probe_s``)."""

    def __init__(self, vehicle: str, params: str | None, writer, *, nice: int = TAP_NICE,
                 wind_down_s: float = WIND_DOWN_S, **options):
        from vdps_hil.app.children import isolate_spawned_children

        isolate_spawned_children()
        ctx = multiprocessing.get_context("spawn")
        self._in_r, self._in_w = ctx.Pipe(duplex=False)
        self._out_r, self._out_w = ctx.Pipe(duplex=False)
        self.writer = writer
        self.wind_down_s = wind_down_s
        self._hurry: threading.Timer | None = None
        self.recording_allowed = lambda: True
        self.proc = ctx.Process(target=_child, name="vdps-pipeline", daemon=True,
                                args=(self._in_r, self._out_w, vehicle, params, options, nice))
        self.proc.start()
        self._in_r.close()
        self._out_w.close()
        self.error: str | None = None
        self._status = "pipeline: starting"
        self._summary: dict | None = None
        self.input_dropped = self.outputs_skipped = 0
        self._done = threading.Event()
        self._ready = threading.Event()
        self._batches = 0  # batches the child reported done
        self._receiver = threading.Thread(target=self._receive, name="tap-receiver", daemon=True)
        self._receiver.start()

    # -- the tap's interface (app.session, cli.log_cmd) ----------------------------------------

    def __call__(self, samples: list) -> None:
        if self.error is not None:
            raise RuntimeError(self.error)
        self._in_w.send(("samples", samples))

    def input_lost(self, n: int) -> None:
        """The session dropped ``n`` samples (never waits: told to the child at the finish,
        where it means "no input order")."""
        self.input_dropped += n

    def wind_down(self) -> None:
        """The recording ends: in ``wind_down_s`` the child skips what it has not fed yet
        (``WIND_DOWN_S``; the session calls this when it stops feeding)."""
        def hurry():
            if not self._ready.is_set():  # not handled yet (still starting): its default kills
                return self._later(1.0, hurry)
            try:
                os.kill(self.proc.pid, signal.SIGUSR1)
            except OSError:
                pass

        self._later(self.wind_down_s, hurry)

    def _later(self, delay_s: float, fn) -> None:
        self._hurry = threading.Timer(delay_s, fn)
        self._hurry.daemon = True
        self._hurry.start()

    def finish(self, timeout_s: float = 60.0) -> None:
        """Let the child work through what it was sent, write its last outputs and the input
        order; RuntimeError when it failed or did no batch in ``timeout_s``."""
        if self.error is None:
            try:
                if self.input_dropped:
                    self._in_w.send(("lost", self.input_dropped))
                self._in_w.send(("finish",))
            except OSError:  # the child is gone: the receiver says why
                pass
            seen, t_seen = self._batches, time.monotonic()
            while not self._done.wait(min(1.0, timeout_s)) and time.monotonic() - t_seen < timeout_s:
                if self._batches != seen:  # getting on (slowly, at its priority)
                    seen, t_seen = self._batches, time.monotonic()
        self._in_w.close()
        if self._hurry is not None:
            self._hurry.cancel()
        if self._summary is None:
            self.proc.kill()
        self.proc.join(5.0)
        if self.error is not None:
            raise RuntimeError(self.error)
        if self._summary is None:
            raise RuntimeError(f"no batch done in {timeout_s:g} s; its last outputs and the "
                               "input order left out")

    def status_line(self) -> str:
        return self._status

    def summary(self) -> dict:
        s = dict(self._summary or {"input_order_recorded": False})
        s["input_dropped"] = self.input_dropped
        s["outputs_skipped_disk"] = self.outputs_skipped
        s["error"] = s.get("error") or self.error
        return s

    # -- the receiver thread ---------------------------------------------------------------------

    def _receive(self) -> None:
        try:
            while True:
                msg = self._out_r.recv()
                if msg[0] == "ready":
                    self._ready.set()
                    continue
                if msg[0] == "error":
                    self.error = f"pipeline process: {msg[1]}"
                    return
                self._write(msg[1])
                self._status = msg[2]
                self._batches += 1
                if msg[0] == "done":
                    self._summary = msg[3]
                    return
        except (EOFError, OSError):
            if self._summary is None and self.error is None:
                self.error = f"pipeline process ended (exit code {self.proc.exitcode})"
        finally:
            self._done.set()

    def _write(self, calls: list) -> None:
        if calls and not self.recording_allowed():
            self.outputs_skipped += sum(name != "add_metadata" for name, _, _ in calls)
            calls = [c for c in calls if c[0] == "add_metadata"]
        for name, args, kw in calls:
            if name in _WRITER_CALLS:
                getattr(self.writer, name)(*args, **kw)
