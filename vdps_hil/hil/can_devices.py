"""The simulator's end of the CAN bus (:mod:`vdps_hil.hil.transports` says which ``--can``
value makes which): a python-can bus (``virtual``, an interface string), an slcan (Lawicel)
USB-CAN adapter emulated on a pseudo-terminal, or a socketcand server on 127.0.0.1. Each sends
the simulated frames without blocking (a device FIFO, :mod:`vdps_hil.hil.serial_device`), logs
their send times and hands back what the pipeline sends."""

from __future__ import annotations

import itertools
import os
import select
import socket
import threading
import time
from typing import Sequence

import numpy as np

from vdps_hil.adapters.base import AdapterError

from .serial_device import DEVICE_FIFO_BYTES, DeviceFifo, PtySerialDevice, SendLog

__all__ = ["CanDeviceSide", "VirtualCanDevice", "SlcanPtyDevice", "SocketcandServer", "ExternalCanDevice"]

_channel_ids = itertools.count()


class CanDeviceSide:
    """The simulator's end of the CAN bus.

    ``send_frames(ids, dlcs, data, stamps_s=None)``: frames in order (``data`` (N, 8) uint8, the
    first DLC bytes of each row); returns how many were accepted (the rest dropped and counted).
    ``stamps_s``: each frame's time on the bus (wall clock, s) for interfaces that carry a
    time stamp to the receiver (virtual, socketcand): what a hardware time stamp says, the time
    the frame was scheduled on the simulated bus, even when the sender was late (late sends are
    counted by the pacer). Without it, the time of sending.
    ``poll(timeout_s)``: frames the pipeline sent since the last call (waiting up to
    ``timeout_s`` for the first), as ``[(mono_ns, can.Message)]`` stamped on arrival.
    ``pipeline_spec``: the interface string the pipeline's CanAdapter opens.
    ``in_process``: the pipeline must run in this process (python-can's virtual bus)."""

    kind = "?"
    in_process = False
    pipeline_spec = ""

    def __init__(self):
        self.log = SendLog()
        self.dropped = 0
        self.frames_received = 0

    def open(self) -> None:
        """Before the bench clock starts. python-can is imported here: its first import (0.5-1 s,
        it loads its whole I/O package) would otherwise happen when the pipeline's first frame
        comes back (``_message``), holding the interpreter lock mid-run (late sends)."""
        import can  # noqa: F401

    def send_frames(self, ids: Sequence[int], dlcs: Sequence[int], data: np.ndarray,
                    stamps_s: Sequence[float] | None = None) -> int:
        raise NotImplementedError

    def poll(self, timeout_s: float = 0.0) -> list:
        return []

    def pump(self) -> None:
        pass

    def close(self) -> None:
        pass

    def describe(self) -> dict:
        return {"kind": self.kind, "pipeline_spec": self.pipeline_spec, "in_process": self.in_process}


def _message(aid: int, dlc: int, payload: bytes, *, rx: bool = True, timestamp: float = 0.0):
    import can

    return can.Message(timestamp=timestamp, arbitration_id=aid, dlc=dlc, data=payload, is_extended_id=False,
                       is_rx=rx, check=False)


class _PythonCanDevice(CanDeviceSide):
    """A device side that is itself a python-can bus (virtual, socketcan, hardware)."""

    def __init__(self):
        super().__init__()
        self.bus = None

    def send_frames(self, ids, dlcs, data, stamps_s=None) -> int:
        import can

        raw = np.ascontiguousarray(data, dtype=np.uint8).tobytes()
        bus = self.bus
        n = 0
        for j, (aid, dlc) in enumerate(zip(ids, dlcs)):
            ts = float(stamps_s[j]) if stamps_s is not None else 0.0
            try:
                bus.send(_message(aid, dlc, raw[8 * j:8 * j + dlc], timestamp=ts), timeout=0.0)
            except (can.CanOperationError, OSError):
                self.dropped += 1
                continue
            n += 1
        self.log.add(n, time.monotonic_ns())
        return n

    def poll(self, timeout_s: float = 0.0) -> list:
        out = []
        bus = self.bus
        if bus is None:  # closed
            return out
        timeout = timeout_s
        while True:
            msg = bus.recv(timeout)
            timeout = 0.0
            if msg is None:
                break
            out.append((time.monotonic_ns(), msg))
        self.frames_received += len(out)
        return out

    def close(self) -> None:
        if self.bus is not None:
            try:
                self.bus.shutdown()
            finally:
                self.bus = None


