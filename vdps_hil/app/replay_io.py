"""The recording side of a replay (``vdps replay``): decoding the ``/raw/`` topics and writing
the output recording, in this process or in a second one (``--jobs 2``).

A replay's costs split in two: the recording side (MCAP chunks, CAN frames, IMU packets, NMEA
sentences, device clocks, the reorder buffer; copying the raw topics and writing the ``/est/``
topics) and the system on the decoded samples. :class:`LocalRecordingSide` does the former in
this process. :class:`RecordingProcess` runs a ``LocalRecordingSide`` in a child interpreter
(``python -P -m vdps_hil.app.replay_io``: never importing from the working directory,
``app.children``) with the same interface: the child decodes and writes
while the parent runs the system, so on two free cores the wall time is set by the slower side
instead of the sum. The output holds the same messages either way (tested).

Interface (both): iterate the decoded samples (in order); ``start_output(metadata)`` once the
replay's configuration is accepted (raw records read before it wait, so a refused configuration
writes nothing; the output is opened at the first raw record, whose clock it keeps);
``writer``: where the system's outputs go (``write_json``, ``write_estimate``), ``None`` without
an output or before it opened; ``finish()`` closes the output; ``abort()`` on an error; after the
iteration ``counters``, ``rejected()`` and ``decoding`` as a ``DecodedRecording`` has them, and
``sample_counts`` (samples per source and kind, first and last sample time).
Errors are :class:`ReplayIOError` (one line).

Wire between the processes: frames of an 8-byte little-endian length and a pickle (protocol 5)
of ``(tag, payload)``. Child -> parent: ``("samples", [Sample, ...])`` batches, ``("end",
decoder state)``, ``("closed", None)``, ``("error", one line)``. Parent -> child: ``("go",
metadata)``, ``("calls", [(method, args, kwargs), ...])`` (``write_encoded`` of messages the parent
encoded with the writer's own functions: the child's decoding is the longer side, so the parent
takes the encoding), ``("close", None)``. The pickles are made by the two processes themselves from plain data
(samples, numbers, strings); bytes read from a recording are never unpickled. The child
inherits stderr, reads the parent's frames on a thread (so neither side can block the other on
a full pipe), stops quietly when the parent goes away, and is killed by ``abort()``. The pipe's
buffer bounds how far the child decodes ahead, so memory stays flat on long drives.
"""

from __future__ import annotations

import json
import os
import pickle
import queue
import signal
import struct
import subprocess
import sys
import threading
from typing import Any, Iterator, Mapping, NoReturn

from vdps_hil.app.children import child_environ, python_module_command
from vdps_hil.bus.samples import Sample

BATCH = 2048
"""Samples per frame: large enough that the per-frame cost vanishes, small enough that the
parent starts early."""

CALLS_PER_FRAME = 512
"""Writer calls the parent collects before it sends them."""

WRITER_CALLS = frozenset({"write_encoded"})
"""The writer methods the parent may ask the child to call (messages the parent encoded)."""

_LEN = struct.Struct("<Q")


class ReplayIOError(ValueError):
    """The recording side cannot go on (unreadable input, output not writable, the second
    process failed): one line."""


def _one_line(e: BaseException) -> str:
    text = str(e)
    return text.splitlines()[0] if text else type(e).__name__


class SampleCounter:
    """Samples per source and kind, first and last sample time (the replay summary's
    ``messages_read`` and duration), counted as the samples are handed out (here, or by the
    replay itself for the samples of a recorded input order)."""

    __slots__ = ("counts", "t_first", "t_last")

    def __init__(self):
        self.counts: dict[tuple[str, str], int] = {}
        self.t_first: int | None = None
        self.t_last: int | None = None

    def count(self, s: Sample) -> None:
        key = (s.source, s.kind)
        self.counts[key] = self.counts.get(key, 0) + 1
        if self.t_first is None:
            self.t_first = s.t_ns
        self.t_last = s.t_ns

    def document(self) -> dict:
        return {"per_source_kind": {f"{a}/{b}": n for (a, b), n in self.counts.items()},
                "t_first_ns": self.t_first, "t_last_ns": self.t_last}


