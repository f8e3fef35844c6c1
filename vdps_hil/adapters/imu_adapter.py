"""The serial IMU (Xsens MTi ``MTData2`` binary, :mod:`vdps_hil.codecs.imu_mtdata2`): live port
and recorded byte stream.

:class:`ImuProtocol` wraps :class:`~vdps_hil.codecs.imu_decoder.ImuDecoder` (message hunting,
checksum, receive-time rule at the port's baud, packet-counter gaps counted as ``seq_gaps``) as a
serial protocol; :class:`ImuAdapter` is a :class:`~vdps_hil.adapters.serial_adapter.SerialAdapter`
with it (default 921600 baud, 1 kHz ``imu`` samples of specific force [m/s^2] and angular rate
[rad/s] in the body frame). ``sensor_to_body`` is the mounting's signed permutation.
"""

from __future__ import annotations

import os

from vdps_hil.adapters.serial_adapter import SerialAdapter, SerialFileAdapter
from vdps_hil.codecs.imu_decoder import ImuDecoder
from vdps_hil.codecs.imu_mtdata2 import DEFAULT_BAUD, SENSOR_TO_BODY

__all__ = ["ImuProtocol", "ImuAdapter", "ImuFileAdapter", "DEFAULT_BAUD"]


class ImuProtocol:
    """The MTi stream of one device as a serial protocol."""

    fmt = "xsens-mtdata2"

    def __init__(self, source: str = "imu", baud: int = DEFAULT_BAUD,
                 sensor_to_body=SENSOR_TO_BODY):
        self.source = source
        self.baud = int(baud)
        self.sensor_to_body = sensor_to_body
        self.decoder = ImuDecoder(source, baud=self.baud, sensor_to_body=sensor_to_body)

    def feed(self, t_ns: int, chunk: bytes) -> list:
        return self.decoder.feed(t_ns, chunk)

    def flush(self) -> list:
        """End of a recorded stream: release what the decoder still holds."""
        return self.decoder.flush()

    def reset(self) -> None:
        """Forget a partial message after an outage (a new decoder keeps nothing of the old
        stream; counters carry over)."""
        old = self.decoder
        self.decoder = ImuDecoder(self.source, baud=self.baud, sensor_to_body=self.sensor_to_body)
        self._carry = dict(old.counters) if not hasattr(self, "_carry") else \
            {k: v + self._carry.get(k, 0) for k, v in old.counters.items()}

    @property
    def counters(self) -> dict[str, int]:
        c = dict(self.decoder.counters)
        for k, v in getattr(self, "_carry", {}).items():
            c[k] = c.get(k, 0) + v
        return c


class ImuAdapter(SerialAdapter):
    """A live MTi on a serial port; samples' source = ``name``."""

    def __init__(self, name: str, port: str, baud: int = DEFAULT_BAUD, *,
                 sensor_to_body=SENSOR_TO_BODY, **kw):
        super().__init__(name, port, baud, ImuProtocol(name, baud, sensor_to_body), **kw)


class ImuFileAdapter(SerialFileAdapter):
    """A binary capture of an MTi stream (no time stamps: wire time at ``baud``)."""

    def __init__(self, name: str, path: str | os.PathLike, baud: int = DEFAULT_BAUD, *,
                 sensor_to_body=SENSOR_TO_BODY, **kw):
        super().__init__(name, path, baud, ImuProtocol(name, baud, sensor_to_body), **kw)
