"""A device reader in its own process: it drains one file descriptor (a serial port, a
pseudo-terminal, an slcan adapter's port) and does nothing else, so no decoding, writing or
estimating in the logger can make it miss bytes.

The parent opens the device (pyserial sets the baud and the raw mode; python-can sends the slcan
set-up commands) and hands the descriptor over a Unix socket (``SCM_RIGHTS``). The child loops::

    poll(device, socket)
    device readable  -> data = read(fd, 64 KiB); t_ns = CLOCK_MONOTONIC now
                        append (DATA, t_ns, data) to its buffer, or drop it when the buffer
                        holds max_buffer_bytes (counted, reported as one OVERFLOW record
                        before the next data: chunks, bytes, time of the first drop)
    socket writable  -> send what the buffer holds
    read error / EOF -> one LOST record (the errno text); the fd is closed, the next one the
                        parent hands over is read
    "Q" from parent  -> read what the device still holds (until it has been quiet for 0.1 s,
                        at most 1 s), send everything, exit

so each chunk carries the monotonic time at which its read returned (the same clock as the
parent's ``SystemClock``), and the only waits of the child are ``poll`` and the read itself. The
child runs this file alone (``python -I -S``: the standard library only, start-up ~20 ms) and ignores SIGINT (Ctrl-C in
a terminal reaches the whole process group; the parent decides when the reader stops). It
exits when the parent's end of the socket closes (the parent died).

Records on the socket: ``struct "<BqI"`` (kind, t_ns, length) then ``length`` bytes. Kinds:
``DATA`` (bytes as read), ``LOST`` (UTF-8 reason), ``OVERFLOW`` (``"<QQ"``: chunks, bytes).
"""

from __future__ import annotations

import os
import select
import signal
import socket
import struct
import subprocess
import sys
import time

__all__ = ["FdReader", "DATA", "LOST", "OVERFLOW", "DEFAULT_BUFFER_BYTES"]

HDR = struct.Struct("<BqI")
DROPS = struct.Struct("<QQ")
DATA, LOST, OVERFLOW = 0, 1, 2
READ_SIZE = 65536
SEND_SIZE = 1 << 20
DEFAULT_BUFFER_BYTES = 256 << 20
"""Bytes a reader holds for a parent that is behind: minutes of a 921,600 baud link."""
DRAIN_QUIET_S = 0.1
"""At quit the device counts as drained once it has been this long without bytes."""
DRAIN_MAX_S = 1.0
"""At quit the drain ends after this long even if the device keeps sending."""


# --- the child ------------------------------------------------------------------------------

def _child(sock: socket.socket, max_buffer: int) -> int:
    return _Child(sock, max_buffer).run()


_HANGUP = select.POLLHUP | select.POLLERR | select.POLLNVAL


class _Child:
    """The reader process: the device's bytes, stamped at each read, into ``pending`` (at most
    ``max_buffer`` bytes; reads beyond are dropped and counted as one OVERFLOW record), sent to
    the parent whenever its socket takes them; control messages carry a new device descriptor
    or "Q" (quit: drain what the device holds, send everything, close)."""

    def __init__(self, sock: socket.socket, max_buffer: int):
        sock.setblocking(False)
        for opt in (getattr(socket, "SO_SNDBUFFORCE", None), socket.SO_SNDBUF):
            if opt is None:
                continue
            try:
                sock.setsockopt(socket.SOL_SOCKET, opt, 4 << 20)
                break
            except OSError:
                continue
        self.sock, self.max_buffer = sock, max_buffer
        self.pending = bytearray()
        self.dev = -1
        self.drop_n = self.drop_b = self.drop_t = 0
        self.poller = select.poll()
        self.sock_fd = sock.fileno()
        self.registered_out = False
        self.poller.register(self.sock_fd, select.POLLIN)

    def lost(self, why: str) -> None:
        self.poller.unregister(self.dev)
        try:
            os.close(self.dev)
        except OSError:
            pass
        self.dev = -1
        msg = why.encode("utf-8", "replace")[:500]
        self.pending.extend(HDR.pack(LOST, time.monotonic_ns(), len(msg)))
        self.pending.extend(msg)

    def read_dev(self, hup: bool) -> bool:
        """One read; False when nothing was there. A terminal in pyserial's raw mode (VMIN 0)
        reads nothing when nothing is waiting: only with a hang-up is that the end."""
        try:
            data = os.read(self.dev, READ_SIZE)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError as e:
            self.lost(f"read failed: {e.strerror or e}")
            return False
        t = time.monotonic_ns()
        if not data:
            if hup:
                self.lost("hang-up (device closed)")
            return False
        pending = self.pending
        if len(pending) + len(data) > self.max_buffer:
            if not self.drop_n:
                self.drop_t = t
            self.drop_n += 1
            self.drop_b += len(data)
            return True
        self.flush_drops()
        pending.extend(HDR.pack(DATA, t, len(data)))
        pending.extend(data)
        return True

    def flush_drops(self) -> None:
        if self.drop_n:
            self.pending.extend(HDR.pack(OVERFLOW, self.drop_t, DROPS.size))
            self.pending.extend(DROPS.pack(self.drop_n, self.drop_b))
            self.drop_n = self.drop_b = 0

    def on_socket(self, ev: int) -> str | None:
        """Send what the parent takes, read its control message: "gone" (the parent is gone or
        closed its end), "quit", or None."""
        if ev & select.POLLOUT and self.pending:
            try:
                n = self.sock.send(memoryview(self.pending)[:SEND_SIZE])
                del self.pending[:n]
            except (BlockingIOError, InterruptedError):
                pass
            except OSError as e:
                print(f"fdreader: send to the parent failed ({e}); stopping", file=sys.stderr)
                return "gone"
        if not ev & (select.POLLIN | select.POLLHUP | select.POLLERR):
            return None
        try:
            msg, fds, _, _ = socket.recv_fds(self.sock, 16, 4)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError:
            return "gone"
        if not msg:
            return "gone"
        for newfd in fds:
            if self.dev >= 0:
                self.poller.unregister(self.dev)
                os.close(self.dev)
            self.dev = newfd
            self.poller.register(newfd, select.POLLIN)
        return "quit" if b"Q" in msg else None

    def drain(self) -> None:
        """Read what the device still holds at quit: until it has been quiet for
        ``DRAIN_QUIET_S`` (at most ``DRAIN_MAX_S``; only ``poll`` waits, never the read). Bytes
        written before the quit can still be on their way through the kernel's terminal layer
        when it arrives (a pty moves them to the reader in steps, each a scheduling of its
        flush work away): a drain that stopped at the first empty poll lost whole writes on a
        loaded machine."""
        if self.dev < 0:
            return
        dev_poll = select.poll()
        dev_poll.register(self.dev, select.POLLIN)
        deadline = time.monotonic() + DRAIN_MAX_S
        while self.dev >= 0:
            left = deadline - time.monotonic()
            if left <= 0.0:
                break
            ev = next((e for _, e in dev_poll.poll(int(1000 * min(DRAIN_QUIET_S, left)) + 1)), 0)
            if not ev or not self.read_dev(bool(ev & _HANGUP)):
                break

    def run(self) -> int:
        quitting = False
        while not quitting:
            want_out = bool(self.pending)
            if want_out != self.registered_out:
                self.poller.modify(self.sock_fd, select.POLLIN | (select.POLLOUT if want_out else 0))
                self.registered_out = want_out
            try:
                events = self.poller.poll(200)
            except InterruptedError:
                continue
            for fd, ev in events:
                if fd == self.dev:
                    self.read_dev(bool(ev & _HANGUP))
                elif fd == self.sock_fd:
                    what = self.on_socket(ev)
                    if what == "gone":
                        return 0
                    quitting = quitting or what == "quit"
        self.drain()
        self.flush_drops()
        self.sock.setblocking(True)
        try:
            self.sock.sendall(self.pending)
            self.sock.shutdown(socket.SHUT_WR)
        except OSError as e:
            print(f"fdreader: the last {len(self.pending)} bytes were not sent ({e})",
                  file=sys.stderr)
        return 0