# ----------------------------------------------------------------------------- in this process
class LocalRecordingSide:
    """Decoding and writing in this process (module docstring). ``reader``: an open
    :class:`~vdps_hil.record.reader.RecordingReader` or a path."""

    def __init__(self, reader, *, dbc=None, signalmap=None, bus_map: Mapping[str, str] | None = None,
                 output=None, copy_raw: bool = True, count_samples: bool = True):
        from vdps_hil.record.decode import DecodeError, decode_recording

        self.output = output
        self.copy_raw = bool(copy_raw)
        self.writer = None
        self._pending: list | None = []  # raw records read before start_output
        self._metadata: dict | None = None
        self._copy = None
        self._counter = SampleCounter() if count_samples else None  # the child leaves it to the parent
        self._decode_error = DecodeError
        try:
            self.dec = decode_recording(reader, dbc=dbc, signalmap=signalmap, bus_map=bus_map,
                                        raw_sink=self._sink if output is not None else None)
        except DecodeError as e:
            raise ReplayIOError(_one_line(e)) from None
        self._reader = self.dec.reader
        self._it = iter(self.dec)

    def __iter__(self) -> Iterator[Sample]:
        return self

    def __next__(self) -> Sample:
        try:
            s = next(self._it)
        except self._decode_error as e:
            raise ReplayIOError(_one_line(e)) from None
        if self._counter is not None:
            self._counter.count(s)
        return s

    @property
    def sample_counts(self) -> dict:
        return self._counter.document()

    def _sink(self, rec) -> None:
        if self._pending is not None:
            self._pending.append(rec)
            return
        if self.writer is None:  # opened at the first raw record: keep its clock
            from vdps_hil.record.decode import raw_copier
            from vdps_hil.record.writer import RecordingWriter

            epoch = max(0, rec.log_time_ns - rec.t_ns) if rec.log_time_ns else None
            try:
                self.writer = RecordingWriter(self.output, sim_epoch_ns=epoch, metadata=self._metadata)
            except OSError as e:
                raise ReplayIOError(f"cannot write {self.output}: {e.strerror or e}") from None
            self._copy = raw_copier(self._reader, self.writer)
        if self.copy_raw:
            self._copy(rec)

    def start_output(self, metadata: Mapping[str, Any]) -> None:
        """The configuration is accepted: write the raw records read so far and go on."""
        self._metadata = dict(metadata)
        pending, self._pending = self._pending, None
        if self.output is not None:
            for rec in pending or ():
                self._sink(rec)

    @property
    def counters(self) -> dict:
        return self.dec.counters

    def rejected(self) -> dict:
        return self.dec.rejected()

    @property
    def decoding(self) -> dict:
        return self.dec.decoding

    def finish(self) -> None:
        """Close the output (complete file)."""
        if self.writer is not None and not self.writer.closed:
            self.writer.close()

    def abort(self) -> None:
        """An error: close what is open (the output stays a readable file of what was written)."""
        self.finish()


# ----------------------------------------------------------------------------- second process
def _send(out, tag: str, payload) -> None:
    """One frame to the buffered binary stream ``out`` (flushed by the caller)."""
    blob = pickle.dumps((tag, payload), protocol=5)
    out.write(_LEN.pack(len(blob)))
    out.write(blob)


def _receive(inp):
    """One frame from the binary stream ``inp``, or None at its end."""
    head = inp.read(_LEN.size)
    if len(head) < _LEN.size:
        return None
    n, = _LEN.unpack(head)
    blob = inp.read(n)
    if len(blob) < n:
        return None
    return pickle.loads(blob)


def _widen_pipes(*files) -> None:
    """Give the pipes a 1 MiB buffer where the system allows (Linux ``F_SETPIPE_SZ``), so one
    side can run a few frames ahead instead of waiting for the other at every frame."""
    try:
        import fcntl
    except ImportError:  # not a POSIX system
        return
    setsz = getattr(fcntl, "F_SETPIPE_SZ", 1031)
    for f in files:
        try:
            fcntl.fcntl(f.fileno(), setsz, 1 << 20)
        except OSError:  # above the system's limit (fs.pipe-max-size): keep the default
            pass