class VirtualCanDevice(_PythonCanDevice):
    """python-can's ``virtual`` bus on a fresh channel (``vdps-hil-<pid>-<n>``): reliable,
    ordered, unbounded queues; the pipeline must be in this process."""

    kind = "virtual"
    in_process = True

    def __init__(self, channel: str | None = None):
        super().__init__()
        self.channel = channel or f"vdps-hil-{os.getpid()}-{next(_channel_ids)}"
        self.pipeline_spec = f"virtual:{self.channel}"

    def open(self) -> None:
        import can

        # the frames carry their time on the bus (send_frames' stamps) like hardware time stamps
        self.bus = can.Bus(interface="virtual", channel=self.channel, preserve_timestamps=True)

    def send_frames(self, ids, dlcs, data, stamps_s=None) -> int:
        if stamps_s is None:
            stamps_s = [time.time()] * len(ids)
        return super().send_frames(ids, dlcs, data, stamps_s)


class ExternalCanDevice(_PythonCanDevice):
    """Any python-can interface string for the simulator (``sim_spec``) while the pipeline opens
    ``spec`` (``hil.transports`` docstring)."""

    kind = "external"

    def __init__(self, spec: str, sim_spec: str | None = None):
        super().__init__()
        from vdps_hil.adapters.can_adapter import parse_can_spec

        self.pipeline_spec = spec
        self.sim_spec = sim_spec or spec
        parse_can_spec(spec)
        self._iface, self._channel, self._kw = parse_can_spec(self.sim_spec)
        self.in_process = self._iface == "virtual"

    def open(self) -> None:
        import logging

        import can

        lg = logging.getLogger("can")
        level = lg.level
        lg.setLevel(logging.ERROR)  # interface modules warn at import about optional libraries
        try:
            self.bus = can.Bus(interface=self._iface, channel=self._channel, **self._kw)
        except (can.CanError, OSError, ValueError, TypeError, ImportError) as e:
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise AdapterError(f"bench CAN {self.sim_spec}: cannot open: {msg}") from None
        finally:
            lg.setLevel(level)

    def describe(self) -> dict:
        return {**super().describe(), "sim_spec": self.sim_spec}


def _parse_slcan_line(line: bytes):
    """A ``t``/``T`` transmit command -> can.Message, else None."""
    try:
        s = line.decode("ascii")
        if s[:1] == "t":
            aid, dlc, off = int(s[1:4], 16), int(s[4]), 5
        elif s[:1] == "T":
            aid, dlc, off = int(s[1:9], 16), int(s[9]), 10
        else:
            return None
        data = bytes.fromhex(s[off:off + 2 * dlc])
        if len(data) != dlc or dlc > 8:
            return None
        import can

        return can.Message(arbitration_id=aid, data=data, dlc=dlc, is_extended_id=s[0] == "T",
                           is_rx=True, check=False)
    except (ValueError, IndexError, UnicodeDecodeError):
        return None


