"""Raw events on the bus: what a device gave, before decoding -- a CAN frame (:class:`RawCan`)
or a chunk of serial bytes (:class:`RawSerial`), stamped with ``t_ns`` (monotonic, orders
events) and ``wall_time_ns`` (MCAP ``log_time``) by the adapter that read it. The recording
keeps them byte for byte (``/raw/``); the decoders turn them into
:class:`~vdps_hil.bus.samples.Sample` objects."""

from __future__ import annotations

from typing import Any

__all__ = ["RawCan", "RawSerial"]


class RawCan:
    """A received (or sent) CAN frame: ``msg`` is the ``can.Message`` as the interface gave it;
    ``device_time_ns`` the interface's own time stamp (``msg.timestamp``) in ns, or None."""

    __slots__ = ("t_ns", "wall_time_ns", "source", "msg", "direction", "device_time_ns")

    def __init__(self, t_ns: int, wall_time_ns: int, source: str, msg: Any,
                 direction: str = "rx", device_time_ns: int | None = None):
        self.t_ns, self.wall_time_ns, self.source = t_ns, wall_time_ns, source
        self.msg, self.direction, self.device_time_ns = msg, direction, device_time_ns

    def __repr__(self) -> str:
        return (f"RawCan({self.source} t={self.t_ns} id=0x{self.msg.arbitration_id:X} "
                f"data={bytes(self.msg.data).hex()})")


class RawSerial:
    """One chunk of bytes as one read returned them (``t_ns`` = when the read returned)."""

    __slots__ = ("t_ns", "wall_time_ns", "source", "data", "baud", "fmt")

    def __init__(self, t_ns: int, wall_time_ns: int, source: str, data: bytes,
                 baud: int | None = None, fmt: str | None = None):
        self.t_ns, self.wall_time_ns, self.source = t_ns, wall_time_ns, source
        self.data, self.baud, self.fmt = data, baud, fmt

    def __repr__(self) -> str:
        return f"RawSerial({self.source} t={self.t_ns} {len(self.data)} B)"