class _EncodingForwarder:
    """The parent's ``writer``: encodes each message as ``RecordingWriter`` would (the same
    functions, so the same bytes and the same checks, raised here) and queues it for the child,
    which writes it (``write_encoded``). Encoding here balances the two processes: the child's
    decoding is the longer side."""

    def __init__(self, proc: "RecordingProcess"):
        from vdps_hil.record import schemas as S
        from vdps_hil.record.payloads import estimate_payload, estimate_topic, json_payload

        self._proc = proc
        self._estimate = S.ESTIMATE
        self._est_payload, self._est_topic, self._json_payload = estimate_payload, estimate_topic, json_payload
        self._topics: dict[str, str] = {}  # estimate topic as given -> checked absolute topic

    def write_json(self, topic: str, schema_name: str, t_ns: int, doc, *, wall_time_ns: int | None = None,
                   channel_metadata: Mapping[str, str] | None = None) -> None:
        payload = self._json_payload(topic, schema_name, t_ns, doc)
        self._proc._call("write_encoded", (topic, schema_name, t_ns, payload),
                         {"wall_time_ns": wall_time_ns, "channel_metadata": channel_metadata})

    def write_encoded(self, topic: str, schema_name: str, t_ns: int, payload: bytes, *,
                      wall_time_ns: int | None = None, channel_metadata: Mapping[str, str] | None = None) -> None:
        """A message already encoded (the Foxglove view's samples), written by the child."""
        self._proc._call("write_encoded", (topic, schema_name, t_ns, payload),
                         {"wall_time_ns": wall_time_ns, "channel_metadata": channel_metadata})

    def write_estimate(self, topic: str, t_ns: int, values, sigmas=None) -> None:
        full = self._topics.get(topic)
        if full is None:
            full = self._topics[topic] = self._est_topic(topic)
        self._proc._call("write_encoded", (full, self._estimate, t_ns, self._est_payload(t_ns, values, sigmas)), {})


class RecordingProcess:
    """The recording side in a child process (module docstring); ``path``: the recording."""

    def __init__(self, path, *, dbc=None, signalmap=None, bus_map: Mapping[str, str] | None = None,
                 output=None, copy_raw: bool = True):
        args = {"path": os.fspath(path), "dbc": None if dbc is None else os.fspath(dbc),
                "signalmap": None if signalmap is None else os.fspath(signalmap),
                "bus_map": dict(bus_map or {}), "output": None if output is None else os.fspath(output),
                "copy_raw": bool(copy_raw)}
        self._proc = subprocess.Popen(python_module_command(__name__, [json.dumps(args)]),
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=child_environ())
        _widen_pipes(self._proc.stdin, self._proc.stdout)
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._sender = threading.Thread(target=self._send_frames, name="replay-io-send", daemon=True)
        self._sender.start()
        self.writer = None if output is None else _EncodingForwarder(self)
        self._counter = SampleCounter()
        self._calls: list = []
        self._state: dict | None = None
        self._it = self._run()

    def __iter__(self) -> Iterator[Sample]:
        return self._it

    @property
    def pid(self) -> int:
        """The child's process id."""
        return self._proc.pid

    def __next__(self) -> Sample:
        return next(self._it)

    # parent -> child
    def _to_child(self, tag: str, payload) -> None:
        """Queue a frame for the child; a thread writes it, so this process never waits on a
        full pipe while the child waits for it to read (both sides keep going)."""
        blob = pickle.dumps((tag, payload), protocol=5)
        self._outbox.put(_LEN.pack(len(blob)) + blob)

    def _send_frames(self) -> None:
        """The writer thread: frames from the outbox to the child's stdin until None."""
        stdin = self._proc.stdin
        try:
            while True:
                frame = self._outbox.get()
                if frame is None:
                    break
                stdin.write(frame)
                stdin.flush()
        except (BrokenPipeError, OSError, ValueError):  # the child has gone: its own frame says why
            pass

    def _call(self, name: str, args, kwargs) -> None:
        self._calls.append((name, args, kwargs))
        if len(self._calls) >= CALLS_PER_FRAME:
            self._flush_calls()

    def _flush_calls(self) -> None:
        if self._calls:
            calls, self._calls = self._calls, []
            self._to_child("calls", calls)

    def start_output(self, metadata: Mapping[str, Any]) -> None:
        self._to_child("go", dict(metadata))

    # child -> parent
    def _frame(self):
        msg = _receive(self._proc.stdout)
        if msg is None:
            code = self._proc.wait()
            raise ReplayIOError(f"the replay's decoding process ended without a result (exit status {code}); "
                                "--jobs 1 decodes in this process")
        tag, payload = msg
        if tag == "error":
            raise ReplayIOError(str(payload))
        return tag, payload

    def _run(self) -> Iterator[Sample]:
        while True:
            tag, payload = self._frame()
            if tag == "samples":
                count = self._counter.count
                for s in payload:
                    count(s)
                    yield s
                self._flush_calls()
            elif tag == "end":
                self._state = payload
                return
            else:
                raise ReplayIOError(f"the replay's decoding process sent an unexpected {tag!r}")

    def _end_state(self) -> dict:
        if self._state is None:
            raise RuntimeError("the decoder's counters are known at the end of the samples")
        return self._state

    @property
    def counters(self) -> dict:
        return self._end_state()["counters"]

    @property
    def sample_counts(self) -> dict:
        return self._counter.document()

    def rejected(self) -> dict:
        return self._end_state()["rejected"]

    @property
    def decoding(self) -> dict:
        return self._end_state()["decoding"]

    def finish(self) -> None:
        """Send the last writer calls, let the child close the output, wait for it."""
        self._flush_calls()
        self._to_child("close", None)
        try:
            while True:
                tag, _ = self._frame()
                if tag == "closed":
                    break
        finally:
            self.abort()

    def abort(self) -> None:
        """Stop the child (if it still runs) and release the pipes: with both pipes closed it
        ends at its next frame (closing the output it has written so far) or is killed."""
        p = self._proc
        self._outbox.put(None)
        self._sender.join(timeout=5.0)  # returns at once unless a write is stuck on a full pipe
        for f in (p.stdout, p.stdin):
            try:
                f.close()
            except (BrokenPipeError, OSError, ValueError):
                pass
        if p.poll() is None:
            try:
                p.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    def __del__(self):
        try:
            if self._proc.poll() is None:
                self._proc.kill()
                self._proc.wait()
        except Exception:  # interpreter shutdown
            pass


