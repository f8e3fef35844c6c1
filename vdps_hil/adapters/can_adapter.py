"""CAN adapters: a live bus through python-can, and a recorded log through python-can's readers.

Interface strings are ``INTERFACE:CHANNEL[,key=value...]`` and go to
``can.Bus(interface=INTERFACE, channel=CHANNEL, **kwargs)`` unchanged (``slcan`` goes to a
subclass of python-can's slcan bus that reads in chunks, same options), so every interface
python-can knows works: ``socketcan:can0``, ``pcan:PCAN_USBBUS1,bitrate=500000``,
``slcan:/dev/ttyACM0@115200``, ``virtual:hil``, ``socketcand:127.0.0.1,port=29536`` ...
Values of ``key=value`` are read as int (``500000``, ``0x1F``), float, ``true``/``false`` or
text.

Time: a live frame gets the host monotonic ``t_ns`` when ``recv`` returned it (one clock for
every source); the interface's own time stamp travels on the event as ``device_time_ns`` and
is checked for going backwards (``device_time_backwards``) -- the recording layout
(``vdps.RawCan.v1``) has no slot for it yet, so it is not in the file. A recorded frame's
``t_ns`` is its file time stamp ``round(timestamp * 1e9)``.

Decoding is delegated to a *CAN decoder*: any object with
``decode(t_ns, arbitration_id, data, is_extended_id) -> list[Sample]`` and a ``counters``
mapping (``VdpsCanDecoder`` for ``dbc/vdps.dbc``, :class:`vdps_hil.adapters.signalmap_decoder.SignalMapDecoder`
for a car's own DBC). ``decode_channels``: when a log holds several channels, only frames of
these channels are decoded; the others are counted ``other_channel`` and recorded raw under
their own bus name ``<bus>.<channel>`` (``/raw/can/pt.can1``), never mixed into ``<bus>``.
"""

from __future__ import annotations

import logging
import os
from typing import Any, Iterable, Mapping, Sequence

from vdps_hil.adapters.base import Adapter, AdapterError, DeviceLost, EndOfInput
from vdps_hil.adapters.quiet_readers import collect_half_built, library_noise_off, reader_scratch, reader_scratch_folder
from vdps_hil.adapters.slcan import SlcanLines, fast_slcan_class, lock_port, slcan_line
from vdps_hil.adapters.text_logs import TEXT_SUFFIXES, SkippedLineCount, TextFeed
from vdps_hil.bus.clocks import ReplayClock
from vdps_hil.bus.raw import RawCan

__all__ = ["CanAdapter", "CanFileAdapter", "parse_can_spec", "slcan_line", "CAN_LOG_SUFFIXES"]

CAN_LOG_SUFFIXES = (".asc", ".blf", ".log", ".trc", ".mf4", ".csv", ".db")
"""Log formats python-can reads (``.mf4`` needs asammdf), plus ``.mcap`` (ours)."""


def _value(text: str) -> Any:
    t = text.strip()
    low = t.lower()
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    try:
        return int(t, 0)
    except ValueError:
        pass
    try:
        return float(t)
    except ValueError:
        return t


def parse_can_spec(spec: str) -> tuple[str, str, dict[str, Any]]:
    """``"pcan:PCAN_USBBUS1,bitrate=500000"`` -> ``("pcan", "PCAN_USBBUS1", {"bitrate":
    500000})``. Raises AdapterError (one line) on a malformed string or an interface python-can
    does not know."""
    import can

    if not isinstance(spec, str) or ":" not in spec:
        raise AdapterError(f"CAN interface {spec!r} is not INTERFACE:CHANNEL "
                           "(e.g. socketcan:can0, pcan:PCAN_USBBUS1, virtual:hil)")
    iface, rest = spec.split(":", 1)
    iface = iface.strip()
    parts = rest.split(",")
    channel = parts[0].strip()
    kwargs: dict[str, Any] = {}
    for p in parts[1:]:
        if "=" not in p:
            raise AdapterError(f"CAN interface {spec!r}: option {p!r} is not key=value")
        k, v = p.split("=", 1)
        kwargs[k.strip()] = _value(v)
    known = set(can.interfaces.VALID_INTERFACES)
    if iface not in known:
        raise AdapterError(f"unknown CAN interface {iface!r} in {spec!r} "
                           f"(python-can knows: {', '.join(sorted(known))})")
    if not channel and iface not in ("virtual",):
        raise AdapterError(f"CAN interface {spec!r} has no channel")
    return iface, channel, kwargs


