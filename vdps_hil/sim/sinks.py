"""Where a drive's output goes: :class:`DriveSink` (the interface a
:class:`~vdps_hil.sim.session.DriveSession` calls) and :class:`RecordingSink` (the MCAP recording
of :mod:`vdps_hil.sim.drive`). The HIL bench has its own sink (live CAN bus and pseudo-terminals).
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from vdps_hil.record.gnss_fix import GnssFixTap
from vdps_hil.record.writer import RecordingWriter

__all__ = ["DriveSink", "RecordingSink"]


class _Frame:
    """A python-can-like frame for ``RecordingWriter.write_can`` (its duck-typed fast path)."""

    __slots__ = ("arbitration_id", "dlc", "data")
    is_extended_id = False
    is_fd = False
    is_remote_frame = False
    is_error_frame = False
    is_rx = True
    bitrate_switch = False
    error_state_indicator = False

    def __init__(self, arbitration_id: int, dlc: int):
        self.arbitration_id = arbitration_id
        self.dlc = dlc
        self.data = b""


class DriveSink:
    """Where a drive's output goes (``Drive.start``). The session calls, in time order per
    stream: ``metadata`` (``truth.drive`` at the start), ``truth`` (``/truth/state`` at 100 Hz
    and ``/truth/events``, while stepping), then after each processed block ``can_block`` and
    ``serial_chunks``. Subclasses override what they need; every method here does nothing.

    ``can_block(bus, t_ns, t_wire_ns, route, data, specs)``: N frames in reception order;
    ``t_ns`` the receive stamps (the interface's clock: a ``clock_jump`` on ``can`` moves them),
    ``t_wire_ns`` the true times the frames' last bits arrived, ``route`` (N,) indices into
    ``specs`` (``[(frame_id, dlc)]`` per sensor message), ``data`` (N, 8) uint8 payloads (the
    first DLC bytes are the frame's). Arrays are the session's: copy what you keep.
    ``serial_chunks(device, baud, fmt, chunks)``: read chunks ``[(t_ns, bytes)]`` stamped with
    the arrival of their last byte.
    """

    def metadata(self, name: str, data: Mapping[str, Any]) -> None:
        pass

    def truth(self, topic: str, t_ns: int, doc: Mapping[str, Any]) -> None:
        pass

    def can_block(self, bus: str, t_ns: np.ndarray, t_wire_ns: np.ndarray, route: np.ndarray,
                  data: np.ndarray, specs: list[tuple[int, int]]) -> None:
        pass

    def serial_chunks(self, device: str, baud: int, fmt: str, chunks: list[tuple[int, bytes]]) -> None:
        pass

    @property
    def messages(self) -> dict[str, int]:
        """Messages delivered per topic (for the summary)."""
        return {}

    @property
    def time_backwards(self) -> dict[str, int]:
        return {}


class RecordingSink(DriveSink):
    """A DriveSink writing the recording layout of the module docstring with a RecordingWriter,
    plus ``/gnss/fix`` decoded from the NMEA stream (``record.gnss_fix``) for Foxglove's map.

    ``bulk`` (default): a block's CAN frames go to the writer as arrays in one call
    (``RecordingWriter.write_can_frames``) and a block's read chunks of a device without a tap as
    one run (``write_serial_chunks``); ``bulk=False`` is the reference path, one ``write_can`` /
    ``write_serial`` per message (the same file, ``tests/test_sinks.py``)."""

    def __init__(self, writer: RecordingWriter, bulk: bool = True):
        self.writer = writer
        self.bulk = bool(bulk)
        self._frames: list[_Frame] = []
        self._fix_taps: dict[str, GnssFixTap] = {}

    def metadata(self, name, data) -> None:
        self.writer.add_metadata(name, data)

    def truth(self, topic, t_ns, doc) -> None:
        self.writer.write_truth(topic, t_ns, doc)

    def can_block(self, bus, t_ns, t_wire_ns, route, data, specs) -> None:
        if self.bulk:
            ids, dlcs = np.array(specs, dtype=np.int64).reshape(-1, 2).T
            route = np.asarray(route, dtype=np.int64)
            self.writer.write_can_frames(bus, t_ns, ids[route], dlcs[route], data)
            return
        frames = self._frames
        if len(frames) != len(specs):
            frames[:] = [_Frame(fid, dlc) for fid, dlc in specs]
        w = self.writer
        raw = data.tobytes()
        for j, (tj, mj) in enumerate(zip(t_ns.tolist(), route.tolist())):
            fr = frames[mj]
            fr.data = raw[8 * j:8 * j + fr.dlc]
            w.write_can(bus, tj, fr)

    def serial_chunks(self, device, baud, fmt, chunks) -> None:
        w = self.writer
        if self.bulk and fmt != "nmea":
            w.write_serial_chunks(device, chunks, baud=baud, fmt=fmt)
            return
        tap = None
        if fmt == "nmea":  # /gnss/fix for Foxglove's map, decoded from the bytes written
            tap = self._fix_taps.get(device)
            if tap is None:
                tap = self._fix_taps[device] = GnssFixTap(w, device, baud)
        for tc, data in chunks:
            w.write_serial(device, tc, data, baud=baud, fmt=fmt)
            if tap is not None:
                tap.feed(tc, data)

    @property
    def messages(self) -> dict[str, int]:
        return dict(self.writer.stats.messages)

    @property
    def time_backwards(self) -> dict[str, int]:
        return dict(self.writer.stats.time_backwards)