class SlcanPtyDevice(CanDeviceSide):
    """The simulator as an slcan (Lawicel) USB-CAN adapter on a pseudo-terminal.

    To the host: every received frame as ``tIIIL<hex>\\r`` (the format python-can's slcan
    interface parses); answers to commands (``O``, ``C``, ``S6``, ``L`` ...) ``\\r``; a
    transmit command ``tIIIL<hex>\\r`` is answered ``z\\r`` and handed to :meth:`poll` (the frame
    went onto the bus). Malformed command lines are counted ``bad_commands``."""

    kind = "pty"

    def __init__(self, fifo_bytes: int = DEVICE_FIFO_BYTES):
        super().__init__()
        self.dev = PtySerialDevice("can", fifo_bytes)
        self.pipeline_spec = f"slcan:{self.dev.port},sleep_after_open=0"
        self._rx = bytearray()
        self.bad_commands = 0

    def send_frames(self, ids, dlcs, data, stamps_s=None) -> int:  # slcan carries no time stamp
        hexes = np.ascontiguousarray(data, dtype=np.uint8).tobytes().hex().upper().encode()
        blob = b"".join([b"t%03X%d%s\r" % (aid, dlc, hexes[16 * j:16 * j + 2 * dlc])
                         for j, (aid, dlc) in enumerate(zip(ids, dlcs))])
        n = len(ids)
        if not n:
            return 0
        if not self.dev.send_unlogged(blob):  # the frames of one instant go together
            self.dropped += n
            return 0
        self.log.add(n, time.monotonic_ns())
        return n

    def pump(self) -> None:
        self.dev.pump()

    def poll(self, timeout_s: float = 0.0) -> list:
        data = self.dev.read(timeout_s)
        if not data:
            return []
        now = time.monotonic_ns()
        buf = self._rx
        buf += data
        out = []
        replies = bytearray()
        while True:
            i = buf.find(b"\r")
            if i < 0:
                break
            line = bytes(buf[:i])
            del buf[:i + 1]
            if line[:1] in (b"t", b"T"):
                msg = _parse_slcan_line(line)
                if msg is None:
                    self.bad_commands += 1
                    replies += b"\x07"
                else:
                    out.append((now, msg))
                    replies += b"z\r"
            else:
                replies += b"\r"
        if len(buf) > 4096:
            del buf[:]
            self.bad_commands += 1
        if replies:
            self.dev.send_unlogged(bytes(replies))
        self.frames_received += len(out)
        return out

    def close(self) -> None:
        self.dev.close()

    def describe(self) -> dict:
        return {**super().describe(), "port": self.dev.port}


