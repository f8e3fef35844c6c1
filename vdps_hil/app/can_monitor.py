"""``vdps monitor SOURCE``: the decoded CAN signals of a live bus or a recording, by message, in
the terminal (``cantools monitor``/``cansniffer``), with the values that changed highlighted.

Each frame is decoded with its bus's DBC into the DBC's signals (scaled values, the DBC's units;
cantools' arithmetic through the DBC description of ``codecs.dbc_cache``, the compiled layout
where it compiles). A frame whose ID the DBC does not define is shown as its payload in hex.
Per message the table keeps the frame count, the mean period and per signal the last value,
how often it changed and when; a value that changed within ``highlight_s`` is drawn in reverse
video on a terminal.

Sources: a recording (``.mcap``: its ``/raw/can/`` topics, each bus with the DBC its metadata
names, found as ``vdps replay`` and ``vdps plot`` find it, ``record.recorded_decoding``; the
``vdps`` bus with ``dbc/vdps.dbc``), played at its own pace times ``speed`` (0: at once); or a
python-can interface string (``virtual:hil``, ``socketcan:can0``, ``pcan:PCAN_USBBUS1,bitrate=500000``;
``adapters.can_adapter.parse_can_spec``) or ``-`` (``candump -L`` lines on standard input,
``adapters.candump_stream``; the end of the input ends the monitor) decoded with ``dbc`` (default
``dbc/vdps.dbc``).

Filters: ``ids`` (frame IDs, ``0x100`` or ``256``, or message names) keeps only those messages;
``signals`` (shell patterns on signal names, case-insensitive) keeps only matching signals and
the messages that have one.
"""

from __future__ import annotations

import fnmatch
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Iterable, Iterator

__all__ = ["MonitorError", "CanMonitor", "render", "run_monitor", "parse_ids"]

REVERSE, RESET = "\x1b[7m", "\x1b[0m"
HOME, CLEAR_LINE, CLEAR_BELOW = "\x1b[H", "\x1b[K", "\x1b[J"


class MonitorError(ValueError):
    """A source that cannot be opened, a DBC that cannot be loaded, a bad filter: one line."""


@dataclass
class SignalState:
    """The last ``value`` of one signal, its ``unit``, how often it ``changes`` and when (``changed_ns``)."""

    value: float | str
    unit: str
    changes: int = 0
    changed_ns: int = -(1 << 62)


@dataclass
class MessageState:
    """One (bus, frame ID): its DBC ``name`` (None: not in the DBC), frames seen, first and last
    time, the last payload and its signals."""

    bus: str
    frame_id: int
    name: str | None
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0
    data: bytes = b""
    signals: dict[str, SignalState] = field(default_factory=dict)

    def period_ms(self) -> float | None:
        return None if self.count < 2 else (self.last_ns - self.first_ns) / (self.count - 1) / 1e6


def parse_ids(items: Iterable[str]) -> tuple[set[int], set[str]]:
    """``--id`` values (repeatable, comma separated) -> (frame IDs, message names)."""
    ids, names = set(), set()
    for item in items:
        for tok in (t.strip() for t in item.split(",")):
            if not tok:
                continue
            try:
                ids.add(int(tok, 0))
            except ValueError:
                if not tok.replace("_", "").isalnum():
                    raise MonitorError(f"--id {tok!r}: give a frame ID (0x100, 256) or a message name") from None
                names.add(tok)
    return ids, names


class _BusDecoder:
    """Frames of one bus -> {signal: value} by its DBC (None: ID not in the DBC)."""

    def __init__(self, db):
        self.messages = {} if db is None else {(m.frame_id, bool(m.is_extended_frame)): m for m in db.messages}
        self._plans: dict = {}

    def decode(self, frame_id: int, extended: bool, data: bytes):
        m = self.messages.get((frame_id, bool(extended)))
        if m is None:
            return None, None
        if len(data) == m.length:
            plan = self._plans.get(m.name, False)
            if plan is False:
                from vdps_hil.codecs.dbc_compile import NotCompilable, compile_message

                try:
                    plan = compile_message(m)
                except NotCompilable:
                    plan = None
                self._plans[m.name] = plan
            if plan is not None:
                return m, {s.name: s.conversion.raw_to_scaled(r, False) for s, r in zip(m.signals, plan.raw(data))}
        try:
            return m, m.decode(data, decode_choices=False, scaling=True, allow_truncated=True, allow_excess=True)
        except Exception:  # noqa: BLE001 - cantools' DecodeError and friends: shown as hex
            return m, None


