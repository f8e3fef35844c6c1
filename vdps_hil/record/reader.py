"""MCAP recording reader: messages in ``t_ns`` order across topics, raw CAN as python-can
messages, raw serial chunks, bus samples, metadata; broken files read as far as they go.

Ordering. MCAP's own readers order by ``log_time`` (wall clock), which is not the
measurement time: wall clocks step, and a live logger stamps wall time at arrival. We order
by ``publish_time = t_ns`` instead, with a k-way merge over channels: within one topic the
writer appends in non-decreasing ``t_ns``, so the next message overall is the smallest head
among the channels. The file is read once, chunk by chunk in file order; a message is
emitted as soon as every selected channel that still has unread messages (per-channel counts
from the statistics record, or from the scan of a truncated file) has one buffered, so memory
stays bounded by how far apart the channels were written. Ties go to file order.

Broken files. A file that is not MCAP (bad magic, empty, unreadable) raises
:class:`RecordingError` with one line; a file without a valid summary is scanned, a corrupt
chunk skipped (:mod:`vdps_hil.record.mcap_file`), and ``reader.truncated`` /
``reader.problems`` say so; everything around a damaged spot is read.

Keeping the estimator off ground truth: select topics by prefix, e.g.
``iter_messages(prefixes=("/raw/",))`` never touches ``/truth/`` chunks.
"""

from __future__ import annotations

import base64
import heapq
import io
import json
import os
from collections import deque
from typing import IO, Iterable, Iterator, NamedTuple

from vdps_hil.record import schemas as S
from vdps_hil.record.mcap_file import MAGIC, McapIndex, one_line

__all__ = ["RecordingError", "RecordingReader", "TopicInfo", "RawRecord", "damage_note", "scan_damage"]


class RecordingError(Exception):
    """A recording that cannot be read at all (one-line message)."""


class TopicInfo(NamedTuple):
    schema: str
    count: int


class RawRecord(NamedTuple):
    """One message as stored: topic, ``t_ns`` (publish_time), ``log_time_ns``, per-channel
    ``sequence`` and the encoded JSON bytes."""

    topic: str
    t_ns: int
    log_time_ns: int
    sequence: int
    data: bytes


