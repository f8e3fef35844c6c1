"""Bench transports: the wires between the simulated vehicle and the pipeline.

The simulator's end of every wire is a *device side* (it plays the sensors and, on CAN, the
bus); the pipeline's end is what a real logger would open: a python-can interface string for
:class:`~vdps_hil.adapters.can_adapter.CanAdapter` and serial port paths for the IMU and GNSS
adapters. Serial always goes through real pseudo-terminals (``os.openpty``): the pipeline's
``ImuAdapter``/``NmeaAdapter`` open ``/dev/pts/N`` exactly as they would open
``/dev/ttyUSB0``.

CAN transports (``--can SPEC``)
-------------------------------
==================  ====================================================================  =========
SPEC                simulator side / pipeline side                                         process
==================  ====================================================================  =========
``virtual``         python-can ``virtual`` bus on a fresh channel / ``virtual:<channel>``  one
(default)
``pty``             the simulator is an slcan (Lawicel) USB-CAN adapter on a pty: frames  two
                    go out as ``tIIILDD..\\r`` lines, the pipeline's ``t080..`` transmit
                    commands come back (answered ``z\\r``) / ``slcan:/dev/pts/N``
``tcp``             the simulator is a socketcand server bound to 127.0.0.1 (an ephemeral  two
                    port; loopback only) / ``socketcand:vdps,host=127.0.0.1,port=P``
``IFACE:CHANNEL``   both sides open ``IFACE:CHANNEL[,key=value..]`` through python-can    one
[,key=value...]     (``socketcan:vcan0``, ``virtual:NAME``); with ``sim_spec`` the
                    simulator opens another interface (two adapters wired together:
                    ``pcan:PCAN_USBBUS1`` for the pipeline, ``kvaser:0`` for the simulator)
==================  ====================================================================  =========

``socketcan:vcan0`` needs a Linux kernel with vcan (``ip link add dev vcan0 type vcan; ip
link set up vcan0``); this project's CI machine has none, so that row is documented, not
tested. Two SocketCAN sockets on one interface see each other's frames (the kernel's loopback),
which is what makes the one-interface form work.

The device sides: :mod:`vdps_hil.hil.can_devices` (CAN) and :mod:`vdps_hil.hil.serial_device`
(serial ptys, the device FIFO and the send log: writes never block the simulator; a full FIFO
drops whole messages and counts them; every accepted write is logged for the latency
measurement).
"""

from __future__ import annotations

import os

from vdps_hil.adapters.base import AdapterError

from .can_devices import CanDeviceSide, ExternalCanDevice, SlcanPtyDevice, SocketcandServer, VirtualCanDevice

__all__ = ["TransportSpec", "parse_transport", "NAMED_TRANSPORTS", "listening_sockets"]

NAMED_TRANSPORTS = ("virtual", "pty", "tcp")
"""Transport names of ``--can`` besides python-can interface strings (module docstring)."""


class TransportSpec:
    """A parsed ``--can`` value: ``name`` (``virtual``, ``pty``, ``tcp`` or ``external``),
    ``spec``/``sim_spec`` for python-can interface strings; ``make()`` builds the device side;
    ``cross_process``: the pipeline runs in a child process."""

    def __init__(self, name: str, spec: str | None = None, sim_spec: str | None = None):
        self.name, self.spec, self.sim_spec = name, spec, sim_spec

    @property
    def cross_process(self) -> bool:
        return self.name in ("pty", "tcp")

    def make(self) -> CanDeviceSide:
        if self.name == "virtual":
            return VirtualCanDevice()
        if self.name == "pty":
            return SlcanPtyDevice()
        if self.name == "tcp":
            return SocketcandServer()
        return ExternalCanDevice(self.spec, self.sim_spec)

    def __repr__(self) -> str:
        return f"TransportSpec({self.name!r}, {self.spec!r}, {self.sim_spec!r})"


def parse_transport(spec: str | None, sim_spec: str | None = None) -> TransportSpec:
    """``--can`` value -> :class:`TransportSpec`; AdapterError (one line) when malformed."""
    from vdps_hil.adapters.can_adapter import parse_can_spec

    s = (spec or "virtual").strip()
    if s in NAMED_TRANSPORTS:
        if sim_spec:
            raise AdapterError(f"--sim-can applies to an interface string, not to --can {s}")
        return TransportSpec(s)
    parse_can_spec(s)
    if sim_spec:
        parse_can_spec(sim_spec)
    return TransportSpec("external", s, sim_spec)


def listening_sockets(pid: int | None = None) -> list[tuple[str, int]]:
    """``[(address, port)]`` of the TCP sockets in LISTEN state (and bound UDP sockets) owned by
    process ``pid`` (default: this one), read from ``/proc/<pid>/fd`` and ``/proc/net/{tcp,tcp6,
    udp,udp6}``; empty for a process that has ended. IPv4 addresses as dotted quads, IPv6 as
    ``[hex]``."""
    pid = os.getpid() if pid is None else int(pid)
    inodes = set()
    fd_dir = f"/proc/{pid}/fd"
    try:
        fds = os.listdir(fd_dir)
    except OSError:  # the process has ended: it listens on nothing
        return []
    for fd in fds:
        try:
            target = os.readlink(os.path.join(fd_dir, fd))
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    out = []
    for table, listen_state in (("tcp", "0A"), ("tcp6", "0A"), ("udp", "07"), ("udp6", "07")):
        try:
            with open(f"/proc/{pid}/net/{table}") as f:
                rows = f.read().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            parts = row.split()
            if len(parts) < 10 or parts[3] != listen_state or parts[9] not in inodes:
                continue
            addr_hex, port_hex = parts[1].split(":")
            if len(addr_hex) == 8:
                addr = ".".join(str(b) for b in bytes.fromhex(addr_hex)[::-1])
            else:
                words = [bytes.fromhex(addr_hex[i:i + 8])[::-1] for i in range(0, 32, 8)]
                raw = b"".join(words)
                if raw[:12] == b"\0" * 10 + b"\xff\xff":
                    addr = ".".join(str(b) for b in raw[12:])
                else:
                    addr = "[" + raw.hex() + "]"
            out.append((addr, int(port_hex, 16)))
    return out
