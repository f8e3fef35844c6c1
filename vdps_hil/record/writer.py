"""MCAP recording writer for the layout of :mod:`vdps_hil.record.schemas`.

One channel per topic, registered lazily on the first message with its schema (once per
file). Messages are JSON; ``publish_time = t_ns`` (monotonic measurement time, the ordering
key) and ``log_time`` = wall-clock UTC ns::

    log_time = wall_time_ns                if given (non-zero)
             = sim_epoch_ns + t_ns         if the writer was opened with sim_epoch_ns
             = time.time_ns() at write     otherwise (live, no wall time supplied)

Chunks are ZSTD-compressed and closed when their uncompressed content exceeds ``chunk_size``
bytes (about 64 KiB by default), so a crash loses at most the chunk in progress and the
copied messages still queued (:meth:`RecordingWriter.copier`; call
:meth:`RecordingWriter.flush` to bound that in time). The file opens with a Header and the
``vdps.recording`` metadata record, so even a file cut off by a crash tells what it is.

Extension points (used by rotation, recovery and python-can registration): every message
goes through :meth:`RecordingWriter.write_json` / ``_write``, except messages copied from
another recording (:meth:`RecordingWriter.copier`: queued, then written in runs per
channel); per-file state (channels, schemas, the mcap writer) lives in ``_open_file`` /
``_finish_file``, so a rotating writer closes one file and opens the next with the same
metadata. The message bytes come from :mod:`vdps_hil.record.payloads` and are appended to the
chunk in progress by :mod:`vdps_hil.record.mcap_append`.

The writer is safe to share between threads (one lock around each message).
"""

from __future__ import annotations

import json
import operator
import os
import threading
import time
from dataclasses import dataclass, field
from typing import IO, Any, Callable, Mapping, Sequence

import numpy as np
from mcap.writer import CompressionType, IndexType, Writer
from mcap.writer import LIBRARY_IDENTIFIER as _MCAP_LIBRARY

from vdps_hil import __version__ as _TOOL_VERSION
from vdps_hil.record import schemas as S
from vdps_hil.record.mcap_append import MessageAppender
from vdps_hil.record.payloads import (check_run, estimate_payload, estimate_topic, json_payload, raw_can_payload,
                                      raw_can_rows, raw_serial_payload, sample_payload, truth_payload)

__all__ = ["RecordingWriter", "WriterStats"]

@dataclass
class _Channel:
    id: int
    schema: str
    seq: int = 0
    last_t_ns: int = -1


@dataclass
class _CopyRun:
    """Copied messages of one channel queued for :meth:`RecordingWriter._write_copies`."""

    channel: _Channel
    queue: list[tuple] = field(default_factory=list)  # (topic, t_ns, log_time, sequence, payload)


_COPY_QUEUE = 256
"""Copied messages queued at most (over all topics) before they are written."""


@dataclass
class WriterStats:
    """What the writer has done: messages per topic and per-topic time-order violations.

    ``time_backwards[topic]`` counts messages whose ``t_ns`` was below the previous one on the
    same topic (written anyway, never dropped; readers assume per-topic order, so such a file
    reads in slightly wrong order around them).
    """

    messages: dict[str, int] = field(default_factory=dict)
    time_backwards: dict[str, int] = field(default_factory=dict)
    location_fix_skipped: int = 0

    @property
    def total(self) -> int:
        return sum(self.messages.values())