class CanMonitor:
    """The table of messages (module docstring). ``decoders``: bus -> DBC description (None:
    raw hex only); ``ids``/``names``: the ``--id`` filter; ``patterns``: the ``--signal`` filter."""

    def __init__(self, decoders: dict, *, ids: set[int] = frozenset(), names: set[str] = frozenset(),
                 patterns: Iterable[str] = ()):
        self._dec = {bus: _BusDecoder(db) for bus, db in decoders.items()}
        self.ids, self.names = set(ids), {n.lower() for n in names}
        self.patterns = [p.lower() for p in patterns]
        self.messages: dict[tuple[str, int, bool], MessageState] = {}
        self.frames = 0
        self.shown = 0

    def _wanted(self, frame_id: int, name: str | None) -> bool:
        if not (self.ids or self.names):
            return True
        return frame_id in self.ids or (name is not None and name.lower() in self.names)

    def _signal_wanted(self, name: str) -> bool:
        return not self.patterns or any(fnmatch.fnmatchcase(name.lower(), p) for p in self.patterns)

    def feed(self, bus: str, t_ns: int, frame_id: int, extended: bool, data: bytes) -> bool:
        """One frame; True when it is in the table (passes the filters)."""
        self.frames += 1
        key = (bus, frame_id, bool(extended))
        st = self.messages.get(key)
        if st is None:
            dec = self._dec.get(bus) or self._dec.setdefault(bus, _BusDecoder(None))
            m = dec.messages.get((frame_id, bool(extended)))
            name = None if m is None else m.name
            if not self._wanted(frame_id, name) or \
                    (self.patterns and (m is None or not any(self._signal_wanted(g.name) for g in m.signals))):
                return False
            st = self.messages[key] = MessageState(bus, frame_id, name, first_ns=t_ns)
        st.count += 1
        st.last_ns = t_ns
        self.shown += 1
        if data == st.data and st.count > 1:
            return True
        st.data = bytes(data)
        m, values = self._dec[bus].decode(frame_id, extended, st.data)
        if values is None:
            values, units = {"data": st.data.hex(" ").upper()}, {}
        else:
            units = {s.name: s.unit or "" for s in m.signals}
        for sig, v in values.items():
            if not self._signal_wanted(sig):
                continue
            s = st.signals.get(sig)
            if s is None:
                st.signals[sig] = SignalState(v, units.get(sig, ""), 0, t_ns if st.count > 1 else -(1 << 62))
            elif s.value != v:
                s.value, s.changes, s.changed_ns = v, s.changes + 1, t_ns
        return True


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def render(mon: CanMonitor, now_ns: int, *, title: str, color: bool, highlight_s: float = 1.0,
           rows: int | None = None, width: int = 100) -> list[str]:
    """The table as lines: a title line, per message a header (bus, ID, name, frames, period)
    and its signals (value, unit, changes); ``color``: reverse video on recent changes."""
    out = [f"{title}   frames {mon.frames}, shown {mon.shown}, messages {len(mon.messages)}"[:width],
           f"{'bus':<8} {'ID':>10}  {'message / signal':<34} {'value':>16}  {'unit':<8} {'changes':>8}"[:width]]
    window = int(highlight_s * 1e9)
    for (bus, fid, ext), st in sorted(mon.messages.items(), key=lambda kv: (kv[0][0], kv[0][1])):
        per = st.period_ms()
        ident = f"0x{fid:08X}" if ext else f"0x{fid:03X}"
        head = f"{bus:<8} {ident:>10}  {(st.name or '(not in the DBC)'):<34} {st.count:>9} frames"
        out.append((head + ("" if per is None else f"  {per:.1f} ms"))[:width])
        for sig, s in st.signals.items():
            val = _fmt(s.value)
            cell = f"{val:>16}"
            if color and now_ns - s.changed_ns <= window:
                cell = f"{REVERSE}{cell}{RESET}"
            out.append(f"{'':<8} {'':>10}    {sig:<32} {cell}  {s.unit:<8} {s.changes:>8}")
    if rows is not None and len(out) > rows:
        out = out[:rows - 1] + [f"... {len(out) - rows + 1} more lines (narrow with --id / --signal)"]
    return out


