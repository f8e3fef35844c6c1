"""Serial adapters: a live port through pyserial, and a recorded byte stream from a file.

Reading: whatever is waiting is read in one call (``in_waiting`` then ``read(n)``; when nothing
is waiting, ``read(1)`` blocks up to the poll timeout and the rest that arrived meanwhile is
read with it). pyserial's ``readline()`` is never used: it reads one byte per call and cannot
keep up with a 921600 baud IMU. Each chunk is one raw record (``/raw/serial/<name>``) stamped
with the host time at which the read returned; the protocol object frames and decodes it
(receive-time rule of :mod:`vdps_hil.codecs.framing`).

A device that disappears (USB unplugged, pty closed: the read fails) is closed and reopened
every ``reconnect_s`` until it is back; the outage is counted (``outages``, ``reconnects``,
``outage_s``) and the protocol's partial-line state is dropped so nothing from before the
outage is glued to what follows.

A *serial protocol* is any object with ``fmt`` (a short name such as ``nmea`` or ``imu``),
``feed(t_ns, chunk) -> list[Sample]``, a ``counters`` mapping and ``reset()`` (drop partial
input after an outage). Sequence-counter gaps are the protocol's to count (``seq_gaps``).

Port strings are ``PORT[@BAUD]``: ``/dev/ttyUSB0@115200``, ``COM4@921600``, or a pyserial URL
(``socket://127.0.0.1:5000``, ``loop://``).
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Sequence

from vdps_hil.adapters.base import Adapter, AdapterError, DeviceLost, EndOfInput
from vdps_hil.bus.clocks import ReplayClock
from vdps_hil.bus.raw import RawSerial
from vdps_hil.codecs.framing import transmission_time_ns

__all__ = ["SerialAdapter", "SerialFileAdapter", "parse_port_spec", "DEFAULT_BAUD"]

DEFAULT_BAUD = 115200
MAX_CHUNK = 65536


def parse_port_spec(spec: str, default_baud: int = DEFAULT_BAUD) -> tuple[str, int]:
    """``"/dev/ttyUSB0@921600"`` -> ``("/dev/ttyUSB0", 921600)``; AdapterError on a bad baud."""
    if not isinstance(spec, str) or not spec.strip():
        raise AdapterError(f"serial port {spec!r} is empty")
    port, baud = spec, default_baud
    if "@" in spec:
        port, b = spec.rsplit("@", 1)
        try:
            baud = int(b)
        except ValueError:
            raise AdapterError(f"serial port {spec!r}: baud {b!r} is not an integer") from None
        if baud <= 0:
            raise AdapterError(f"serial port {spec!r}: baud must be positive")
    if not port:
        raise AdapterError(f"serial port {spec!r} has no port")
    return port, baud


class _SerialBase(Adapter):
    transport = "serial"

    def __init__(self, name: str, device: str, baud: int, protocol, **kw):
        super().__init__(name, device, **kw)
        self.baud = int(baud)
        self.protocol = protocol
        self._fmt = getattr(protocol, "fmt", None)

    def _raw(self, t_ns, wall_time_ns, data):
        return RawSerial(t_ns, wall_time_ns, self.name, data, self.baud, self._fmt)

    def _decode(self, t_ns, data):
        if self.protocol is None:
            return ()
        return self.protocol.feed(t_ns, data)

    def decoder_counters(self):
        c = getattr(self.protocol, "counters", None)
        if c is None:
            return {}
        return c() if callable(c) else c

    def _on_lost(self) -> None:
        reset = getattr(self.protocol, "reset", None)
        if reset is not None:
            reset()


class SerialAdapter(_SerialBase):
    """A live serial device. ``port`` is a path or pyserial URL; ``protocol`` decodes it
    (None: raw only). Options of ``serial.serial_for_url`` may be passed as
    ``serial_kwargs``.

    Message times follow the receive-time rule, which back-dates a message by the wire time of
    the bytes after it in its chunk. A link faster than its nominal baud (a pseudo-terminal,
    a USB adapter delivering a burst) can make that earlier than the previous message of the
    same stream, which cannot be: such a time is raised to the previous one (counted
    ``time_clamped``, not an error), so live samples of a device never go backwards.

    A device path is opened for exclusive access (pyserial's ``exclusive``: an advisory lock
    that every other exclusive opener respects), so two readers never share a port and each
    silently lose the bytes the other read -- e.g. an adapter reconnecting by path to a
    pseudo-terminal whose number the kernel has since given to another device (the likely cause,
    not proven, of a test run that lost 80 % of a pty's bytes). ``serial_kwargs={"exclusive":
    False}`` shares it.
    """

    def __init__(self, name: str, port: str, baud: int = DEFAULT_BAUD, protocol=None, *,
                 serial_kwargs: dict | None = None, **kw):
        super().__init__(name, f"{port}@{baud}", baud, protocol, **kw)
        self.port = port
        self.serial_kwargs = dict(serial_kwargs or {})
        self.ser = None
        self._last_sample_t = -1

    def _decode(self, t_ns, data):
        out = super()._decode(t_ns, data)
        if not out:
            return out
        last = self._last_sample_t
        fixed = []
        for s in out:
            if s.t_ns < last:
                s = dataclasses.replace(s, t_ns=last)
                self.health.count("time_clamped")
            last = s.t_ns
            fixed.append(s)
        self._last_sample_t = last
        return fixed

    def _open(self) -> None:
        import serial

        kw = dict(self.serial_kwargs)
        if "://" not in self.port:  # a device path: this adapter is its only reader (docstring)
            kw.setdefault("exclusive", True)
        try:
            self.ser = serial.serial_for_url(self.port, baudrate=self.baud, timeout=0.05, **kw)
        except (serial.SerialException, OSError, ValueError) as e:
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            if self.health.state == "closed":
                raise AdapterError(f"serial {self.name}: cannot open {self.port}: {msg}") \
                    from None
            raise DeviceLost(msg) from None

    def _close(self) -> None:
        if self.ser is not None:
            try:
                self.ser.close()
            finally:
                self.ser = None

    def reader_fd(self) -> int | None:
        """The port's descriptor when pyserial opened a POSIX device (a reader process drains
        it); None for URL handlers (``socket://``, ``loop://``: a reader thread)."""
        try:
            from serial.serialposix import Serial
        except ImportError:  # not a POSIX system
            return None
        if isinstance(self.ser, Serial) and self.ser.fd is not None:
            return self.ser.fd
        return None

    def _read(self, timeout_s: float) -> Sequence[tuple[int | None, Any]]:
        import serial

        ser = self.ser
        try:
            n = ser.in_waiting
            if n:
                data = ser.read(min(n, MAX_CHUNK))
            else:
                if ser.timeout != timeout_s:
                    ser.timeout = timeout_s
                data = ser.read(1)
                if not data:
                    return ()
                n = ser.in_waiting
                if n:
                    data += ser.read(min(n, MAX_CHUNK))
        except (serial.SerialException, OSError, TypeError, AttributeError) as e:
            raise DeviceLost(str(e).splitlines()[0] if str(e) else type(e).__name__) from None
        if not data:
            return ()
        self.health.bytes += len(data)
        return [(None, bytes(data))]


class SerialFileAdapter(_SerialBase):
    """A recorded byte stream (a binary capture of a serial device, no time stamps), replayed
    in chunks of ``chunk`` bytes. The time of a chunk is the wire time of the bytes up to its
    end at ``baud`` (8N1) after ``t0_ns``: ``t = t0_ns + (offset + len) * 10 / baud``."""

    def __init__(self, name: str, path: str | os.PathLike, baud: int = DEFAULT_BAUD,
                 protocol=None, *, t0_ns: int = 0, chunk: int = 4096, **kw):
        kw.setdefault("clock", ReplayClock())
        super().__init__(name, os.fspath(path), baud, protocol, **kw)
        self.path = os.fspath(path)
        self.t0_ns = int(t0_ns)
        self.chunk = int(chunk)
        self._f = None
        self._offset = 0

    def _open(self) -> None:
        try:
            self._f = open(self.path, "rb")
        except OSError as e:
            raise AdapterError(f"serial file {self.path}: {e.strerror or e}") from None

    def _close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def _flush_decoder(self):
        flush = getattr(self.protocol, "flush", None)
        return flush() if flush is not None else ()

    def _read(self, timeout_s: float) -> Sequence[tuple[int | None, Any]]:
        data = self._f.read(self.chunk) if self._f is not None else b""
        if not data:
            raise EndOfInput()
        self._offset += len(data)
        self.health.bytes += len(data)
        return [(self.t0_ns + transmission_time_ns(self._offset, self.baud), data)]