def _clean_channel(channel) -> str:
    return "".join(c if c.isalnum() or c in "_.:-" else "_" for c in str(channel)) or "none"


class _CanDecodeMixin:
    """Decoding and raw records shared by the live and the file adapter."""

    decoder: Any
    decode_channels: frozenset | None
    bus_name: str

    def _raw(self, t_ns, wall_time_ns, msg):
        dev = getattr(msg, "timestamp", None)
        source = self.name
        if self.decode_channels is not None and str(msg.channel) not in self.decode_channels:
            source = f"{self.name}.{_clean_channel(msg.channel)}"  # another physical bus
        return RawCan(t_ns, wall_time_ns, source, msg,
                      "rx" if getattr(msg, "is_rx", True) else "tx",
                      None if dev is None else int(round(dev * 1e9)))

    def _decode(self, t_ns, msg):
        if self.decoder is None or msg.is_error_frame:
            if msg.is_error_frame:
                self.health.count("error_frames")
            return ()
        if self.decode_channels is not None and str(msg.channel) not in self.decode_channels:
            self.health.count("other_channel")
            return ()
        flags = {k: True for k in ("is_fd", "is_remote_frame") if getattr(msg, k)}  # counted rejects
        return self.decoder.decode(t_ns, msg.arbitration_id, bytes(msg.data),
                                   msg.is_extended_id, **flags)

    def decoder_counters(self) -> Mapping[str, int]:
        c = getattr(self.decoder, "counters", None)
        if c is None:
            return {}
        return c() if callable(c) else c

    def _decode_gap(self) -> None:
        reset = getattr(self.decoder, "reset_sequence", None)
        if reset is not None:
            reset()  # frames not decoded are not frames lost on the bus


