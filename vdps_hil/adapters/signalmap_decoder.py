"""Applying a signal map (``adapters.signalmap``) to one CAN bus: the bus's DBC loaded (parsed by
cantools, never by hand, and its description cached as JSON by ``codecs.dbc_cache``) and
``SignalMapDecoder``, which turns each frame into a bus sample by the map's rules. Frames of
layouts that compile (``codecs.dbc_compile``) are decoded without importing cantools, the
others by cantools.

Counters of :class:`SignalMapDecoder`: ``frames``, ``decoded`` (mapped frames that gave a
sample), ``unmapped`` (in the DBC, not in the map: decoded only to check them),
``unknown_id`` (not in the DBC: not an error), ``dlc_mismatch`` (payload length differs from
the DBC; a longer payload is decoded from its first bytes, a shorter one as far as it goes),
``undecodable`` (cantools could not decode: a decode error), ``checksum_mismatch`` and
``counter_jump`` (the sample is kept with ``valid=False``), ``missing_signal`` (a mapped signal
absent from the frame).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

from vdps_hil.adapters.signalmap import CHECKSUMS, BusMap, MessageRule, SignalMap, SignalMapError
from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.dbc_cache import DbcDescription, load_description

__all__ = ["SignalMapDecoder", "load_dbc", "build_decoder"]

log = logging.getLogger(__name__)


def load_dbc(path: str | os.PathLike, *, strict: bool = True) -> DbcDescription:
    """Load a DBC: its description (``codecs.dbc_cache``: cached, else parsed by cantools;
    ``strict=False`` logs that it is lax). SignalMapError on failure, suggesting
    ``dbc_strict = false`` when only the strict checks fail."""
    p = Path(path).resolve()
    if not p.is_file():
        raise SignalMapError(f"DBC {p}: no such file")
    try:
        db = load_description(p, strict=strict)  # cantools' warnings silenced there
    except Exception as e:  # noqa: BLE001 - OSError, cantools raises many types
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        if strict:
            try:
                load_description(p, strict=False)
            except Exception:  # noqa: BLE001
                pass
            else:
                raise SignalMapError(f"DBC {p} fails cantools' strict checks ({msg}); set "
                                     "dbc_strict = false in the signal map to load it anyway") \
                    from None
        raise SignalMapError(f"DBC {p}: cannot load: {msg}") from None
    if not strict and p not in _LAX_LOGGED:  # once per file: a diagnosis loads it for every pass
        _LAX_LOGGED.add(p)
        log.warning("DBC %s loaded with strict=False (the signal map allows it)", p)
    return db


_LAX_LOGGED: set[Path] = set()


# --- the decoder ----------------------------------------------------------------------------

class _Compiled:
    __slots__ = ("rule", "message", "length", "counter_mod", "last_counter", "checksum")

    def __init__(self, rule: MessageRule, message):
        self.rule, self.message = rule, message
        self.length = message.length
        self.checksum = CHECKSUMS.get(rule.checksum)
        self.counter_mod = 0
        self.last_counter = None
        if rule.counter:
            sig = next((s for s in message.signals if s.name == rule.counter), None)
            if sig is None:
                raise SignalMapError(f"frame 0x{rule.frame_id:X}: counter signal "
                                     f"{rule.counter!r} is not in the DBC message")
            self.counter_mod = 1 << sig.length


def _compile(message):
    """(compiled layout, conversions) of a DBC message, or None when it does not compile."""
    from vdps_hil.codecs.dbc_compile import NotCompilable, compile_message

    try:
        comp = compile_message(message)
    except NotCompilable:
        return None
    return comp, tuple(s.conversion for s in message.signals)


class SignalMapDecoder:
    """Decode one bus's frames with its DBC and signal map into bus samples.

    Same interface as ``VdpsCanDecoder``: ``decode(t_ns, arbitration_id, data,
    is_extended_id) -> list[Sample]`` never raises on frame content; ``counters`` (module
    docstring). ``db``: the DBC from :func:`load_dbc` (a cantools database works too);
    ``source``: the samples' source (default ``can.<bus>``).
    """

    def __init__(self, bus_map: BusMap, db, *, source: str | None = None):
        self.bus_map = bus_map
        self.db = db
        self.source = source or f"can.{bus_map.name}"
        self._c = {k: 0 for k in ("frames", "decoded", "unmapped", "unknown_id",
                                  "dlc_mismatch", "undecodable", "checksum_mismatch",
                                  "counter_jump", "missing_signal", "remote_frame",
                                  "fd_mismatch")}
        self._by_key: dict[tuple[int, bool], _Compiled | None] = {}
        self._fast: dict[tuple[int, bool], tuple | None] = {}  # compiled layouts (None: cantools)
        self._dbc_msgs: dict[tuple[int, bool], Any] = {}
        for m in db.messages:
            self._dbc_msgs[(m.frame_id, bool(m.is_extended_frame))] = m
        for key, rule in bus_map.messages.items():
            m = self._dbc_msgs.get(key)
            if m is None:
                raise SignalMapError(f"signal map bus {bus_map.name}: frame 0x{key[0]:X} "
                                     f"({rule.name or 'unnamed'}) is not in the DBC")
            if rule.name and rule.name != m.name:
                log.warning("signal map bus %s: frame 0x%X is %s in the DBC, not %s",
                            bus_map.name, key[0], m.name, rule.name)
            names = {s.name for s in m.signals}
            for r in rule.rules:
                for s in r.signals:
                    if s not in names:
                        raise SignalMapError(f"signal map bus {bus_map.name}: frame 0x{key[0]:X}"
                                             f" ({m.name}) has no signal {s!r}")
            if rule.valid_signal and rule.valid_signal not in names:
                raise SignalMapError(f"signal map bus {bus_map.name}: frame 0x{key[0]:X} has no "
                                     f"signal {rule.valid_signal!r}")
            self._by_key[key] = _Compiled(rule, m)

    @property
    def counters(self) -> Mapping[str, int]:
        return MappingProxyType(self._c)

    def fields(self) -> set[str]:
        return self.bus_map.fields()

    def decode(self, t_ns: int, arbitration_id: int, data: bytes, is_extended_id: bool = False,
               *, is_fd: bool = False, is_remote_frame: bool = False) -> list[Sample]:
        """A frame -> ``[Sample]`` or ``[]`` (counted): a remote frame carries no signals
        (``remote_frame``), a CAN FD frame of a classic message or a classic frame of an FD
        message is not that message (``fd_mismatch``)."""
        c = self._c
        c["frames"] += 1
        if is_remote_frame:
            c["remote_frame"] += 1
            return []
        key = (arbitration_id, bool(is_extended_id))
        comp = self._by_key.get(key)
        m = self._dbc_msgs.get(key)
        if m is not None and bool(is_fd) != bool(m.is_fd):
            c["fd_mismatch"] += 1
            return []
        if comp is None:
            if m is None:
                c["unknown_id"] += 1
                return []
            c["unmapped"] += 1
            if self.bus_map.decode_all:
                self._try_decode(m, data, key)
            return []
        vals = self._try_decode(comp.message, data, key)
        if vals is None:
            return []
        rule = comp.rule
        valid = True
        if comp.checksum is not None and not comp.checksum(arbitration_id, data):
            c["checksum_mismatch"] += 1
            valid = False
        if comp.counter_mod:
            cnt = vals.get(rule.counter)
            if cnt is not None:
                cnt = int(cnt)
                if comp.last_counter is not None and \
                        (cnt - comp.last_counter) % comp.counter_mod != 1:
                    c["counter_jump"] += 1
                    valid = False
                comp.last_counter = cnt
        if rule.valid_signal:
            v = vals.get(rule.valid_signal)
            if v is None or not float(v):
                valid = False
        fields = {}
        for r in rule.rules:
            y = r.value(vals)
            if y is None:
                c["missing_signal"] += 1
                continue
            fields[r.field] = y
        if not fields:
            return []
        c["decoded"] += 1
        return [Sample(t_ns=int(t_ns), source=self.source, kind=rule.kind, fields=fields,
                       valid=valid)]

    def _try_decode(self, m, data: bytes, key=None):
        """The scaled signal values (cantools' ``decode(..., scaling=True)``), or None (counted).
        A frame of the message's length goes through the message's compiled layout
        (``codecs.dbc_compile``; each value by the signal's conversion, cantools' arithmetic)
        when the layout compiles, otherwise and for other lengths through cantools."""
        c = self._c
        n = len(data)
        if n == m.length and key is not None:
            fast = self._fast.get(key, False)
            if fast is False:
                fast = self._fast[key] = _compile(m)
            if fast is not None:
                comp, convs = fast
                return {name: conv.raw_to_scaled(r, False)
                        for name, conv, r in zip(comp.names, convs, comp.raw(bytes(data)))}
        if n != m.length:
            c["dlc_mismatch"] += 1
        try:
            return m.decode(bytes(data), decode_choices=False, scaling=True,
                            allow_truncated=n < m.length, allow_excess=True)
        except Exception:  # noqa: BLE001 - cantools' DecodeError and friends
            c["undecodable"] += 1
            return None


def build_decoder(sigmap: SignalMap, bus: str, dbc_path: str | os.PathLike | None = None,
                  *, source: str | None = None) -> tuple[SignalMapDecoder | None, dict]:
    """The decoder of ``bus`` from a signal map and a DBC (``dbc_path`` overrides the map's).

    Returns ``(decoder or None, info)`` where ``info`` has the DBC path and its sha256, whether
    it was loaded non-strictly, and the decoded channel; ``None`` when the map has no entry for
    this bus. Raises SignalMapError (one line) when the DBC is missing or does not fit.
    """
    bm = sigmap.bus(bus)
    if bm is None:
        return None, {}
    path = Path(dbc_path) if dbc_path is not None else bm.dbc
    if path is None:
        raise SignalMapError(f"signal map {sigmap.name} bus {bm.name}: no DBC given "
                             f"(pass --dbc {bm.dbc_name or 'FILE'})")
    db = load_dbc(path, strict=bm.dbc_strict)
    generic = SignalMapDecoder(bm, db, source=source)  # checks the map against the DBC
    digest = db.sha256  # of the bytes described
    if bm.dbc_sha256 and bm.dbc_sha256 != digest:
        log.warning("DBC %s differs from the one signal map %s was written for (sha256 %s...)",
                    path, sigmap.name, bm.dbc_sha256[:12])
    info = {"dbc": str(path), "dbc_sha256": digest, "dbc_strict": bm.dbc_strict,
            "channel": bm.channel, "signalmap": sigmap.name, "signalmap_sha256": sigmap.sha256,
            "codec": bm.codec or "signalmap"}
    if bm.codec == "vdps":
        from vdps_hil.codecs.can_dbc import DbcError
        from vdps_hil.codecs.can_decode import VdpsCanDecoder

        try:
            return VdpsCanDecoder(path, source=source or f"can.{bm.name}"), info
        except DbcError as e:
            raise SignalMapError(str(e)) from None
    return generic, info