class SocketcandServer(CanDeviceSide):
    """The simulator as a socketcand server (the ASCII protocol python-can's ``socketcand``
    interface speaks), listening on 127.0.0.1 only, on an ephemeral port, for one client.

    Handshake: ``< hi >``, then ``< open CHANNEL >`` -> ``< ok >``, ``< rawmode >`` -> ``< ok >``.
    Frames to the client: ``< frame III SECS.USECS HEX >``; from the client: ``< send III L B0 B1
    .. >`` (handed to :meth:`poll`). The accept and the handshake run in a thread; frames sent
    before a client is in raw mode are kept (up to the FIFO) and go out when it is."""

    kind = "tcp"
    HOST = "127.0.0.1"

    def __init__(self, channel: str = "vdps", fifo_bytes: int = DEVICE_FIFO_BYTES):
        super().__init__()
        self.channel = channel
        self._lsock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._lsock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._lsock.bind((self.HOST, 0))
        self._lsock.listen(1)
        self.port = self._lsock.getsockname()[1]
        self.pipeline_spec = f"socketcand:{channel},host={self.HOST},port={self.port},tcp_tune=true"
        self._conn: socket.socket | None = None
        self._ready = threading.Event()
        self._closed = False
        self._peer_closed = False
        self._pre = bytearray()
        self._fifo: DeviceFifo | None = None
        self._fifo_bytes = int(fifo_bytes)
        self._rx = bytearray()
        self.bad_commands = 0
        self.handshake_error = ""
        self._thread = threading.Thread(target=self._accept, name="socketcand-accept", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        try:
            self._lsock.settimeout(60.0)
            conn, _ = self._lsock.accept()
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.settimeout(10.0)
            conn.sendall(b"< hi >")
            for expect, reply in ((b"< open ", b"< ok >"), (b"< rawmode >", b"< ok >")):
                got = conn.recv(256)
                if not got.startswith(expect):
                    self.handshake_error = f"expected {expect!r}, got {got[:40]!r}"
                    conn.close()
                    return
                conn.sendall(reply)
            conn.setblocking(False)
            self._conn = conn
            self._fifo = DeviceFifo(conn.send, self._fifo_bytes)
            self._ready.set()
        except OSError as e:
            if not self._closed:
                self.handshake_error = str(e) or type(e).__name__

    def wait_client(self, timeout_s: float) -> bool:
        return self._ready.wait(timeout_s)

    def send_frames(self, ids, dlcs, data, stamps_s=None) -> int:
        raw = np.ascontiguousarray(data, dtype=np.uint8).tobytes()
        hexes = raw.hex().encode()
        if stamps_s is None:
            stamps_s = [time.time()] * len(ids)
        us = [divmod(int(round(ts * 1e6)), 1_000_000) for ts in stamps_s]  # (s, us) of each frame
        blob = b"".join([b"< frame %03X %d.%06d %s >" % (aid, sec, usec, hexes[16 * j:16 * j + 2 * dlc])
                         for j, (aid, dlc, (sec, usec)) in enumerate(zip(ids, dlcs, us))])
        n = len(ids)
        if not n:
            return 0
        fifo = self._fifo
        if fifo is None:  # no client yet: keep (bounded), as an adapter's buffer would
            if len(self._pre) + len(blob) > self._fifo_bytes:
                self.dropped += n
                return 0
            self._pre += blob
        else:
            if self._pre:
                fifo.send(bytes(self._pre))
                self._pre.clear()
            if not fifo.send(blob):
                self.dropped += n
                return 0
        self.log.add(n, time.monotonic_ns())
        return n

    def pump(self) -> None:
        if self._fifo is not None:
            if self._pre:
                self._fifo.send(bytes(self._pre))
                self._pre.clear()
            self._fifo.pump()

    def poll(self, timeout_s: float = 0.0) -> list:
        conn = self._conn
        if conn is None:
            if timeout_s > 0:
                self._ready.wait(timeout_s)
            return []
        if self._peer_closed:  # readable for ever after the client's close: never a busy loop
            if timeout_s > 0:
                time.sleep(timeout_s)
            return []
        try:
            r, _, _ = select.select([conn], [], [], timeout_s)
            data = conn.recv(65536) if r else None
            if data == b"":  # end of stream: the pipeline closed its side
                self._peer_closed = True
        except (BlockingIOError, InterruptedError):
            data = b""
        except OSError:
            data = b""
        if not data:
            return []
        now = time.monotonic_ns()
        buf = self._rx
        buf += data
        out = []
        while True:
            a = buf.find(b"<")
            b = buf.find(b">", a + 1) if a >= 0 else -1
            if a < 0 or b < 0:
                break
            body = bytes(buf[a + 1:b]).split()
            del buf[:b + 1]
            msg = None
            if len(body) >= 3 and body[0] == b"send":
                try:
                    aid, dlc = int(body[1], 16), int(body[2], 16)
                    payload = bytes(int(x, 16) for x in body[3:3 + dlc])
                    if len(payload) == dlc <= 8:
                        msg = _message(aid, dlc, payload)
                except ValueError:
                    msg = None
            if msg is None:
                self.bad_commands += 1
            else:
                out.append((now, msg))
        if len(buf) > 4096:
            del buf[:]
            self.bad_commands += 1
        self.frames_received += len(out)
        return out

    def close(self) -> None:
        self._closed = True
        for s in (self._conn, self._lsock):
            if s is not None:
                try:
                    s.close()
                except OSError:
                    pass

    def describe(self) -> dict:
        return {**super().describe(), "listen": f"{self.HOST}:{self.port}"}

