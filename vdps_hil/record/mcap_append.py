"""Fast appending of MCAP message records to the chunk in progress of an mcap ``Writer``.

:class:`MessageAppender` writes the same bytes, statistics, message indexes and chunk boundaries
as ``Writer.add_message`` called once per message, without the library's per-message objects;
the recording writer (:mod:`vdps_hil.record.writer`) uses it when the library's internals are
the ones it was written against, else the library's own ``add_message``.
"""

from __future__ import annotations

import bisect
import io
import struct
from itertools import accumulate, chain, repeat
from typing import Callable, Sequence

import numpy as np
from mcap.opcode import Opcode
from mcap.records import MessageIndex

__all__ = ["MessageAppender"]

_MESSAGE_RECORD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log_time, publish_time
_MESSAGE_RECORD_BYTES = _MESSAGE_RECORD.size  # 31: record header (9) + message header (22)
_MESSAGE_RECORD_DTYPE = np.dtype([("opcode", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                                  ("log_time", "<u8"), ("publish_time", "<u8")])  # packed, as _MESSAGE_RECORD


class MessageAppender:
    """Appends message records to the chunk in progress of an mcap ``Writer`` without the
    library's per-message objects (a Message dataclass, eight small writes and a seek back per
    record: about 5 us, the largest share of copying a replay's raw topics). Same bytes,
    statistics, message indexes and chunk boundaries as ``Writer.add_message`` called once per
    message (``tests/test_mcap_append.py`` compares the files).

    ``add`` writes one message; ``add_run`` a run of messages of one channel with one pack and
    one write per run piece: the run is cut where the library would close the chunk (after the
    message that takes the chunk past ``chunk_size``); ``add_rows`` the same for payloads given
    as rows of a numpy array (records built with numpy, no Python object per message)."""

    def __init__(self, stats, chunk_builder, record_writer, maybe_finalize, chunk_size: int):
        self._st, self._cb, self._rw = stats, chunk_builder, record_writer
        self._finalize = maybe_finalize
        self._chunk_size = chunk_size

    @classmethod
    def attach(cls, mcap_writer) -> "MessageAppender | None":
        """The appender of ``mcap_writer``, or None when the mcap library's internals are not
        the ones this was written against (then the library's own add_message is used)."""
        st = getattr(mcap_writer, "_Writer__statistics", None)
        cb = getattr(mcap_writer, "_Writer__chunk_builder", None)
        finalize = getattr(mcap_writer, "_Writer__maybe_finalize_chunk", None)
        chunk_size = getattr(mcap_writer, "_Writer__chunk_size", None)
        rw = getattr(cb, "record_writer", None)
        if st is None or cb is None or finalize is None or type(chunk_size) is not int \
                or not isinstance(getattr(rw, "_buffer", None), io.BytesIO) \
                or not all(hasattr(cb, a) for a in ("num_messages", "message_start_time", "message_end_time",
                                                     "message_indices")) \
                or not all(hasattr(st, a) for a in ("message_count", "message_start_time", "message_end_time",
                                                     "channel_message_counts")):
            return None
        return cls(st, cb, rw, finalize, chunk_size)

    def _account(self, channel_id: int, n: int, t_min: int, t_max: int):
        """Statistics and chunk times of ``n`` messages with log times in [t_min, t_max]; the
        channel's message index of the chunk in progress."""
        st, cb = self._st, self._cb
        if st.message_count == 0 or t_min < st.message_start_time:
            st.message_start_time = t_min
        if t_max > st.message_end_time:
            st.message_end_time = t_max
        st.channel_message_counts[channel_id] += n
        st.message_count += n
        if cb.num_messages == 0 or t_min < cb.message_start_time:
            cb.message_start_time = t_min
        if t_max > cb.message_end_time:
            cb.message_end_time = t_max
        cb.num_messages += n
        mi = cb.message_indices.get(channel_id)
        if mi is None:
            mi = cb.message_indices[channel_id] = _MessageIndex(channel_id=channel_id, records=[])
        return mi.records

    def add(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        """``Writer.add_message`` (same signature)."""
        index = self._account(channel_id, 1, log_time, log_time)
        buf = self._rw._buffer
        index.append((log_time, buf.tell()))
        buf.write(_MESSAGE_RECORD.pack(0x05, 22 + len(data), channel_id, sequence, log_time, publish_time))
        buf.write(data)
        self._finalize()

    def add_run(self, channel_id: int, sequence: int, log_times: Sequence[int], payloads: Sequence[bytes],
                publish_times: Sequence[int]) -> None:
        """Messages ``k = 0..n-1`` of one channel with sequence numbers ``sequence + k`` (the
        caller keeps them below 2^32), as ``add`` once per message in that order."""
        n = len(payloads)
        ends = list(accumulate(map(_MESSAGE_RECORD_BYTES.__add__, map(len, payloads))))  # run offsets
        headers = list(map(_MESSAGE_RECORD.pack, repeat(0x05), map((22).__add__, map(len, payloads)),
                           repeat(channel_id), range(sequence, sequence + n), log_times, publish_times))

        def write(i: int, k: int, base: int) -> None:
            self._rw._buffer.writelines(chain.from_iterable(zip(headers[i:k], payloads[i:k])))

        self._write_cut(channel_id, log_times, ends, write)

    def add_rows(self, channel_id: int, sequence: int, log_times: np.ndarray, publish_times: np.ndarray,
                 rows: np.ndarray, lengths: np.ndarray) -> None:
        """``add_run`` of the payloads ``rows[k, :lengths[k]]`` (rows (N, W) uint8; times int64
        arrays): the records (header and payload) are laid out in one array."""
        n = len(lengths)
        if n == 0:
            return
        size = _MESSAGE_RECORD_BYTES + np.asarray(lengths, dtype=np.int64)
        head = np.zeros(n, dtype=_MESSAGE_RECORD_DTYPE)
        head["opcode"], head["length"], head["channel"] = 0x05, size - 9, channel_id
        head["sequence"] = np.arange(sequence, sequence + n, dtype=np.int64)
        head["log_time"], head["publish_time"] = log_times, publish_times
        full = np.empty((n, _MESSAGE_RECORD_BYTES + rows.shape[1]), dtype=np.uint8)
        full[:, :_MESSAGE_RECORD_BYTES] = head.view(np.uint8).reshape(n, _MESSAGE_RECORD_BYTES)
        full[:, _MESSAGE_RECORD_BYTES:] = rows
        blob = full[np.arange(full.shape[1])[None, :] < size[:, None]]  # the records back to back

        def write(i: int, k: int, base: int) -> None:
            self._rw._buffer.write(blob[base:ends[k - 1]].data)

        ends = np.cumsum(size).tolist()
        self._write_cut(channel_id, np.asarray(log_times).tolist(), ends, write)

    def _write_cut(self, channel_id: int, log_times: Sequence[int], ends: list[int],
                   write: Callable[[int, int, int], None]) -> None:
        """Records k = 0..n-1 of one channel ending at run offsets ``ends``, cut where the library
        would close the chunk; ``write(i, k, base)`` writes records i..k-1 (base: run offset of
        record i)."""
        n = len(ends)
        i = 0
        while i < n:
            base = ends[i - 1] if i else 0  # run offset of message i
            start = self._rw._buffer.tell()  # its offset in the chunk
            # the chunk closes after the first message ending past chunk_size
            k = min(bisect.bisect_right(ends, self._chunk_size - start + base, i) + 1, n)
            piece = log_times[i:k]
            index = self._account(channel_id, k - i, min(piece), max(piece))
            index.extend(zip(piece, map((start - base).__add__, chain((base,), ends[i:k - 1]))))
            write(i, k, base)
            self._finalize()
            i = k


class _MessageIndex(MessageIndex):
    """Written with one pack of all its (log_time, offset) pairs instead of two calls each."""

    def write(self, stream) -> None:
        recs = self.records
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(recs) * 16)
        stream.write(struct.pack(f"<{2 * len(recs)}Q", *chain.from_iterable(recs)))
        stream.finish_record()