def main(argv=None) -> int:
    """``python -m vdps_hil.adapters.fdreader SOCKET_FD MAX_BUFFER_BYTES``"""
    argv = sys.argv[1:] if argv is None else argv
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sock = socket.socket(fileno=int(argv[0]))
    return _child(sock, int(argv[1]))


# --- the parent's handle --------------------------------------------------------------------

class FdReader:
    """The parent's side of one reader process.

    ``give(fd)`` hands a device descriptor to the child (again after a reconnect). ``take()``
    returns the records received so far without waiting, in order: ``(DATA, t_ns, bytes)``,
    ``(LOST, t_ns, reason)``, ``(OVERFLOW, t_ns, (chunks, bytes))``. ``stop()`` lets the child
    read what the device still holds and returns the last records. ``fileno()`` is readable
    when something came.
    """

    def __init__(self, name: str, max_buffer_bytes: int = DEFAULT_BUFFER_BYTES):
        self.name = name
        parent, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self.proc = subprocess.Popen(  # this file alone: standard library only, no site
                [sys.executable, "-I", "-S", os.path.abspath(__file__), str(child.fileno()),
                 str(int(max_buffer_bytes))],
                pass_fds=(child.fileno(),), stdin=subprocess.DEVNULL, close_fds=True)
        finally:
            child.close()
        self.sock = parent
        self.sock.setblocking(False)
        self._buf = bytearray()
        self._eof = False

    def fileno(self) -> int:
        return self.sock.fileno()

    def give(self, fd: int) -> None:
        socket.send_fds(self.sock, [b"F"], [fd])

    def _parse(self) -> list:
        buf = self._buf
        out = []
        pos, n = 0, len(buf)
        unpack = HDR.unpack_from
        hs = HDR.size
        while n - pos >= hs:
            kind, t_ns, length = unpack(buf, pos)
            end = pos + hs + length
            if end > n:
                break
            body = bytes(buf[pos + hs:end])
            if kind == LOST:
                body = body.decode("utf-8", "replace")
            elif kind == OVERFLOW:
                body = DROPS.unpack(body)
            out.append((kind, t_ns, body))
            pos = end
        del buf[:pos]
        return out

    def take(self, max_bytes: int = 8 << 20) -> list:
        """What the child sent so far (never waits)."""
        got = 0
        while got < max_bytes and not self._eof:
            try:
                b = self.sock.recv(SEND_SIZE)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._eof = True
                break
            if not b:
                self._eof = True
                break
            self._buf += b
            got += len(b)
        return self._parse()

    @property
    def alive(self) -> bool:
        return not self._eof and self.proc.poll() is None

    def stop(self, timeout_s: float = 5.0) -> list:
        """Ask the child to finish; returns the last records."""
        try:
            self.sock.send(b"Q")
        except OSError:
            pass
        t_end = time.monotonic() + timeout_s
        while not self._eof and time.monotonic() < t_end:
            select.select([self.sock], [], [], 0.05)
            try:
                b = self.sock.recv(SEND_SIZE)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                break
            if not b:
                break
            self._buf += b
        out = self._parse()
        self.close()
        return out

    def close(self) -> None:
        try:
            self.sock.close()
        except OSError:
            pass
        try:
            self.proc.wait(2.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


if __name__ == "__main__":
    sys.exit(main())
