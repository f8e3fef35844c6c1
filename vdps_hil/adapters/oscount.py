"""The OS's own loss counters of a serial device: what the driver dropped before any read.

Linux serial drivers answer ``ioctl(fd, TIOCGICOUNT)`` with ``struct serial_icounter_struct``
(``include/uapi/linux/serial.h``: cts, dsr, rng, dcd, rx, tx, frame, overrun, parity, brk,
buf_overrun, 9 reserved ints). ``overrun`` counts bytes the UART's FIFO lost, ``buf_overrun``
bytes the driver's buffer lost; ``frame``/``parity`` bytes received with errors. USB serial
adapters whose driver keeps them (ftdi_sio, cdc-acm, ...) answer too; a pseudo-terminal does
not (``ENOTTY``), and then the health says why the OS's counters are unknown.
"""

from __future__ import annotations

import fcntl
import os
import struct

__all__ = ["TIOCGICOUNT", "ICOUNT_FIELDS", "serial_icount", "OsCounters"]

TIOCGICOUNT = 0x545D
"""Linux ``ioctl`` reading a serial driver's ``struct serial_icounter_struct``."""
_ICOUNT = struct.Struct("<20i")  # cts dsr rng dcd rx tx frame overrun parity brk buf_overrun + 9
ICOUNT_FIELDS = {"os_frame_errors": 6, "os_overrun": 7, "os_parity_errors": 8, "os_breaks": 9,
                 "os_buf_overrun": 10}
"""Counters of ``serial_icounter_struct`` kept (name -> index): ``overrun`` is the UART's FIFO
overrun, ``buf_overrun`` the driver's buffer overrun (bytes lost before any read)."""


def serial_icount(fd: int) -> dict[str, int] | str:
    """The serial driver's error counters of ``fd`` (:data:`ICOUNT_FIELDS`), or why they are
    not available (a pseudo-terminal, a USB adapter whose driver has no ``TIOCGICOUNT``)."""
    try:
        raw = fcntl.ioctl(fd, TIOCGICOUNT, bytes(_ICOUNT.size))
    except OSError as e:
        return f"unavailable ({os.strerror(e.errno) if e.errno else e})"
    v = _ICOUNT.unpack(raw)
    return {k: v[i] for k, i in ICOUNT_FIELDS.items()}


class OsCounters:
    """The OS's loss counters of one open descriptor as deltas since it was opened, added to
    an adapter's health (``os_overrun`` ...), or the reason they are unknown in
    ``health.os_counters``."""

    def __init__(self, health):
        self.health = health
        self._base: dict[str, int] | None = None
        self._fd = -1

    def update(self, fd: int | None) -> None:
        h = self.health
        if fd is None:
            return
        now = serial_icount(fd)
        if isinstance(now, str):
            h.os_counters = now
            return
        h.os_counters = "yes"
        if fd != self._fd or self._base is None:  # opened (again): counts start here
            self._fd, self._base = fd, now
            return
        for k, v in now.items():
            d = v - self._base[k]
            if d > 0:
                h.count(k, d)
        self._base = now
