"""Recordings: one MCAP file per run, JSON channels, raw frames beside decoded values.

Data flow. Writing: the logger, the importer, the replay and the bench hand messages to
:class:`RecordingWriter` (``writer``), which encodes them (``payloads``) in the layout of
``schemas`` (topics, schemas, time stamps, metadata) and appends them to ZSTD chunks
(``mcap_append``); ``rotation`` starts a new file by size or time. Reading:
:class:`RecordingReader` (``reader``) indexes the file from its summary or, for a broken file,
by scanning it (``mcap_file``) and yields messages in ``t_ns`` order across channels;
``decode`` turns the ``/raw/`` records into bus samples through one decoder per source
(``streams``) stamped by the devices' own clocks (``device_clock``); ``input_order`` keeps the
order a live system received its samples; ``recover`` rescues a file cut off by a crash;
``can_io`` lets python-can read and write ``.mcap``.
"""

from vdps_hil.record.reader import RawRecord, RecordingError, RecordingReader, TopicInfo
from vdps_hil.record.schemas import (DEFAULT_SIM_EPOCH_NS, LAYOUT_VERSION, content_hash,
                                     location_fix_doc, register_schema)
from vdps_hil.record.writer import RecordingWriter, WriterStats

__all__ = ["RecordingWriter", "WriterStats", "RecordingReader", "RecordingError", "TopicInfo",
           "RawRecord", "DEFAULT_SIM_EPOCH_NS", "LAYOUT_VERSION", "content_hash",
           "location_fix_doc", "register_schema"]