class CanAdapter(_CanDecodeMixin, Adapter):
    """A live CAN bus through python-can.

    ``bus_name``: the logical bus (topic ``/raw/can/<bus_name>``, source ``can.<bus_name>``).
    ``spec``: an interface string (see the module docstring) or None with ``bus=`` an already
    open ``can.BusABC`` (tests, HIL). ``decoder``: a CAN decoder or None (raw only).
    """

    transport = "can"

    def __init__(self, bus_name: str, spec: str | None = None, *, decoder=None, bus=None,
                 decode_channels: Iterable[str] | None = None, batch: int = 256, **kw):
        super().__init__(f"can.{bus_name}", spec or repr(bus), **kw)
        self.bus_name = bus_name
        self.spec = spec
        self.decoder = decoder
        self.decode_channels = None if decode_channels is None else frozenset(
            str(c) for c in decode_channels)
        self.batch = int(batch)
        self.bus = bus
        self._external_bus = bus is not None
        self._last_dev_ns = -1
        self._slcan: SlcanLines | None = None
        self._port_lock: int | None = None  # slcan: the descriptor holding its port's lock (lock_port)
        if spec is not None:
            self.iface, self.channel, self.bus_kwargs = parse_can_spec(spec)
        elif bus is None:
            raise AdapterError(f"CAN bus {bus_name}: give an interface string or a bus")

    def _open(self) -> None:
        if self._external_bus:
            return
        import can

        try:
            if self.iface == "slcan":  # same protocol and options, reads in chunks; locked (lock_port)
                self._port_lock = lock_port(self.channel)
                try:
                    self.bus = fast_slcan_class()(channel=self.channel, **self.bus_kwargs)
                except BaseException:
                    self._unlock_port()
                    raise
            else:
                self.bus = can.Bus(interface=self.iface, channel=self.channel,
                                   **self.bus_kwargs)
        except (can.CanInterfaceNotImplementedError, ImportError) as e:
            raise AdapterError(f"CAN {self.spec}: interface not available here: "
                               f"{str(e).splitlines()[0] if str(e) else type(e).__name__}") \
                from None
        except (can.CanError, OSError, ValueError, TypeError) as e:
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            if self.health.state == "closed":
                raise AdapterError(f"CAN {self.spec}: cannot open: {msg}") from None
            raise DeviceLost(msg) from None

    def _close(self) -> None:
        if self.bus is not None and not self._external_bus:
            try:
                self.bus.shutdown()
            finally:
                self.bus = None
                self._unlock_port()

    def _unlock_port(self) -> None:
        fd, self._port_lock = self._port_lock, None
        if fd is not None:
            os.close(fd)

    def _read(self, timeout_s: float) -> Sequence[tuple[int | None, Any]]:
        import can

        bus = self.bus
        out = []
        timeout = timeout_s
        for _ in range(self.batch):
            try:
                msg = bus.recv(timeout)
            except (can.CanOperationError, OSError) as e:
                if out:  # deliver what came before; the loss shows at the next read
                    break
                raise DeviceLost(str(e).splitlines()[0] if str(e) else type(e).__name__) \
                    from None
            except (ValueError, IndexError, KeyError, TypeError) as e:
                self.health.count("bad_frames")  # e.g. a malformed slcan line
                self.health.last_error = f"bad frame: {type(e).__name__}: {e}"[:200]
                timeout = 0.0
                continue
            if msg is None:
                break
            out.append((None, msg))
            timeout = 0.0
        for _, m in out:
            ts = m.timestamp
            if ts:
                dev = int(ts * 1e9)
                if dev < self._last_dev_ns:
                    self.health.count("device_time_backwards")
                self._last_dev_ns = dev
        return out

    def reader_fd(self) -> int | None:
        """slcan: the descriptor of the adapter's serial port (a reader process drains it and
        :class:`SlcanLines` parses the lines here); other interfaces: None (a reader thread
        calls ``recv``)."""
        port = getattr(self.bus, "serialPortOrig", None)
        if self._external_bus or port is None:
            return None
        try:
            from serial.serialposix import Serial
        except ImportError:
            return None
        return port.fd if isinstance(port, Serial) and port.fd is not None else None

    def _chunk_items(self, t_ns: int, data: bytes):
        if self._slcan is None:
            self._slcan = SlcanLines(self.health)
        self.health.bytes += len(data)
        return self._slcan.feed(t_ns, data, self.clock.wall(t_ns) / 1e9)

    def _reader_lost(self) -> None:
        if self._slcan is not None:
            self._slcan.reset()

    def send(self, msg) -> None:
        """Send a frame on this bus and publish it as a ``tx`` raw record."""
        import can

        try:
            self.bus.send(msg)
        except (can.CanOperationError, OSError) as e:
            self.health.count("send_errors")
            self.health.last_error = str(e).splitlines()[0] if str(e) else "send failed"
            return
        t, wall = self.clock.now()
        self._publish(RawCan(t, wall, self.name, msg, "tx", None))
        self.health.count("sent")