class RecordingWriter:
    """Write one MCAP recording.

    ``path``: file path, or a binary stream opened for writing (not closed by us).
    ``metadata``: free-form provenance (values converted to str; non-str values as JSON),
    stored in the ``vdps.recording`` metadata record next to the layout version and tool
    version. ``content_hashes``: role -> bytes or file path; stored as ``hash.<role>`` =
    ``sha256:<hex>`` (e.g. ``{"config": cfg_path, "dbc.vdps": dbc_path, "signalmap": ...}``).
    ``sim_epoch_ns``: set for simulated recordings (``schemas.DEFAULT_SIM_EPOCH_NS``) so that
    ``log_time = sim_epoch_ns + t_ns`` when no wall time is given.
    """

    def __init__(self, path: str | os.PathLike | IO[bytes], *,
                 metadata: Mapping[str, Any] | None = None,
                 content_hashes: Mapping[str, bytes | os.PathLike | str] | None = None,
                 chunk_size: int = 65536, sim_epoch_ns: int | None = None):
        if chunk_size <= 0:
            raise ValueError("chunk_size must be positive")
        self.chunk_size = int(chunk_size)
        self.sim_epoch_ns = (None if sim_epoch_ns is None
                             else S.check_time_ns("sim_epoch_ns", sim_epoch_ns))
        self._metadata = S.provenance_record(metadata or {}, content_hashes or {}, self.sim_epoch_ns,
                                             _TOOL_VERSION, _MCAP_LIBRARY)
        self._lock = threading.Lock()
        self.stats = WriterStats()
        self._serial_meta: dict[str, tuple[str, str]] = {}
        self._can_topics: dict[str, str] = {}
        self._est_topics: set[str] = set()  # estimate topics already checked (absolute)
        self.mirror: Callable[..., None] | None = None
        """``mirror(topic, schema, t_ns, payload, log_time_ns, channel_metadata)`` after each
        message written (a live view: ``app.live_view.LiveServer.mirror``); never raises."""
        self._closed = True
        self._open_file(path)

    # --- per-file state (rotation re-runs these) ----------------------------------------------

    def _open_file(self, path: str | os.PathLike | IO[bytes]) -> None:
        if hasattr(path, "write"):
            self._stream, self._owns_stream = path, False
            self.path = getattr(path, "name", None)
        else:
            self._stream, self._owns_stream = open(path, "wb"), True
            self.path = os.fspath(path)
        self._mcap = Writer(self._stream, chunk_size=self.chunk_size,
                            compression=CompressionType.ZSTD, index_types=IndexType.ALL,
                            repeat_channels=True, repeat_schemas=True, use_chunking=True,
                            use_statistics=True, use_summary_offsets=True, enable_crcs=True)
        self._channels: dict[str, _Channel] = {}
        self._schema_ids: dict[str, int] = {}
        self._appender = MessageAppender.attach(self._mcap)
        self._add_message = self._mcap.add_message if self._appender is None else self._appender.add
        self._copies: dict[str, _CopyRun | None] = {}  # copies not written yet per topic (None: not copied)
        self._copies_queued = 0
        self._mcap.start(profile="", library=f"vdps-hil/{_TOOL_VERSION} {_MCAP_LIBRARY}")
        self._mcap.add_metadata(S.METADATA_NAME, self._metadata)
        self._stream.flush()
        self._closed = False

    def _finish_file(self) -> None:
        try:
            self._write_copies()
            self._mcap.finish()
            self._stream.flush()
        finally:
            if self._owns_stream:
                self._stream.close()

    # --- core -----------------------------------------------------------------------------------

    def _log_time(self, t_ns: int, wall_time_ns: int | None) -> int:
        if wall_time_ns:
            return S.check_time_ns("wall_time_ns", wall_time_ns)
        if self.sim_epoch_ns is not None:
            return S.check_time_ns("log_time", self.sim_epoch_ns + t_ns)
        return time.time_ns()

    def _channel(self, topic: str, schema_name: str, channel_metadata: Mapping[str, str]):
        ch = self._channels.get(topic)
        if ch is not None:
            if ch.schema != schema_name:
                raise ValueError(f"topic {topic} already carries {ch.schema}, "
                                 f"not {schema_name}")
            return ch
        sid = self._schema_ids.get(schema_name)
        if sid is None:
            sid = self._mcap.register_schema(schema_name, S.SCHEMA_ENCODING,
                                             S.schema_bytes(schema_name))
            self._schema_ids[schema_name] = sid
        cid = self._mcap.register_channel(topic, S.MESSAGE_ENCODING, sid,
                                          {str(k): str(v) for k, v in channel_metadata.items()})
        ch = self._channels[topic] = _Channel(cid, schema_name)
        return ch

    def _write(self, topic: str, schema_name: str, t_ns: int, payload: bytes,
               wall_time_ns: int | None, channel_metadata: Mapping[str, str] = {}) -> None:
        """Append one encoded message (t_ns already validated)."""
        with self._lock:
            if self._closed:
                raise ValueError("recording is closed")
            log_time = self._log_time(t_ns, wall_time_ns)
            ch = self._channels.get(topic)
            if ch is None or ch.schema != schema_name:
                ch = self._channel(topic, schema_name, channel_metadata)  # raises on mismatch
            if self._copies.get(topic):
                self._write_copies()  # the topic's queued copies go first: per-topic order
            if t_ns < ch.last_t_ns:
                self.stats.time_backwards[topic] = self.stats.time_backwards.get(topic, 0) + 1
            else:
                ch.last_t_ns = t_ns
            self._add_message(ch.id, log_time, payload, t_ns, ch.seq)
            ch.seq = (ch.seq + 1) & 0xFFFFFFFF
            self.stats.messages[topic] = self.stats.messages.get(topic, 0) + 1
        if self.mirror is not None:
            self.mirror(topic, schema_name, t_ns, payload, log_time, channel_metadata)

    def copier(self, channel_of: Callable[[str], tuple[str, Mapping[str, str]] | None]
               ) -> Callable[[tuple], None]:
        """A function appending messages read from another recording unchanged: each a
        ``(topic, t_ns, log_time_ns, sequence, payload)`` tuple (a reader's ``RawRecord``; the
        sequence is not kept, this file numbers its own). ``channel_of(topic)`` gives, at a
        topic's first message, its schema name and channel metadata, or None: not copied. A
        ``log_time_ns`` of 0 means none (the log-time rule of the module docstring).

        The same messages as ``_write`` gives (statistics, sequence numbers, time-order counts),
        written later: copies are queued and written in runs of one channel each (one pack and
        one write per run, see ``MessageAppender.add_run``) when ``_COPY_QUEUE`` messages are
        queued over all topics, when a copied topic is written directly, and at ``flush`` /
        ``close`` (``stats`` counts them then). A file therefore holds a topic's copies up to
        ``_COPY_QUEUE`` messages after the messages written directly next to them (in ``t_ns``
        order per topic still), and a crash loses those queued copies with the chunk in
        progress."""
        lock, max_ns = self._lock, S.MAX_TIME_NS

        def copy(rec: tuple) -> None:
            with lock:
                if self._closed:
                    raise ValueError("recording is closed")
                run = self._copies.get(rec[0], False)
                if run is False:
                    run = self._copy_run(rec[0], channel_of)
                if run is None:
                    return
                if not 0 < rec[2] <= max_ns:  # none given (0), or the error of an invalid one
                    rec = (rec[0], rec[1], self._log_time(rec[1], rec[2] or None), rec[3], rec[4])
                run.queue.append(rec)
                self._copies_queued += 1
                if self._copies_queued >= _COPY_QUEUE:
                    self._write_copies()

        return copy

    def _copy_run(self, topic: str, channel_of) -> "_CopyRun | None":
        """The queue of a topic's copies (its channel registered now), None if not copied."""
        how = channel_of(topic)
        if how is None:
            self._copies[topic] = None
            return None
        ch = self._channels.get(topic)
        if ch is None or ch.schema != how[0]:
            ch = self._channel(topic, how[0], how[1])  # raises on a schema mismatch
        run = self._copies[topic] = _CopyRun(ch)
        return run

    def _write_copies(self) -> None:
        """Write every queued copy (lock held)."""
        for topic, run in self._copies.items():
            if run is None or not run.queue:
                continue
            _, t_ns, log_time, _, payload = zip(*run.queue)
            run.queue.clear()
            self._append_run(topic, run.channel, t_ns, log_time, payload)
        self._copies_queued = 0

    def _append_run(self, topic: str, ch: "_Channel", t_ns, log_time, payload) -> None:
        """Messages of one channel in this order, as ``_write`` once each (lock held, times checked)."""
        n = len(payload)
        if ch.last_t_ns <= t_ns[0] and all(map(operator.le, t_ns, t_ns[1:])):
            ch.last_t_ns = t_ns[-1]  # in order: the common case
        else:
            for t in t_ns:
                if t < ch.last_t_ns:
                    self.stats.time_backwards[topic] = self.stats.time_backwards.get(topic, 0) + 1
                else:
                    ch.last_t_ns = t
        self.stats.messages[topic] = self.stats.messages.get(topic, 0) + n
        if self._appender is not None and ch.seq + n <= 1 << 32:
            self._appender.add_run(ch.id, ch.seq, log_time, payload, t_ns)
        else:  # the library's add_message, or sequence numbers wrapping inside the run
            for k in range(n):
                self._add_message(ch.id, log_time[k], payload[k], t_ns[k], (ch.seq + k) & 0xFFFFFFFF)
        ch.seq = (ch.seq + n) & 0xFFFFFFFF

    def write_json(self, topic: str, schema_name: str, t_ns: int, doc: Mapping[str, Any], *,
                   wall_time_ns: int | None = None,
                   channel_metadata: Mapping[str, str] | None = None) -> None:
        """Write a document under a registered schema (``schemas.SCHEMAS``).

        When the schema has a ``t_ns`` property, ``doc`` gets ``t_ns`` added if absent (a
        different ``t_ns`` inside is an error). Non-finite floats become null.
        """
        self._write(topic, schema_name, t_ns, json_payload(topic, schema_name, t_ns, doc), wall_time_ns,
                    channel_metadata or {})

    def write_encoded(self, topic: str, schema_name: str, t_ns: int, payload: bytes, *,
                      wall_time_ns: int | None = None, channel_metadata: Mapping[str, str] | None = None) -> None:
        """Write a message already encoded by :func:`~vdps_hil.record.payloads.json_payload` or
        :func:`~vdps_hil.record.payloads.estimate_payload` (elsewhere, e.g. in the other process
        of ``vdps replay --jobs 2``): the topic, schema and time are checked as ``write_json``
        checks them; the payload must be bytes."""
        S.check_topic(topic)
        S.check_time_ns("t_ns", t_ns)
        if schema_name not in S.SCHEMAS:
            raise KeyError(f"unknown schema {schema_name!r}")
        if not isinstance(payload, bytes):
            raise TypeError(f"payload must be bytes, got {type(payload).__name__}")
        self._write(topic, schema_name, t_ns, payload, wall_time_ns, channel_metadata or {})

    def write_encoded_run(self, topic: str, schema_name: str, t_ns: Sequence[int], payloads: Sequence[bytes],
                          wall_time_ns: Sequence[int | None], channel_metadata: Mapping[str, str] | None = None
                          ) -> None:
        """``write_encoded`` of message k = 0..n-1 (the same messages, statistics and checks, all
        raised before anything is written) as one run of the channel (``MessageAppender.add_run``)."""
        t_ns, payloads, walls = check_run(topic, schema_name, t_ns, payloads, wall_time_ns)
        if not payloads:
            return
        if not all(walls):  # none given: the rule of write_encoded
            walls = tuple(w if w else self._log_time(t, None) for t, w in zip(t_ns, walls))
        md = channel_metadata or {}
        with self._lock:
            if self._closed:
                raise ValueError("recording is closed")
            ch = self._channels.get(topic)
            if ch is None or ch.schema != schema_name:
                ch = self._channel(topic, schema_name, md)  # raises on mismatch
            if self._copies.get(topic):
                self._write_copies()  # the topic's queued copies go first: per-topic order
            self._append_run(topic, ch, t_ns, walls, payloads)
        if self.mirror is not None:
            for t, p, w in zip(t_ns, payloads, walls):
                self.mirror(topic, schema_name, t, p, w, md)

    # --- typed helpers --------------------------------------------------------------------------

    def write_can(self, bus: str, t_ns: int, msg_or_fields: Any, direction: str | None = None,
                  wall_time_ns: int | None = None) -> None:
        """One CAN frame on ``/raw/can/<bus>``.

        ``msg_or_fields``: a ``can.Message`` or a mapping with ``arbitration_id`` and ``data``
        (bytes) or ``data_hex``, optionally ``is_extended_id``, ``is_fd``, ``is_remote_frame``,
        ``is_error_frame``, ``dlc``, ``direction``, ``bitrate_switch``,
        ``error_state_indicator``. ``direction`` (``rx``/``tx``) defaults to the message's
        ``is_rx`` (or the mapping's ``direction``, else ``rx``).
        """
        topic = self._can_topics.get(bus)
        if topic is None:
            topic = self._can_topics[bus] = S.can_topic(bus)
        S.check_time_ns("t_ns", t_ns)
        payload = raw_can_payload(t_ns, msg_or_fields, direction)
        self._write(topic, S.RAW_CAN, t_ns, payload, wall_time_ns, {"bus": bus})

    def write_can_frames(self, bus: str, t_ns, arbitration_ids, dlcs, data) -> None:
        """``write_can`` of N received classic standard-ID frames in this order (numpy arrays,
        ``payloads.raw_can_rows``) as one run built with numpy: the same messages and file."""
        topic = self._can_topics.get(bus)
        if topic is None:
            topic = self._can_topics[bus] = S.can_topic(bus)
        t = np.asarray(t_ns, dtype=np.int64)
        rows, lengths = raw_can_rows(t, arbitration_ids, dlcs, data)  # checks the frames
        if t.size == 0:
            return
        with self._lock:
            if self._closed:
                raise ValueError("recording is closed")
            ch = self._channels.get(topic)
            if ch is None or ch.schema != S.RAW_CAN:
                ch = self._channel(topic, S.RAW_CAN, {"bus": bus})  # raises on mismatch
            epoch, n = self.sim_epoch_ns, t.size
            slow = (not self._runs_ok or epoch is None or self.mirror is not None or self._copies.get(topic)
                    or ch.seq + n > 1 << 32 or int(t.max()) > S.MAX_TIME_NS - epoch
                    or ch.last_t_ns > t[0] or bool((t[1:] < t[:-1]).any()))  # uncommon: one at a time
            if not slow:
                ch.last_t_ns = int(t[-1])
                self.stats.messages[topic] = self.stats.messages.get(topic, 0) + n
                self._appender.add_rows(ch.id, ch.seq, t + epoch, t, rows, lengths)
                ch.seq = (ch.seq + n) & 0xFFFFFFFF
        if slow:
            for k, tk in enumerate(t.tolist()):
                self._write(topic, S.RAW_CAN, tk, rows[k, :lengths[k]].tobytes(), None, {"bus": bus})

    def write_serial(self, device: str, t_ns: int, data: bytes,
                     wall_time_ns: int | None = None, baud: int | None = None,
                     fmt: str | None = None) -> None:
        """One read chunk on ``/raw/serial/<device>``; ``baud`` and ``fmt`` go into the
        channel metadata at the first write (later calls may omit them; a different value is
        an error, since a channel's metadata is fixed)."""
        topic, md = self._serial_channel(device, baud, fmt)
        self._write(topic, S.RAW_SERIAL, S.check_time_ns("t_ns", t_ns), raw_serial_payload(t_ns, data), wall_time_ns,
                    md)

    def write_serial_chunks(self, device: str, chunks: Sequence[tuple[int, bytes]], baud: int | None = None,
                            fmt: str | None = None) -> None:
        """``write_serial`` of each read chunk ``(t_ns, bytes)`` in this order (no wall times), as
        one run of the channel (``write_encoded_run``)."""
        if not self._runs_ok:
            for t, d in chunks:
                self.write_serial(device, t, d, baud=baud, fmt=fmt)
            return
        topic, md = self._serial_channel(device, baud, fmt)
        t_ns = [c[0] for c in chunks]
        self.write_encoded_run(topic, S.RAW_SERIAL, t_ns, [raw_serial_payload(t, d) for t, d in chunks],
                               [None] * len(t_ns), md)

    @property
    def _runs_ok(self) -> bool:  # runs may bypass _write: the appender is used, no subclass acts per message
        return self._appender is not None and type(self)._write is RecordingWriter._write

    def _serial_channel(self, device: str, baud: int | None, fmt: str | None) -> tuple[str, dict[str, str]]:
        """The topic and channel metadata of a serial device (fixed at its first write)."""
        topic = S.serial_topic(device)
        meta = self._serial_meta.get(topic)
        if meta is None:
            meta = ("" if baud is None else str(int(baud)), fmt or "")
            self._serial_meta[topic] = meta
        elif (baud is not None and str(int(baud)) != meta[0]) or (fmt and fmt != meta[1]):
            raise ValueError(f"{topic}: baud/format changed from {meta} to {(baud, fmt)}")
        return topic, {"device": device, "baud": meta[0], "format": meta[1]}

    def write_sample(self, sample, topic: str | None = None) -> None:
        """A bus Sample on ``/decoded/<source>/<kind>`` (or ``topic``); log_time from the
        sample's ``wall_time_ns`` when non-zero."""
        topic = S.sample_topic(sample.source, sample.kind) if topic is None else S.check_topic(topic)
        S.check_time_ns("t_ns", sample.t_ns)
        self._write(topic, S.SAMPLE, sample.t_ns, sample_payload(sample), sample.wall_time_ns or None,
                    {"source": sample.source, "kind": sample.kind})

    def write_location_fix(self, sample, topic: str = S.GNSS_FIX_TOPIC,
                           frame_id: str = "gnss") -> bool:
        """The GNSS position of a ``gnss_pos`` sample as ``foxglove.LocationFix``.

        Its ``timestamp`` is the message's log_time (wall or simulated wall clock). Returns
        False (and counts ``stats.location_fix_skipped``) when the sample has no finite
        latitude/longitude.
        """
        S.check_topic(topic)
        with self._lock:
            stamp = self._log_time(S.check_time_ns("t_ns", sample.t_ns),
                                   sample.wall_time_ns or None)
        doc = S.location_fix_doc(sample, frame_id=frame_id, stamp_ns=stamp)
        if doc is None:
            self.stats.location_fix_skipped += 1
            return False
        payload = json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()
        self._write(topic, S.LOCATION_FIX, sample.t_ns, payload, stamp)
        return True

    def write_truth(self, topic: str, t_ns: int, values: Mapping[str, Any]) -> None:
        """Simulator ground truth (simulation only) on ``/truth/...``; ``topic`` may be given
        without the prefix (``"state"`` -> ``/truth/state``)."""
        if not topic.startswith("/"):
            topic = S.TRUTH_PREFIX + topic
        if not S.check_topic(topic).startswith(S.TRUTH_PREFIX):
            raise ValueError(f"truth topic must be under {S.TRUTH_PREFIX}: {topic}")
        self._write(topic, S.TRUTH, t_ns, truth_payload(topic, t_ns, values), None, {})

    def write_estimate(self, topic: str, t_ns: int, values: Mapping[str, float],
                       sigmas: Mapping[str, float] | None = None) -> None:
        """Estimator output on ``/est/...`` (``"ekf"`` -> ``/est/ekf``)."""
        if topic not in self._est_topics:
            topic = estimate_topic(topic)
            if len(self._est_topics) < 1024:
                self._est_topics.add(topic)  # checked once
        self._write(topic, S.ESTIMATE, t_ns, estimate_payload(t_ns, values, sigmas), None, {})

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """An extra MCAP metadata record (values converted to str, non-str as JSON)."""
        md = {str(k): v if isinstance(v, str) else json.dumps(S.clean_json(v), sort_keys=True)
              for k, v in data.items()}
        with self._lock:
            if self._closed:
                raise ValueError("recording is closed")
            self._mcap.add_metadata(name, md)

    # --- lifecycle ------------------------------------------------------------------------------

    @property
    def metadata(self) -> dict[str, str]:
        """The ``vdps.recording`` metadata record as written."""
        return dict(self._metadata)

    def flush(self) -> None:
        """Close the chunk in progress and push everything written so far to the OS."""
        with self._lock:
            if not self._closed:
                self._write_copies()
                self._mcap.flush()

    def close(self) -> None:
        """Write the summary and footer and close the file (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._finish_file()

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
