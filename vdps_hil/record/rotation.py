"""Recording rotation by size or time: ``out.mcap`` becomes ``out_0000.mcap``,
``out_0001.mcap``, ... each a complete, independently readable recording.

A new file starts after the write that makes the current one reach ``max_bytes`` (bytes on
disk; the writer flushes a chunk every ~64 KiB, so files overshoot by at most a chunk) or span
``max_s`` seconds of ``t_ns``. Every file carries the same ``vdps.recording`` metadata (config,
signal map and DBC hashes, tool version) plus ``vdps.segment`` (its index and the previous
file's name), so any one of them can be read, imported or recovered alone.
"""

from __future__ import annotations

import os
from pathlib import Path

from vdps_hil.record.writer import RecordingWriter

__all__ = ["RotatingRecordingWriter", "segment_path"]

SEGMENT_METADATA = "vdps.segment"


def segment_path(base: str | os.PathLike, index: int) -> Path:
    """``out.mcap`` -> ``out_0003.mcap`` for index 3."""
    p = Path(base)
    suffix = p.suffix or ".mcap"
    return p.with_name(f"{p.stem}_{index:04d}{suffix}")


class RotatingRecordingWriter(RecordingWriter):
    """A :class:`RecordingWriter` that continues in a new file every ``max_bytes`` bytes or
    ``max_s`` seconds of data (either may be None; both None: no rotation, one segment).
    ``files`` lists the segments written so far."""

    def __init__(self, path: str | os.PathLike, *, max_bytes: int | None = None,
                 max_s: float | None = None, **kw):
        if max_bytes is not None and max_bytes <= 0:
            raise ValueError("max_bytes must be positive")
        if max_s is not None and max_s <= 0:
            raise ValueError("max_s must be positive")
        self.base = Path(path)
        self.max_bytes = max_bytes
        self.max_ns = None if max_s is None else int(max_s * 1e9)
        self.index = 0
        self.files: list[str] = []
        self._first_t_ns: int | None = None
        super().__init__(segment_path(self.base, 0), **kw)

    def _open_file(self, path) -> None:
        super()._open_file(path)
        self.files.append(os.fspath(path))
        self._first_t_ns = None
        self._mcap.add_metadata(SEGMENT_METADATA, {
            "index": str(self.index),
            "previous": "" if len(self.files) < 2 else os.path.basename(self.files[-2])})

    def _write(self, topic, schema_name, t_ns, payload, wall_time_ns, channel_metadata={}):
        super()._write(topic, schema_name, t_ns, payload, wall_time_ns, channel_metadata)
        if self._first_t_ns is None:
            self._first_t_ns = t_ns
        due = (self.max_bytes is not None and self._stream.tell() >= self.max_bytes) or \
              (self.max_ns is not None and t_ns - self._first_t_ns >= self.max_ns)
        if due:
            self.rotate()

    def copier(self, channel_of):
        """``RecordingWriter.copier`` with one ``_write`` per message (no queue), so that rotation
        is checked after each."""
        how: dict = {}

        def copy(rec) -> None:
            topic, t_ns, log_time_ns, _, payload = rec
            if topic not in how:
                how[topic] = channel_of(topic)
            if how[topic] is not None:
                self._write(topic, how[topic][0], t_ns, payload, log_time_ns or None, how[topic][1])

        return copy

    def rotate(self) -> None:
        """Close the current file and continue in the next one now."""
        with self._lock:
            if self._closed:
                return
            self._finish_file()
            self.index += 1
            self._open_file(segment_path(self.base, self.index))