class CanFileAdapter(_CanDecodeMixin, Adapter):
    """A recorded CAN log read through python-can's readers (asc, blf, candump log, trc, mf4,
    csv, db, and ``.mcap`` through our plugin), replayed as fast as it can be read.

    Text formats go line by line: a line python-can cannot parse is skipped and counted
    (``bad_lines``, with the first in ``last_error``), bytes that are not UTF-8 too
    (``non_utf8_lines``), and reading goes on after them. A binary file that breaks off ends
    the input there (``read_errors`` when python-can raises).

    ``channels``: keep only frames of these channels (``msg.channel`` as text; None: all).
    ``decode_channels``: see the module docstring.
    """

    transport = "can"

    def __init__(self, bus_name: str, path: str | os.PathLike, *, decoder=None,
                 channels: Iterable[str] | None = None,
                 decode_channels: Iterable[str] | None = None, batch: int = 4096, **kw):
        kw.setdefault("clock", ReplayClock())
        super().__init__(f"can.{bus_name}", os.fspath(path), **kw)
        self.bus_name = bus_name
        self.path = os.fspath(path)
        self.decoder = decoder
        self.channels = None if channels is None else frozenset(str(c) for c in channels)
        self.decode_channels = None if decode_channels is None else frozenset(
            str(c) for c in decode_channels)
        self.batch = int(batch)
        self._reader = None
        self._it = None
        self._feed: TextFeed | None = None
        self._raw_file = None
        self._reader_cls = None
        self._scratch = None  # asammdf's working copies of an MF4 (adapters.quiet_readers)
        self._log_handler = SkippedLineCount(self)

    def _make_reader(self):
        if self._feed is not None:
            return self._reader_cls(file=self._feed)
        import can

        return can.LogReader(self.path)

    def _open(self) -> None:
        from can.io.player import MESSAGE_READERS, _update_reader_plugins

        if not os.path.isfile(self.path):
            raise AdapterError(f"CAN log {self.path}: no such file")
        suffix = os.path.splitext(self.path)[1].lower()
        err = None  # raised after the reader's leftovers are gone (adapters.quiet_readers)
        self._scratch = reader_scratch(suffix)
        with library_noise_off(), reader_scratch_folder(self._scratch):
            try:
                if suffix in TEXT_SUFFIXES:
                    _update_reader_plugins()
                    self._reader_cls = MESSAGE_READERS[suffix]
                    self._raw_file = open(self.path, "rb")
                    self._feed = TextFeed(self._raw_file, self.health.counters)
                self._reader = self._make_reader()
                self._it = iter(self._reader)
            except ValueError as e:  # a known format that breaks, or python-can's "unknown log format"
                first = (str(e).splitlines() or [type(e).__name__])[0]
                err = (f"unreadable: {first}" if suffix in (*CAN_LOG_SUFFIXES, ".mcap")
                       else f"{first} (readable: {', '.join(CAN_LOG_SUFFIXES)}, .mcap)")
            except ImportError as e:
                err = f"needs an optional package: {e}"
            except OSError as e:
                err = f"{e.strerror or e}"
            except Exception as e:  # noqa: BLE001 - a broken file is the person's input
                err = f"unreadable: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
            if err is not None:
                collect_half_built()
        if err is not None:
            self._close()
            raise AdapterError(f"CAN log {self.path}: {err}")

    @property
    def lines_read(self) -> int | None:
        """Lines of a text log read so far (all channels', for a progress bar); None if binary."""
        return None if getattr(self, "_feed", None) is None else self._feed.consumed

    def _close(self) -> None:
        if self._reader is not None:
            try:
                self._reader.stop()
            except Exception:  # noqa: BLE001
                pass
            self._reader = None
        if self._raw_file is not None:
            self._raw_file.close()
            self._raw_file = None
        if self._scratch is not None:
            self._scratch.cleanup()
            self._scratch = None

    def _bad_line(self, e: BaseException) -> bool:
        """A text reader failed on the feed's last line: count it, continue after it.
        Returns False when there is nothing left to try."""
        h = self.health
        feed = self._feed
        h.count("bad_lines")
        if h.counters["bad_lines"] == 1:
            h.last_error = f"first bad line {feed.last.strip()[:80]!r}: {type(e).__name__}"
        before = feed.consumed
        feed.restart()
        try:
            self._reader = self._make_reader()
            self._it = iter(self._reader)
        except Exception:  # noqa: BLE001
            return False
        self._restart_consumed = before
        return True

    def _read(self, timeout_s: float) -> Sequence[tuple[int | None, Any]]:
        # python-can's readers report skipped lines through the "can.io" logger: count them
        # for this adapter while it reads (and keep them off the console)
        lg = logging.getLogger("can.io")
        saved = (lg.propagate, lg.level)
        lg.addHandler(self._log_handler)
        lg.propagate = False
        lg.setLevel(logging.INFO)  # TRC reports dropped lines at INFO
        try:
            return self._read_batch()
        finally:
            lg.removeHandler(self._log_handler)
            lg.propagate, level = saved
            lg.setLevel(level)

    def _read_batch(self) -> Sequence[tuple[int | None, Any]]:
        if self._it is None:
            raise EndOfInput()
        out = []
        chans = self.channels
        feed = self._feed
        while len(out) < self.batch and self._it is not None:
            try:
                for msg in self._it:
                    if feed is not None:
                        feed.message_seen()
                    if chans is not None and str(msg.channel) not in chans:
                        continue
                    out.append((int(round(msg.timestamp * 1e9)), msg))
                    if len(out) >= self.batch:
                        break
                else:
                    self._it = None
            except Exception as e:  # noqa: BLE001 - damaged input: count, go on if we can
                if feed is not None and feed.consumed > getattr(self, "_restart_consumed", -1):
                    if self._bad_line(e):
                        continue
                self.health.count("read_errors")
                self.health.last_error = (f"{type(e).__name__}: "
                                          f"{str(e).splitlines()[0] if str(e) else ''}")
                self._it = None
        if not out and self._it is None:
            raise EndOfInput()
        return out
