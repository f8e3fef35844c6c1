"""The live view (``--serve PORT`` of ``vdps replay``, ``vdps log`` and ``vdps bench``): the topics
a run writes, also served to Foxglove over its WebSocket protocol by the foxglove-sdk's server,
bound to 127.0.0.1 only (Foxglove: Open connection -> Foxglove WebSocket ->
``ws://127.0.0.1:PORT``; the layout ``configs/foxglove/vdps-layout.json`` applies unchanged).

:class:`LiveServer` has the writer methods the system's outputs and the Foxglove view use
(``write_json``, ``write_encoded``, ``write_estimate``, ``write_sample``): each topic becomes one
server channel with the recording's JSON schema (``record.schemas``), each message the recording's
bytes, its log time ``epoch_ns + t_ns`` (a replay: the output's clock) or the wall clock at the
write (a live run, ``epoch_ns=None``). :class:`TeeWriter` writes to a recording and to the server;
:class:`ServedSide` gives a replay's recording side a writer that also serves (or only serves,
without ``-o``). The server runs in its own context, so nothing else (no global MCAP sink) sees
these channels. Messages logged while no client subscribes to a channel are dropped by the server
(a live view, not a recording); a replay waits for its first subscriber (``wait_for_subscriber``)
so the view starts at the beginning.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Mapping

import foxglove
from foxglove.websocket import ServerListener

from vdps_hil.record import schemas as S
from vdps_hil.record.payloads import estimate_payload, estimate_topic, json_payload

__all__ = ["LAYOUT_TOPICS", "LOCALHOST", "LiveServer", "LiveServerError", "ServedSide", "TeeWriter"]

LOCALHOST = "127.0.0.1"
"""The only address the server binds (project rule: network servers on 127.0.0.1)."""


LAYOUT_TOPICS = {"/est/state": S.ESTIMATE, "/est/prediction": S.ESTIMATE, "/est/ident": S.ESTIMATE,
                 "/est/filtered": S.ESTIMATE, "/est/warning": S.SAMPLE, S.GNSS_FIX_TOPIC: S.LOCATION_FIX,
                 S.EST_FIX_TOPIC: S.LOCATION_FIX, S.EST_TF_TOPIC: S.FRAME_TRANSFORM, S.EST_POSE_TOPIC: S.POSE_IN_FRAME}
"""The topics of the layout every run has, advertised before data flows (``advertise``)."""


class LiveServerError(ValueError):
    """The server cannot start (port in use, bad port): one line."""


SUBSCRIBE_SETTLE_S = 0.2
"""Time between the first ``on_subscribe`` and the first message (``wait_for_subscriber``)."""


class _Listener(ServerListener):
    """The server's listener: sets ``subscribed`` at the first subscription (the other events
    keep the SDK's defaults)."""

    def __init__(self):
        self.subscribed = threading.Event()

    def on_subscribe(self, client, channel) -> None:
        self.subscribed.set()


