"""The device end of a wire: a non-blocking writer with a device FIFO, the log of send times,
and the pseudo-terminal serial device the simulator writes the IMU and GNSS streams to.

Device-side behaviour (all transports, :mod:`vdps_hil.hil.transports`):

* Writes never block the simulator: a pty or socket that cannot take more keeps the rest in a
  device FIFO (``fifo_bytes``, default ``DEVICE_FIFO_BYTES`` = 64 KiB: a USB adapter's FIFO plus
  the host driver's buffers, about 1.4 s of the IMU stream at 921600 Bd on top of the pty's own
  20-30 KB) and, when that is full too, drops the whole new message and counts it
  (``dropped``) -- lost data shows up as sequence gaps at the receiver, as on a real link.
* Every accepted write is logged as (cumulative count, monotonic time) in a :class:`SendLog`:
  the latency measurement (``hil.latency``) finds the time a given frame or byte went onto the
  wire from its index.

Symbols: cumulative counts (frames, bytes) are 0-based item indices + 1; times are monotonic
host ns (``time.monotonic_ns``).
"""

from __future__ import annotations

import errno
import fcntl
import os
import pty
import select
import threading
import time
import tty

import numpy as np

__all__ = ["SendLog", "DeviceFifo", "PtySerialDevice", "DEVICE_FIFO_BYTES"]

DEVICE_FIFO_BYTES = 65536
"""Buffering of a device side beyond the pty/socket [bytes] (module docstring)."""


class SendLog:
    """(cumulative count, monotonic ns) per accepted write: ``time_of(i)`` is the send time of
    item ``i`` (0-based: the i-th frame, or the byte at offset i of a serial stream)."""

    def __init__(self):
        self._cum: list[int] = []
        self._t: list[int] = []
        self.total = 0

    def add(self, n: int, mono_ns: int) -> None:
        if n > 0:
            self.total += n
            self._cum.append(self.total)
            self._t.append(mono_ns)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self._cum, dtype=np.int64), np.asarray(self._t, dtype=np.int64)

    def time_of(self, index) -> np.ndarray:
        """Send time of items ``index`` (array); -1 where the item was never sent."""
        cum, t = self.arrays()
        idx = np.asarray(index, dtype=np.int64)
        k = np.searchsorted(cum, idx, side="right")
        out = np.full(idx.shape, -1, dtype=np.int64)
        ok = (k < len(cum)) & (idx >= 0)
        out[ok] = t[k[ok]]
        return out


def _nonblocking(fd: int) -> None:
    fl = fcntl.fcntl(fd, fcntl.F_GETFL)
    fcntl.fcntl(fd, fcntl.F_SETFL, fl | os.O_NONBLOCK)


class DeviceFifo:
    """A non-blocking writer with a device FIFO (module docstring). ``write_fn(bytes) -> n``
    writes what the OS takes (raises BlockingIOError when nothing)."""

    def __init__(self, write_fn, fifo_bytes: int):
        self._write = write_fn
        self._lock = threading.Lock()
        self.fifo_bytes = int(fifo_bytes)
        self.pending = bytearray()
        self.dropped = 0
        self.dropped_bytes = 0
        self.log = SendLog()

    def pump(self) -> None:
        with self._lock:
            self._pump()

    def _pump(self) -> None:
        while self.pending:
            try:
                n = self._write(bytes(self.pending))
            except (BlockingIOError, InterruptedError):
                return
            except OSError as e:
                if e.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                    return
                raise
            if not n:
                return
            self.log.add(n, time.monotonic_ns())
            del self.pending[:n]

    def send(self, msg: bytes) -> bool:
        """Queue one whole message; False (dropped, counted) when the FIFO cannot take it."""
        with self._lock:
            if self.pending:
                self._pump()
            if len(self.pending) + len(msg) > self.fifo_bytes and self.pending:
                self.dropped += 1
                self.dropped_bytes += len(msg)
                return False
            self.pending += msg
            self._pump()
            return True


class PtySerialDevice:
    """The device end of a pseudo-terminal (raw mode, non-blocking). ``port`` is the path the
    pipeline opens. ``write(data)`` queues one message (a read chunk of the simulated device),
    counts what was accepted (``log``, byte offsets) and what was dropped. The slave end stays
    open on our side so the pty survives the pipeline opening and closing it."""

    def __init__(self, name: str, fifo_bytes: int = DEVICE_FIFO_BYTES):
        self.name = name
        self.master, self.slave = pty.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        _nonblocking(self.master)
        self.port = os.ttyname(self.slave)
        self._fifo = DeviceFifo(lambda b: os.write(self.master, b), fifo_bytes)
        self.messages = 0
        self.lines = 0
        self.bytes_in = 0

    @property
    def log(self) -> SendLog:
        return self._fifo.log

    @property
    def dropped(self) -> int:
        return self._fifo.dropped

    @property
    def pending_bytes(self) -> int:
        return len(self._fifo.pending)

    def write(self, data: bytes) -> bool:
        self.messages += 1
        self.bytes_in += len(data)
        self.lines += data.count(b"\n")
        return self._fifo.send(data)

    def send_unlogged(self, data: bytes) -> bool:
        """Queue ``data`` whole, like ``write``, without counting it among the device's
        messages, lines and bytes (an emulated adapter's protocol traffic)."""
        return self._fifo.send(data)

    def pump(self) -> None:
        self._fifo.pump()

    def read(self, timeout_s: float = 0.0) -> bytes:
        """What the pipeline wrote to the device (commands); waits up to ``timeout_s``."""
        if self.master < 0:  # closed
            return b""
        try:
            if timeout_s > 0:
                r, _, _ = select.select([self.master], [], [], timeout_s)
                if not r:
                    return b""
            return os.read(self.master, 65536)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            return b""

    def close(self) -> None:
        """Close both ends, once: a second call closes nothing (the descriptor numbers may by
        then belong to another file of the process)."""
        fds, self.master, self.slave = (self.master, self.slave), -1, -1
        for fd in fds:
            if fd < 0:
                continue
            try:
                os.close(fd)
            except OSError:
                pass
