"""Recordings: one MCAP file per run, JSON channels, raw frames beside decoded values.

The layout (topics, schemas, time stamps, metadata) is documented in
:mod:`vdps_hil.record.schemas`; :class:`RecordingWriter` writes it and
:class:`RecordingReader` reads it back in ``t_ns`` order (broken files as far as they go).
"""

from vdps_hil.record.reader import RawRecord, RecordingError, RecordingReader, TopicInfo
from vdps_hil.record.schemas import (DEFAULT_SIM_EPOCH_NS, LAYOUT_VERSION, content_hash,
                                     location_fix_doc, register_schema)
from vdps_hil.record.writer import RecordingWriter, WriterStats

__all__ = ["RecordingWriter", "WriterStats", "RecordingReader", "RecordingError", "TopicInfo",
           "RawRecord", "DEFAULT_SIM_EPOCH_NS", "LAYOUT_VERSION", "content_hash",
           "location_fix_doc", "register_schema"]