@dataclass
class Frame:
    bus: str
    t_ns: int
    frame_id: int
    extended: bool
    data: bytes


def _dbc(path, strict: bool = True):
    from vdps_hil.adapters.signalmap import SignalMapError
    from vdps_hil.adapters.signalmap_decoder import load_dbc

    try:
        return load_dbc(path, strict=strict)
    except (SignalMapError, ValueError) as e:
        raise MonitorError(str(e).splitlines()[0]) from None


def recording_source(path, dbc=None, signalmap=None) -> tuple[dict, Iterator[Frame]]:
    """(bus -> DBC, frames) of a recording's ``/raw/can/`` topics (module docstring)."""
    from vdps_hil.adapters.signalmap import SignalMapError, load_signalmap
    from vdps_hil.codecs.can_dbc import DEFAULT_DBC_PATH, recorded_vdps_dbc
    from vdps_hil.record import schemas as S
    from vdps_hil.record.reader import RecordingError, RecordingReader
    from vdps_hil.record.recorded_decoding import RecordedDecodingError, find_recorded_decoding

    try:
        reader = RecordingReader(path)
    except RecordingError as e:
        raise MonitorError(str(e)) from None
    try:
        buses = [t[len(S.RAW_CAN_PREFIX):] for t in reader.topics() if t.startswith(S.RAW_CAN_PREFIX)]
        if not buses:
            raise MonitorError(f"{os.fspath(path)}: no /raw/can/ topics to monitor")
        rd = find_recorded_decoding(reader, path, dbc=dbc, signalmap=signalmap)
        sigmap = None if rd.signalmap is None else load_signalmap(rd.signalmap)
        vdps_dbc = recorded_vdps_dbc(reader.metadata().get(S.METADATA_NAME, {})) or DEFAULT_DBC_PATH
        dbs = {}
        for bus in buses:
            bm = None if sigmap is None else sigmap.bus(bus)
            p = rd.dbc if rd.dbc is not None and (bm is not None or sigmap is None) else \
                (bm.dbc if bm is not None else (vdps_dbc if bus == "vdps" else None))
            dbs[bus] = None if p is None else _dbc(p, bm.dbc_strict if bm is not None else True)
    except (RecordedDecodingError, SignalMapError) as e:
        reader.close()
        raise MonitorError(str(e).splitlines()[0]) from None
    except BaseException:
        reader.close()
        raise

    def frames():
        with reader:
            for bus, msg in reader.iter_raw_can():
                if not (msg.is_remote_frame or msg.is_error_frame):
                    yield Frame(bus, round(msg.timestamp * 1e9), msg.arbitration_id, msg.is_extended_id,
                                bytes(msg.data))

    return dbs, frames()


