"""A live CAN bus made of ``candump -L`` lines on a stream (standard input): ``candump -L can0 |
vdps log --can pt=- ...``.

:class:`CandumpStreamBus` is a python-can ``BusABC``, so the ordinary :class:`CanAdapter
<vdps_hil.adapters.can_adapter.CanAdapter>` reads it like any interface (host time stamps when a
frame is received, the line's own time as the device time, decoding, health). Lines are parsed by
python-can's candump reader (``can.io.canutils.CanutilsLogReader``, never by hand) in a reader
thread, so a slow pipe never blocks the adapter. Format, one frame per line::

    (1436509052.249713) can0 100#2A366C2BBA        classic frame (``R``/``T`` suffix: direction)
    (1436509052.250000) can0 1ABCDEF0#R            remote frame, 29-bit ID
    (1436509052.251000) can0 123##1A1B1C           CAN FD (flags digit, then data)

A line python-can cannot parse is raised as ``ValueError`` from ``recv`` once (the adapter counts
it in ``bad_frames``, with the line in ``last_error``) and reading goes on; bytes that are not
UTF-8 are replaced and so end in a bad line. At the end of the stream, once every frame was
received, ``recv`` raises :class:`~vdps_hil.adapters.base.EndOfInput` and the adapter ends.
"""

from __future__ import annotations

import io
import queue
import threading
from typing import IO

import can
from can.io.canutils import CanutilsLogReader

from vdps_hil.adapters.base import EndOfInput

__all__ = ["CandumpStreamBus", "STDIN_SPEC"]

STDIN_SPEC = "-"
"""The ``--can BUS=-`` interface string: candump -L lines on standard input."""


class _Lines:
    """The stream's lines as text, for python-can's reader (which closes it at the end: no-op);
    ``last`` is the line read last (named in the error of a line that does not parse)."""

    def __init__(self, stream: IO[bytes]):
        self.text = io.TextIOWrapper(stream, encoding="utf-8", errors="replace", newline=None)
        self.last = ""

    def __iter__(self):
        while True:
            line = self.text.readline()
            if not line:
                return
            self.last = line
            yield line

    def close(self) -> None:
        pass


class CandumpStreamBus(can.BusABC):
    """Frames of ``candump -L`` lines read from ``stream`` (binary; module docstring). Receive only."""

    def __init__(self, stream: IO[bytes], channel: str = "stdin", **kwargs):
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"candump -L lines on {channel}"
        self._q: queue.Queue = queue.Queue(maxsize=100_000)
        self._ended = threading.Event()
        self._drained = False
        self.lines_bad = 0
        self._thread = threading.Thread(target=self._read, args=(_Lines(stream),), name="candump-stream", daemon=True)
        self._thread.start()

    def _read(self, lines: _Lines) -> None:
        try:
            while True:
                try:
                    for msg in CanutilsLogReader(lines):
                        self._q.put(msg)
                    return
                except (ValueError, IndexError, TypeError) as e:  # a line python-can cannot parse
                    self.lines_bad += 1
                    self._q.put(ValueError(f"not a candump -L line ({type(e).__name__}): {lines.last.strip()[:120]!r}"))
        finally:
            self._ended.set()

    def _recv_internal(self, timeout: float | None):
        if self._drained and self._q.empty():
            raise EndOfInput("end of the candump stream")
        try:
            item = self._q.get(timeout=0.1 if timeout is None else timeout) if timeout != 0 else self._q.get_nowait()
        except queue.Empty:
            if self._ended.is_set() and self._q.empty():
                self._drained = True  # the next call ends the input (after this batch is delivered)
            return None, False
        if isinstance(item, Exception):
            raise item
        return item, False

    def __del__(self) -> None:
        # python-can warns about a bus never shut down; this one holds no device (a CanAdapter
        # given it as an open bus leaves it to its owner), so it is shut down quietly here
        if not getattr(self, "_is_shutdown", True):
            self.shutdown()

    def send(self, msg, timeout=None) -> None:
        raise can.CanOperationError("a candump stream is receive-only")