class LiveServer:
    """A Foxglove WebSocket server on ``127.0.0.1:port`` (0: a free port, read ``port``) serving
    what is written to it (module docstring). ``close()`` stops it; a context manager."""

    def __init__(self, port: int = 8765, *, name: str = "vdps", epoch_ns: int | None = None):
        if not 0 <= int(port) <= 65535:
            raise LiveServerError(f"--serve {port}: a port is 0..65535")
        self.epoch_ns = epoch_ns
        self._context = foxglove.Context()
        self._listener = _Listener()
        try:
            self._server = foxglove.start_server(name=name, host=LOCALHOST, port=int(port), context=self._context,
                                                 server_listener=self._listener)
        except Exception as e:  # noqa: BLE001 - the SDK raises its own error types for a busy port
            raise LiveServerError(f"--serve {port}: cannot listen on {LOCALHOST}:{port}: "
                                  f"{str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
        self._channels: dict[str, object] = {}
        self._lock = threading.Lock()
        self.sent = 0
        self.refused = 0

    @property
    def port(self) -> int:
        return self._server.port

    @property
    def url(self) -> str:
        return f"ws://{LOCALHOST}:{self.port}"

    def wait_for_subscriber(self, timeout_s: float | None = None) -> bool:
        """Block until a client subscribes to a channel (True) or ``timeout_s`` passes (False).
        The SDK calls ``on_subscribe`` before it routes the channel to the client: a message
        logged at once is lost (seen on a quiet machine), so this returns ``SUBSCRIBE_SETTLE_S``
        after the first subscription."""
        if not self._listener.subscribed.wait(timeout_s):
            return False
        time.sleep(SUBSCRIBE_SETTLE_S)
        return True

    def advertise(self, topics: Mapping[str, str]) -> None:
        """Open the channels ``{topic: schema name}`` now (a client can subscribe before data flows)."""
        for topic, schema_name in topics.items():
            self._channel(topic, schema_name, None)

    def _channel(self, topic: str, schema_name: str, metadata: Mapping[str, str] | None):
        ch = self._channels.get(topic)
        if ch is None:
            with self._lock:
                ch = self._channels.get(topic)
                if ch is None:
                    schema = foxglove.Schema(name=schema_name, encoding="jsonschema",
                                       data=json.dumps(S.SCHEMAS[schema_name]).encode())
                    ch = self._channels[topic] = foxglove.Channel(
                        topic, schema=schema, message_encoding="json", context=self._context,
                        metadata={str(k): str(v) for k, v in (metadata or {}).items()})
        return ch

    def _stamp(self, t_ns: int, wall_time_ns: int | None) -> int:
        if wall_time_ns:
            return int(wall_time_ns)
        return self.epoch_ns + int(t_ns) if self.epoch_ns is not None else time.time_ns()

    def write_encoded(self, topic: str, schema_name: str, t_ns: int, payload: bytes, *,
                      wall_time_ns: int | None = None, channel_metadata: Mapping[str, str] | None = None) -> None:
        self._channel(topic, schema_name, channel_metadata).log(bytes(payload),
                                                                log_time=self._stamp(t_ns, wall_time_ns))
        self.sent += 1

    def write_json(self, topic: str, schema_name: str, t_ns: int, doc, *, wall_time_ns: int | None = None,
                   channel_metadata: Mapping[str, str] | None = None) -> None:
        self.write_encoded(topic, schema_name, t_ns, json_payload(topic, schema_name, t_ns, doc), wall_time_ns=wall_time_ns,
                           channel_metadata=channel_metadata)

    def write_estimate(self, topic: str, t_ns: int, values, sigmas=None) -> None:
        self.write_encoded(estimate_topic(topic), S.ESTIMATE, t_ns, estimate_payload(t_ns, values, sigmas))

    def write_sample(self, sample, topic: str | None = None) -> None:
        self.write_json(topic or S.sample_topic(sample.source, sample.kind), S.SAMPLE, sample.t_ns,
                        sample.to_json(), wall_time_ns=sample.wall_time_ns or None,
                        channel_metadata={"source": sample.source, "kind": sample.kind})

    def mirror(self, topic: str, schema_name: str, t_ns: int, payload: bytes, log_time_ns: int,
               channel_metadata: Mapping[str, str] | None = None) -> None:
        """``RecordingWriter.mirror``: serve each message a recording writes as written, except the
        ``/raw/`` topics (hex and base64, not plottable; the decoded ones are served); never
        raises (a refused message is counted in ``refused``)."""
        if topic.startswith(S.RAW_PREFIX):
            return
        try:
            self.write_encoded(topic, schema_name, t_ns, payload, wall_time_ns=log_time_ns,
                               channel_metadata=channel_metadata)
        except (ValueError, TypeError, KeyError, OverflowError, RuntimeError):
            self.refused += 1

    def close(self) -> None:
        if self._server is not None:
            self._server.stop()
            self._server = None

    def __enter__(self) -> "LiveServer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class TeeWriter:
    """The writer methods of :class:`LiveServer`, each called on ``writer`` and then on ``live``
    (a message the server refuses never costs the recording: counted in ``refused``)."""

    def __init__(self, writer, live: LiveServer):
        self.writer, self.live = writer, live
        self.refused = 0

    def _both(self, name: str, *args, **kw) -> None:
        getattr(self.writer, name)(*args, **kw)
        try:
            getattr(self.live, name)(*args, **kw)
        except (ValueError, TypeError, KeyError, OverflowError, RuntimeError):
            self.refused += 1

    def write_encoded(self, *args, **kw) -> None:
        self._both("write_encoded", *args, **kw)

    def write_json(self, *args, **kw) -> None:
        self._both("write_json", *args, **kw)

    def write_estimate(self, *args, **kw) -> None:
        self._both("write_estimate", *args, **kw)

    def write_sample(self, *args, **kw) -> None:
        self._both("write_sample", *args, **kw)


class ServedSide:
    """A replay's recording side (``app.replay_io``) whose ``writer`` also serves: the side's own
    writer teed with ``live``, or ``live`` alone while the side has none (no ``-o``, or before the
    output opened)."""

    def __init__(self, side, live: LiveServer):
        self._side, self._live = side, live
        self._tee: TeeWriter | None = None

    @property
    def writer(self):
        w = self._side.writer
        if w is None:
            return self._live
        if self._tee is None or self._tee.writer is not w:
            self._tee = TeeWriter(w, self._live)
        return self._tee