def _child(args: dict) -> NoReturn:
    """The child: decode, send the samples, write the output as the parent says; it ends
    through :func:`_exit_now` on every path."""
    from vdps_hil.record.reader import RecordingError, RecordingReader

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it closes the pipes
    out = sys.stdout.buffer
    inbox: queue.SimpleQueue = queue.SimpleQueue()

    def listen():  # the parent's frames, as they come
        inp = sys.stdin.buffer
        while True:
            try:
                msg = _receive(inp)
            except Exception:  # a broken frame: treated as the end
                msg = None
            inbox.put(msg or ("eof", None))
            if msg is None or msg[0] == "close":
                return

    threading.Thread(target=listen, name="replay-io-inbox", daemon=True).start()
    side = None

    def serve(block: bool) -> bool:
        """Carry out the parent's frames waiting (all of them up to close with ``block``);
        True once the parent said close (or went away)."""
        while True:
            try:
                tag, payload = inbox.get() if block else inbox.get_nowait()
            except queue.Empty:
                return False
            if tag == "go":
                side.start_output(payload)
            elif tag == "calls":
                w = side.writer
                if w is not None:
                    for name, a, kw in payload:
                        if name in WRITER_CALLS:
                            getattr(w, name)(*a, **kw)
            elif tag in ("close", "eof"):
                return True

    try:
        try:
            side = LocalRecordingSide(RecordingReader(args["path"]), dbc=args["dbc"], signalmap=args["signalmap"],
                                      bus_map=args["bus_map"] or None, output=args["output"],
                                      copy_raw=args["copy_raw"], count_samples=False)
            batch: list[Sample] = []
            for s in side:
                batch.append(s)
                if len(batch) >= BATCH:
                    _send(out, "samples", batch)
                    out.flush()
                    batch = []
                    serve(False)
            if batch:
                _send(out, "samples", batch)
            _send(out, "end", {"counters": side.counters, "rejected": dict(side.rejected()),
                               "decoding": dict(side.decoding)})
            out.flush()
            while not serve(True):
                pass
            side.finish()
        except (ReplayIOError, RecordingError) as e:
            _send(out, "error", _one_line(e))
            out.flush()
            _exit_now(1)
        except Exception as e:  # a bug: one line to the parent instead of a traceback
            _send(out, "error", f"the replay's decoding process failed: {type(e).__name__}: {_one_line(e)}")
            out.flush()
            _exit_now(1)
        _send(out, "closed", None)
        out.flush()
        _exit_now(0)  # the output is closed and said so: skip the interpreter's teardown the parent waits for
    except BrokenPipeError:  # the parent stopped reading (a refused configuration, Ctrl-C)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, out.fileno())  # nothing left to flush at exit
        if side is not None:
            side.abort()
        _exit_now(0)


def _exit_now(code: int) -> NoReturn:
    """End the child without the interpreter's teardown, which aborted on the stdin lock the
    listening thread holds ("Fatal Python error: _enter_buffered_busy ..." on the user's
    terminal under the one-line error). The caller has flushed what it wrote."""
    sys.stderr.flush()
    os._exit(code)


def main(argv: list[str] | None = None) -> NoReturn:
    _child(json.loads((sys.argv[1:] if argv is None else argv)[0]))


if __name__ == "__main__":
    main()