def bus_source(spec: str, dbc=None, bus_name: str = "can") -> tuple[dict, Iterator[Frame | None]]:
    """(bus -> DBC, frames) of a live python-can bus; yields None about every 0.1 s without a frame."""
    from vdps_hil.adapters.base import AdapterError
    from vdps_hil.adapters.can_adapter import parse_can_spec
    from vdps_hil.codecs.can_dbc import DEFAULT_DBC_PATH

    from vdps_hil.adapters.base import EndOfInput
    from vdps_hil.adapters.candump_stream import STDIN_SPEC, CandumpStreamBus

    db = _dbc(dbc if dbc is not None else DEFAULT_DBC_PATH)
    import can

    if spec == STDIN_SPEC:
        bus = CandumpStreamBus(sys.stdin.buffer)
    else:
        try:
            iface, channel, kwargs = parse_can_spec(spec)
        except AdapterError as e:
            raise MonitorError(str(e)) from None
        try:
            bus = can.Bus(interface=iface, channel=channel, **kwargs)
        except Exception as e:  # noqa: BLE001 - python-can raises many types for a missing device
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise MonitorError(f"cannot open CAN interface {spec!r}: {msg}") from None

    def frames():
        try:
            while True:
                try:
                    msg = bus.recv(0.1)
                except ValueError:  # a candump line that does not parse: skipped
                    continue
                except EndOfInput:
                    return
                if msg is None:
                    yield None
                elif not (msg.is_remote_frame or msg.is_error_frame):
                    yield Frame(bus_name, time.monotonic_ns(), msg.arbitration_id, msg.is_extended_id, bytes(msg.data))
        finally:
            bus.shutdown()

    return {bus_name: db}, frames()


def run_monitor(source: str, *, dbc=None, signalmap=None, ids=(), signals=(), once: bool = False,
                duration_s: float | None = None, speed: float = 1.0, refresh_hz: float = 10.0,
                highlight_s: float = 1.0, out=None) -> CanMonitor:
    """Monitor ``source`` (module docstring) until its end, ``duration_s`` of its time, or Ctrl-C.
    On a terminal (and not ``once``) the table is redrawn ``refresh_hz`` times a second; otherwise
    it is printed once at the end, without escape sequences."""
    out = out or sys.stdout
    id_set, names = parse_ids(ids)
    is_file = source.lower().endswith(".mcap") or os.path.isfile(source)
    if not is_file and (signalmap is not None):
        raise MonitorError("--signalmap is for a recording; give a live bus --dbc FILE")
    if not is_file and once and duration_s is None and source != "-":
        raise MonitorError("--once on a live bus needs --duration SECONDS")
    if not speed >= 0:
        raise MonitorError("--speed must be >= 0")
    dbs, frames = recording_source(source, dbc, signalmap) if is_file else bus_source(source, dbc)
    mon = CanMonitor(dbs, ids=id_set, names=names, patterns=signals)
    live = not once and out.isatty()
    size = os.get_terminal_size(out.fileno()) if live else os.terminal_size((100, 10_000))
    pace = is_file and live and speed > 0
    t0_src = t0_wall = None
    now = 0
    next_draw = 0.0

    def draw():
        lines = render(mon, now, title=f"vdps monitor {source}", color=live, highlight_s=highlight_s,
                       rows=None if not live else size.lines - 1, width=size.columns)
        if live:
            out.write(HOME + "".join(f"{ln}{CLEAR_LINE}\n" for ln in lines) + CLEAR_BELOW)
        else:
            out.write("\n".join(lines) + "\n")
        out.flush()

    try:
        for fr in frames:
            wall = time.monotonic()
            if fr is not None:
                if t0_src is None:
                    t0_src, t0_wall = fr.t_ns, wall
                if duration_s is not None and fr.t_ns - t0_src > duration_s * 1e9:
                    break
                while pace and (ahead := (fr.t_ns - t0_src) / 1e9 / speed - (time.monotonic() - t0_wall)) > 0:
                    time.sleep(min(ahead, 1.0 / refresh_hz))
                    if time.monotonic() >= next_draw:
                        draw()
                        next_draw = time.monotonic() + 1.0 / refresh_hz
                wall = time.monotonic()
                now = fr.t_ns
                mon.feed(fr.bus, fr.t_ns, fr.frame_id, fr.extended, fr.data)
            elif not is_file:
                now = time.monotonic_ns()
                if t0_src is None:
                    t0_src, t0_wall = now, wall
                if duration_s is not None and now - t0_src > duration_s * 1e9:
                    break
            if live and wall >= next_draw:
                draw()
                next_draw = wall + 1.0 / refresh_hz
    except KeyboardInterrupt:
        pass
    finally:
        close = getattr(frames, "close", None)
        if close is not None:
            close()
    draw()
    return mon
