"""python-can plugins for ``.mcap``: ``can.Logger("x.mcap")`` and ``can.LogReader("x.mcap")``.

Registered through python-can's entry point groups (python-can >= 4.2 reads them in
``can.io.logger._update_writer_plugins`` and ``can.io.player._update_reader_plugins``, keyed by
the suffix)::

    [project.entry-points."can.io.message_writer"]
    ".mcap" = "vdps_hil.record.can_io:McapCanWriter"
    [project.entry-points."can.io.message_reader"]
    ".mcap" = "vdps_hil.record.can_io:McapCanReader"

so python-can's own tools work with our recordings: ``python -m can.logger -f x.mcap``,
``python -m can.player x.mcap``, ``python -m can.logconvert x.mcap x.asc``.

Writer: each message goes to ``/raw/can/<bus>`` of our layout (``bus`` = the message's
``channel`` made a valid name, or the ``bus`` argument when the message has none), with
``t_ns = round(timestamp * 1e9)`` (clamped at 0) and ``log_time`` the same (python-can's
time stamps are seconds since the epoch for live interfaces). Reader: the frames of every
``/raw/can/...`` topic in ``t_ns`` order, ``timestamp = t_ns / 1e9``, ``channel`` = the bus
name; a file cut off by a crash reads as far as its complete chunks go.
"""

from __future__ import annotations

import os
from typing import Any, Iterator

from can.io.generic import MessageReader, SizedMessageWriter

__all__ = ["McapCanWriter", "McapCanReader"]


def _bus_name(channel: Any, default: str) -> str:
    if channel is None or channel == "":
        return default
    name = "".join(c if c.isalnum() or c in "_.:-" else "_" for c in str(channel))
    return name or default


class McapCanWriter(SizedMessageWriter):
    """A python-can message writer producing a vdps recording (MCAP)."""

    def __init__(self, file, bus: str = "can", metadata: dict | None = None, **kwargs: Any):
        from vdps_hil.record.writer import RecordingWriter

        if kwargs.get("append"):
            raise ValueError("MCAP recordings cannot be appended to; write a new file")
        self.bus = bus
        md = {"mode": "python-can"}
        md.update(metadata or {})
        self._writer = RecordingWriter(file, metadata=md)
        self._stream = self._writer._stream
        self.messages = 0
        self.skipped = 0

    def on_message_received(self, msg) -> None:
        t = msg.timestamp or 0.0
        t_ns = max(0, int(round(t * 1e9)))
        try:
            self._writer.write_can(_bus_name(msg.channel, self.bus), t_ns, msg,
                                   wall_time_ns=t_ns or None)
        except ValueError:
            self.skipped += 1  # a frame the layout cannot hold (e.g. DLC > 64)
            return
        self.messages += 1

    def file_size(self) -> int:
        try:
            return self._stream.tell()
        except (OSError, ValueError):
            return 0

    def stop(self) -> None:
        self._writer.close()


class McapCanReader(MessageReader):
    """A python-can message reader of the raw CAN frames of a vdps recording."""

    def __init__(self, file, bus: str | None = None, **kwargs: Any):
        from vdps_hil.record.reader import RecordingReader

        self._reader = RecordingReader(file if hasattr(file, "read") else os.fspath(file))
        self.bus = bus

    def __iter__(self) -> Iterator:
        for _, msg in self._reader.iter_raw_can(self.bus):
            yield msg

    def stop(self) -> None:
        self._reader.close()