class RecordingReader(McapIndex):
    """Read a recording written by :class:`~vdps_hil.record.writer.RecordingWriter` (or any
    MCAP with JSON channels).

    Attributes: ``truncated`` (no valid summary: read by scanning), ``problems`` (one-line
    notes about anything skipped), ``rejected`` (messages that could not be decoded).
    """

    def __init__(self, path: str | os.PathLike | IO[bytes]):
        self.rejected = 0
        if hasattr(path, "read"):
            self._f, self._owns = path, False
            self.path = getattr(path, "name", "<stream>")
        else:
            self.path = os.fspath(path)
            try:
                self._f, self._owns = open(self.path, "rb"), True
            except OSError as e:
                raise RecordingError(f"cannot open {self.path}: {e.strerror or e}") from None
        try:
            self._f.seek(0, io.SEEK_END)
            size = self._f.tell()
            self._f.seek(0)
            magic = self._f.read(len(MAGIC))
        except OSError as e:
            self.close()
            raise RecordingError(f"cannot read {self.path}: {e.strerror or e}") from None
        if magic != MAGIC:
            self.close()
            what = "empty file" if size == 0 else "bad magic"
            raise RecordingError(f"{self.path} is not an MCAP recording ({what})")
        super().__init__(self._f, size)

    # --- catalogue ------------------------------------------------------------------------------

    def topics(self) -> dict[str, TopicInfo]:
        """Topic -> (schema name, message count), sorted by topic."""
        out: dict[str, TopicInfo] = {}
        for cid, ch in self._channels.items():
            n = self._counts.get(cid, 0)
            old = out.get(ch.topic)
            out[ch.topic] = TopicInfo(ch.schema, n) if old is None else \
                TopicInfo(old.schema, old.count + n)
        return dict(sorted(out.items()))

    def channel_metadata(self, topic: str) -> dict[str, str]:
        for ch in self._channels.values():
            if ch.topic == topic:
                return dict(ch.metadata)
        raise KeyError(f"no topic {topic!r} in {self.path}")

    def serial_config(self, device: str) -> tuple[int | None, str]:
        """(baud, format) of a raw serial device from its channel metadata."""
        md = self.channel_metadata(S.RAW_SERIAL_PREFIX + device)
        baud = md.get("baud", "")
        return (int(baud) if baud.isdigit() else None), md.get("format", "")

    def metadata(self) -> dict[str, dict[str, str]]:
        """MCAP metadata records: name -> key/value strings (records of the same name merged,
        later ones winning). ``metadata()["vdps.recording"]`` is the provenance record."""
        out: dict[str, dict[str, str]] = {}
        for name, md in self._metadata:
            out.setdefault(name, {}).update(md)
        return out

    @property
    def layout_version(self) -> str | None:
        return self.metadata().get(S.METADATA_NAME, {}).get("layout_version")

    # --- iteration ------------------------------------------------------------------------------

    def _select(self, topics: Iterable[str] | str | None,
                prefixes: Iterable[str] | str | None, schema: str | None = None) -> set[int]:
        if isinstance(topics, str):
            topics = (topics,)
        if isinstance(prefixes, str):
            prefixes = (prefixes,)
        topics = None if topics is None else set(topics)
        prefixes = None if prefixes is None else tuple(prefixes)
        out = set()
        for cid, ch in self._channels.items():
            if schema is not None and ch.schema != schema:
                continue
            if topics is None and prefixes is None:
                out.add(cid)
            elif (topics is not None and ch.topic in topics) or \
                    (prefixes is not None and ch.topic.startswith(prefixes)):
                out.add(cid)
        return out

    def _merged(self, cids: set[int]) -> Iterator[tuple[int, int, int, int, bytes]]:
        """(cid, t_ns, log_time, seq, data) of the selected channels in t_ns order."""
        if not cids:
            return
        unread = {c: self._counts.get(c, 0) for c in cids}
        bufs: dict[int, deque] = {c: deque() for c in cids}
        blocking = sum(1 for c in cids if unread[c] > 0)
        heap: list[tuple[int, int, int]] = []
        order = 0
        for block in self._blocks:
            if block.channels is not None and block.channels.isdisjoint(cids):
                continue
            try:
                records = self._block_messages(block, cids)
            except Exception as e:  # noqa: BLE001 - damaged block: note it, read the rest
                note = f"block at byte {block.offset} unreadable, skipped: {one_line(e)}"
                if note not in self.problems:  # once per file, not once per pass
                    self.problems.append(note)
                continue
            for _, cid, seq, log_t, pub_t, data in records:
                buf = bufs.get(cid)
                if buf is None:
                    continue
                if not buf:
                    heapq.heappush(heap, (pub_t, order, cid))
                    if unread[cid] > 0:
                        blocking -= 1
                buf.append((pub_t, order, log_t, seq, data))
                unread[cid] -= 1
                order += 1
            while blocking == 0 and heap:
                _, _, c = heapq.heappop(heap)
                buf = bufs[c]
                pub_t, _, log_t, seq, data = buf.popleft()
                if buf:
                    heapq.heappush(heap, (buf[0][0], buf[0][1], c))
                elif unread[c] > 0:
                    blocking += 1
                yield c, pub_t, log_t, seq, data
        while heap:  # counts were short (damaged blocks): drain what is buffered, in order
            _, _, c = heapq.heappop(heap)
            buf = bufs[c]
            pub_t, _, log_t, seq, data = buf.popleft()
            if buf:
                heapq.heappush(heap, (buf[0][0], buf[0][1], c))
            yield c, pub_t, log_t, seq, data

    def iter_records(self, topics: Iterable[str] | str | None = None, *,
                     prefixes: Iterable[str] | str | None = None) -> Iterator[RawRecord]:
        """Undecoded messages in ``t_ns`` order (see :meth:`iter_messages` for selection)."""
        chans = self._channels
        for cid, t_ns, log_t, seq, data in self._merged(self._select(topics, prefixes)):
            yield RawRecord(chans[cid].topic, t_ns, log_t, seq, data)

    def iter_messages(self, topics: Iterable[str] | str | None = None, *,
                      prefixes: Iterable[str] | str | None = None
                      ) -> Iterator[tuple[str, int, dict]]:
        """``(topic, t_ns, doc)`` in ``t_ns`` order across the selected topics.

        A topic is selected when it is in ``topics`` or starts with one of ``prefixes``; with
        neither, every topic. JSON ``null`` stays ``None`` here. Undecodable messages are
        skipped and counted in ``rejected``.
        """
        chans = self._channels
        loads = json.loads
        for cid, t_ns, _, _, data in self._merged(self._select(topics, prefixes)):
            try:
                doc = loads(data)
            except ValueError as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield chans[cid].topic, t_ns, doc

    def _reject(self, topic: str, t_ns: int, e: BaseException) -> None:
        self.rejected += 1
        if self.rejected <= 20:
            self.problems.append(f"{topic} t_ns={t_ns}: undecodable message skipped "
                                 f"({one_line(e)})")

    def iter_raw_can(self, bus: str | Iterable[str] | None = None):
        """``(bus, can.Message)`` of ``/raw/can/...`` in ``t_ns`` order; ``timestamp`` is
        ``t_ns / 1e9`` (seconds), ``channel`` the bus name, ``is_rx`` from ``direction``."""
        import can

        topics = None if bus is None else \
            [S.RAW_CAN_PREFIX + b for b in ((bus,) if isinstance(bus, str) else bus)]
        cids = self._select(topics, None if topics else (S.RAW_CAN_PREFIX,), S.RAW_CAN)
        chans = self._channels
        for cid, t_ns, _, _, data in self._merged(cids):
            name = chans[cid].topic[len(S.RAW_CAN_PREFIX):]
            try:
                d = json.loads(data)
                fd = d["is_fd"]
                msg = can.Message(timestamp=t_ns / 1e9, arbitration_id=d["arbitration_id"],
                                  is_extended_id=d["is_extended_id"],
                                  is_remote_frame=d["is_remote_frame"],
                                  is_error_frame=d["is_error_frame"], channel=name,
                                  dlc=d["dlc"], data=bytes.fromhex(d["data_hex"]),
                                  is_fd=fd, is_rx=d["direction"] != "tx",
                                  bitrate_switch=fd and d.get("bitrate_switch", False),
                                  error_state_indicator=fd and d.get("error_state_indicator",
                                                                     False),
                                  check=False)
            except (ValueError, KeyError, TypeError) as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield name, msg

    def iter_raw_serial(self, device: str | Iterable[str] | None = None
                        ) -> Iterator[tuple[str, int, bytes]]:
        """``(device, t_ns, bytes)`` of ``/raw/serial/...`` in ``t_ns`` order."""
        topics = None if device is None else \
            [S.RAW_SERIAL_PREFIX + d for d in ((device,) if isinstance(device, str) else device)]
        cids = self._select(topics, None if topics else (S.RAW_SERIAL_PREFIX,), S.RAW_SERIAL)
        chans = self._channels
        for cid, t_ns, _, _, data in self._merged(cids):
            try:
                raw = base64.b64decode(json.loads(data)["data_b64"], validate=True)
            except (ValueError, KeyError, TypeError) as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield chans[cid].topic[len(S.RAW_SERIAL_PREFIX):], t_ns, raw

    def iter_samples(self, prefixes: Iterable[str] | str = (S.DECODED_PREFIX,)):
        """Bus :class:`~vdps_hil.bus.samples.Sample` objects (``vdps.Sample.v1`` channels
        under ``prefixes``, ``/decoded/`` by default) in ``t_ns`` order; null fields -> NaN."""
        from vdps_hil.bus.samples import Sample

        chans = self._channels
        for cid, t_ns, _, _, data in self._merged(self._select(None, prefixes, S.SAMPLE)):
            try:
                sample = Sample.from_json(json.loads(data))
            except (ValueError, KeyError, TypeError) as e:
                self._reject(chans[cid].topic, t_ns, e)
                continue
            yield sample

    # --- lifecycle ------------------------------------------------------------------------------

    def close(self) -> None:
        if self._owns and not self._f.closed:
            self._f.close()

    def __enter__(self) -> "RecordingReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def damage_note(problems, path) -> str:
    """`` (the recording is damaged: ...; `vdps info PATH` lists them)`` for a reader's
    ``problems`` (a missing summary alone is not damage: a recording cut off by a crash still
    reads), else ''. Appended to an error such as "no IMU", so that it is not read as a
    property of the car."""
    problems = [p for p in problems if "no summary" not in p]
    if not problems:
        return ""
    what = f"{len(problems)} problems" if len(problems) > 1 else problems[0]
    return f" (the recording is damaged: {what}; `vdps info {path}` lists them)"


def scan_damage(path) -> list[str]:
    """The problems met reading every record of the recording at ``path`` (an error path's
    second look; [] when it is not an MCAP recording at all)."""
    try:
        with RecordingReader(path) as r:
            for _ in r.iter_records():
                pass
            return list(r.problems)
    except (RecordingError, OSError):
        return []
