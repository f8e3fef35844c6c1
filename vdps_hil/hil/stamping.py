"""How the bench's pipeline stamps what it reads: CAN frames by the interface's own time stamp,
serial messages by the device's own clock, both on the bench clock (``hil.node``'s docstring)."""

from __future__ import annotations

from vdps_hil.adapters.can_adapter import CanAdapter
from vdps_hil.bus.clocks import wall_minus_monotonic_ns

__all__ = ["InterfaceTimeCanAdapter", "DeviceTimeProtocol"]


class InterfaceTimeCanAdapter(CanAdapter):
    """A CanAdapter that stamps each frame with the interface's own time stamp (``msg.timestamp``:
    when the frame was on the bus -- python-can's virtual bus stamps at send, the bench's
    socketcand server at send, SocketCAN in the kernel at reception), mapped onto the bench clock,
    as a logger with hardware time stamps does. Without it a reader thread held up by the pipeline
    (Python's GIL) gives a whole burst of frames one late host time, and the estimator sees 20 ms of
    suspension samples at one instant. A stamp is never later than the host's reception nor earlier
    than the previous frame's or the bench's start; slcan stamps at host reception."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self._wall_minus_mono_ns = wall_minus_monotonic_ns()
        self._last_stamp = None

    def _read(self, timeout_s: float):
        items = super()._read(timeout_s)
        if not items:
            return items
        clock = self.clock
        now = clock.now_ns()
        last = self._last_stamp
        out = []
        for _, msg in items:
            ts = msg.timestamp
            t = clock.t_of(int(ts * 1e9) - self._wall_minus_mono_ns) if ts else now
            t = now if t > now else t
            t = t if t > 0 else 0  # sent at the start, stamped early by the two clock offsets
            if last is not None and t < last:
                t = last
            last = t
            out.append((t, msg))
        self._last_stamp = last
        return out


class DeviceTimeProtocol:
    """A serial protocol (``adapters.serial_adapter``) that stamps each message by the device's
    own clock mapped onto the host's -- the IMU's SampleTimeFine, the GNSS sentences' UTC --
    exactly as ``vdps replay`` does (``record.decode``: leaky running minimum of host minus
    device time, clock steps confirmed before they are believed). The receive-time rule alone
    makes a GNSS fix 6-20 ms late (the sentences' own wire time at 115200 Bd) and lets a late
    read chunk compress the IMU's stamps; with the devices' clocks the live pipeline sees the
    same times as a replay of the recording."""

    def __init__(self, stream, fmt: str):
        self.stream = stream
        self.fmt = fmt

    def feed(self, t_ns: int, chunk: bytes) -> list:
        return self.stream.feed(t_ns, chunk)

    def flush(self) -> list:
        return self.stream.feed(0, None)

    def reset(self) -> None:
        framer = getattr(self.stream, "framer", None)
        if framer is not None:
            framer.flush()

    def counters(self) -> dict:
        return self.stream.counters()

    def clock_status(self) -> dict:
        return self.stream.clock_status()
