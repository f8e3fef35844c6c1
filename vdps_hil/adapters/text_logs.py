"""Text CAN logs (asc, candump log, trc, csv) for python-can's line readers: the lines fed one at a
time with bad bytes skipped and the header kept (:class:`TextFeed`), and the lines the readers skip
with a warning counted instead of printed (:class:`SkippedLineCount`). Used by
``can_adapter.CanFileAdapter``.
"""

from __future__ import annotations

import logging

__all__ = ["TEXT_SUFFIXES", "TextFeed", "SkippedLineCount"]

TEXT_SUFFIXES = (".asc", ".log", ".trc", ".csv")
"""Line-based formats read through :class:`TextFeed` (bad lines skipped and counted)."""


class TextFeed:
    """The lines of a text log for a python-can reader, one at a time, with the header kept.

    Bytes that are not UTF-8 are skipped (``non_utf8_lines``). When the reader fails on a
    line, :meth:`restart` replays the header (the lines before the first message) so a new
    reader over the same feed continues after the bad line with the header state restored.
    """

    def __init__(self, f, counters: dict):
        self.f = f
        self.counters = counters
        self.header: list[str] = []
        self.in_header = True
        self._replay: list[str] = []
        self.last = ""
        self.consumed = 0

    def __iter__(self):
        return self

    def __next__(self) -> str:
        if self._replay:
            return self._replay.pop(0)
        while True:
            b = self.f.readline()
            if not b:
                raise StopIteration
            try:
                line = b.decode("utf-8")
            except UnicodeDecodeError:
                self.counters["non_utf8_lines"] = self.counters.get("non_utf8_lines", 0) + 1
                continue
            self.consumed += 1
            if self.in_header:
                self.header.append(line)
            self.last = line
            return line

    def message_seen(self) -> None:
        if self.in_header:
            self.in_header = False
            if self.header:
                self.header.pop()  # that line was a message, not header

    def restart(self) -> None:
        self.in_header = False
        self._replay = list(self.header)

    def close(self) -> None:
        pass

    @property
    def closed(self) -> bool:
        return self.f.closed


class SkippedLineCount(logging.Handler):
    """Counts the lines python-can's readers skip with a warning (e.g. TRC's "Failed to parse
    message"), instead of printing them."""

    def __init__(self, adapter):
        super().__init__(logging.INFO)
        self.adapter = adapter

    def emit(self, record) -> None:
        h = self.adapter.health
        msg = record.getMessage()
        if "Dropping" in msg or record.levelno < logging.INFO:
            h.count("skipped_lines")  # e.g. TRC bus-information lines: legitimately skipped
            return
        h.count("bad_lines")
        if not h.last_error:
            h.last_error = msg.splitlines()[0][:200]
