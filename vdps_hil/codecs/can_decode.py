"""The counting decoder of the vdps chassis bus: a frame -> ``[Sample]`` (catalogue fields in
SI plus the frame's counter) or ``[]`` with the reject counted, never raising on frame content.

Per message the decoding is planned once (``_DecodePlan``: the compiled layout of
``codecs.dbc_compile``, or cantools when it does not compile; signal indexes; scale and offset;
which ranges need a check); per frame the checks run in this order: DLC, CRC (every protected
frame; over the data ID first for sensor frames), rolling counter (``codecs.can_e2e``), raw range;
then ``x = raw * scale + offset`` (``codecs.can_encode`` module docstring; the TTR sentinel raw
65535 decodes to +inf).

In bulk (``decode_many``, a replay's frames): the frames of each message are checked and scaled
as one numpy block (``codecs.can_bulk``; the counter rule by ``SequenceState.check_many``), the
sample groups merged afterwards in frame order: the same samples and counters as frame by frame.

Sample groups: the messages sharing a DBC ``VdpsSampleGroup`` (the front and rear torque frames)
decode into one sample. An accepted frame of the group is held; the group's last message (the
highest ID, sent last at an instant) emits one sample with the fields of all members at its own
time and counter when every other member was accepted at most half its cycle time before it
(the same instant); otherwise nothing is emitted and its ``group_incomplete`` counts (the frames
themselves were accepted; a lost member is already in ``lost_frames``). Samples above the codec
therefore look as in layout 1 (four torques in one ``wheel_torque`` sample).

Rejects, each counted per message (``REJECT_REASONS``): ``dlc_mismatch`` (payload length != DBC
DLC), ``undecodable`` (cantools could not decode), ``crc_mismatch``, ``counter_repeat``,
``counter_jump`` (``codecs.can_e2e``), ``out_of_range`` (raw outside the DBC range). Frames
with an unknown ID are counted under ``bus/unknown_id`` (11-bit) or ``bus/unknown_id_extended``
(29-bit, none are defined); the bus defines classic data frames only, so a remote frame counts
as ``bus/remote_frame`` and a CAN FD frame (whatever its ID) as ``bus/fd_frame``; arguments that
are not an ID/bytes, and error frames, count as ``bus/malformed``.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Mapping

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.codecs.can_bulk import bulk_layout, crc_column, payload_block, raw_columns, scaled_column
from vdps_hil.codecs.can_dbc import TTR_NONE_RAW, MessageSpec, VdpsDbc, is_ttr, load_dbc
from vdps_hil.codecs.can_e2e import WARNING_MAX_DELTA_COUNTER, SequenceState, e2e_crc, e2e_register

if TYPE_CHECKING:
    import can

DEFAULT_SOURCE = "can.vdps"

REJECT_REASONS = ("dlc_mismatch", "undecodable", "out_of_range", "crc_mismatch",
                  "counter_repeat", "counter_jump")
"""Per-message reject counters (each rejected frame increments exactly one)."""

BUS_REJECTS = ("unknown_id", "unknown_id_extended", "malformed", "remote_frame", "fd_frame")
"""Rejects of frames that are no message of the bus (module docstring)."""


BULK_MIN_FRAMES = 16
"""Fewest frames of one message in a ``decode_many`` call decoded as a block (fewer: per frame)."""


class _DecodePlan:
    """A message's decoding precomputed (``codecs.dbc_compile``; cantools when the layout is not
    compilable): signal indexes of the CRC, counter and ``warning_status``, and per value signal
    (field, index, scale, offset, is the TTR sentinel field); ``checks``: (index, raw_min,
    raw_max) of the value signals whose DBC range is narrower than their bits can hold (the
    compiled raw values lie inside the bits: a full-width range needs no check). The scaled
    value is ``float(raw * scale + offset)`` with the conversion's own scale and offset, which
    is what cantools' ``raw_to_scaled`` computes (``codecs.can_encode._from_raw``; tested on
    every raw value). ``modulus``: of the rolling counter."""

    __slots__ = ("spec", "compiled", "names", "crc", "counter", "counter_name", "status", "values",
                 "checks", "modulus", "data_id", "crc_reg", "closes", "max_age_ns", "bulk", "field_names")

    def __init__(self, spec: MessageSpec):
        from vdps_hil.codecs.dbc_compile import NotCompilable, compile_message

        self.spec = spec

        try:
            self.compiled = compile_message(spec.message)
        except NotCompilable:
            self.compiled = None
        self.names = tuple(s.name for s in spec.message.signals)
        idx = {n: i for i, n in enumerate(self.names)}
        self.crc = idx[spec.crc.name] if spec.crc is not None else -1
        self.counter = idx[spec.counter.name]
        self.counter_name = spec.counter.name
        self.status = idx.get("warning_status", -1) if spec.crc is not None else -1
        self.modulus = 1 << spec.counter.length_bits
        vals, checks = [], []
        for sig in spec.values:
            conv = sig.signal.conversion
            conv = getattr(conv, "_conversion", conv)  # named values: the numeric conversion
            vals.append((sig.name, idx[sig.name], conv.scale, conv.offset, is_ttr(sig)))
            half = 1 << (sig.length_bits - 1)
            full = (-half, half - 1) if sig.is_signed else (0, 2 * half - 1)
            if self.compiled is None or (sig.raw_min, sig.raw_max) != full:
                checks.append((idx[sig.name], sig.raw_min, sig.raw_max))
        self.values = tuple(vals)
        self.field_names = tuple(v[0] for v in vals) + (self.counter_name,)  # a sample's fields, in order
        self.checks = tuple(checks)
        self.bulk = bulk_layout(self.compiled, spec.dlc)  # codecs.can_bulk, None: frame by frame
        self.data_id = spec.data_id
        self.crc_reg = e2e_register(spec.data_id)  # the CRC register after the data ID
        self.closes = False  # the last message of its sample group (VdpsCanDecoder sets it)
        self.max_age_ns = int((spec.cycle_time_ms or 10) * 500_000)  # half the cycle


class VdpsCanDecoder:
    """Decode chassis frames into :class:`Sample` objects, counting every reject.

    ``decode(t_ns, arbitration_id, data, is_extended_id=False)`` returns ``[Sample]`` for an
    accepted frame and ``[]`` for a rejected one; it never raises on frame content. Samples
    carry catalogue fields (SI) plus ``seq_counter`` (sensor frames) or ``warning_counter``;
    kinds come from the DBC attribute ``VdpsKind`` (``wheel_speed``, ``wheel_torque``,
    ``steer``, ``suspension``, ``warning``). A warning with ``warning_status != 0`` is returned
    with ``valid=False``. Rules and counters: module docstring.
    """

    def __init__(self, dbc_path: str | Path | None = None, *, source: str = DEFAULT_SOURCE,
                 max_delta_counter: int = WARNING_MAX_DELTA_COUNTER):
        self._dbc = load_dbc(dbc_path)
        self._source = source
        self._max_delta = int(max_delta_counter)
        self._by_id = dict(self._dbc.by_id)
        self._bus = dict.fromkeys(BUS_REJECTS, 0)
        self._counts = {name: dict.fromkeys(("accepted", "lost_frames") + REJECT_REASONS, 0)
                        for name in self._dbc.messages}
        self._seq = {name: SequenceState() for name in self._dbc.messages}
        self._plan = {aid: _DecodePlan(spec) for aid, spec in self._by_id.items()}
        self._held: dict[str, dict[str, tuple[int, dict, bool]]] = {}  # group -> name -> frame
        self._members: dict[str, tuple[str, ...]] = {}
        for aid in sorted(self._plan):
            g = self._plan[aid].spec.group
            if g:
                self._members[g] = self._members.get(g, ()) + (self._plan[aid].spec.name,)
                self._held[g] = {}
        for g, names in self._members.items():
            last = max(self._dbc.messages[n].frame_id for n in names)
            self._plan[last].closes = True
            self._counts[names[-1]]["group_incomplete"] = 0

    @property
    def dbc(self) -> VdpsDbc:
        return self._dbc

    @property
    def counters(self) -> Mapping[str, Mapping[str, int]]:
        """Read-only snapshot: ``{"bus": {unknown_id, unknown_id_extended, malformed,
        remote_frame, fd_frame},
        <message name>: {accepted, lost_frames, dlc_mismatch, undecodable, out_of_range,
        crc_mismatch, counter_repeat, counter_jump} (+ group_incomplete on the last message of a
        sample group)}``."""
        snap = {"bus": MappingProxyType(dict(self._bus))}
        snap.update({k: MappingProxyType(dict(v)) for k, v in self._counts.items()})
        return MappingProxyType(snap)

    @property
    def crc_errors(self) -> int:
        """Frames rejected for a wrong CRC, over all messages (``crc_mismatch`` summed)."""
        return sum(c["crc_mismatch"] for c in self._counts.values())

    @property
    def total_rejected(self) -> int:
        """All rejected frames (unknown IDs, malformed and per-message rejects)."""
        return sum(self._bus.values()) + sum(c[r] for c in self._counts.values()
                                             for r in REJECT_REASONS)

    def reset_sequence(self) -> None:
        """Forget the counter history (e.g. after a bus restart); counts are kept."""
        self._seq = {name: SequenceState() for name in self._dbc.messages}

    def decode_message(self, msg: can.Message, t_ns: int | None = None) -> list[Sample]:
        """Decode a python-can message (``t_ns`` defaults to its timestamp)."""
        if msg.is_error_frame:
            self._bus["malformed"] += 1
            return []
        t = t_ns if t_ns is not None else int(round(msg.timestamp * 1e9))
        return self.decode(t, msg.arbitration_id, bytes(msg.data[:msg.dlc]), msg.is_extended_id,
                           is_fd=msg.is_fd, is_remote_frame=msg.is_remote_frame)

    def decode(self, t_ns: int, arbitration_id: int, data: bytes, is_extended_id: bool = False,
               *, is_fd: bool = False, is_remote_frame: bool = False) -> list[Sample]:
        """A frame -> ``[Sample]`` or ``[]`` (counted); remote and CAN FD frames are rejects."""
        frame = self.frame_of(t_ns, arbitration_id, data, is_extended_id, is_fd=is_fd,
                              is_remote_frame=is_remote_frame)
        return [] if frame is None else self.decode_frame(*frame)

    def frame_of(self, t_ns, arbitration_id, data, is_extended_id=False, *, is_fd: bool = False,
                 is_remote_frame: bool = False) -> tuple[int, int, bytes, bool] | None:
        """The typed fields ``(t_ns, id, payload, is_extended_id)`` that :meth:`decode` passes to
        :meth:`decode_frame`, or None with the reject counted (remote, FD, malformed)."""
        if is_remote_frame or is_fd:
            self._bus["remote_frame" if is_remote_frame else "fd_frame"] += 1
            return None
        try:
            return int(t_ns), int(arbitration_id), bytes(data), bool(is_extended_id)
        except (TypeError, ValueError, OverflowError):
            self._bus["malformed"] += 1
            return None

    def decode_frame(self, t_ns: int, aid: int, payload: bytes, is_extended_id: bool) -> list[Sample]:
        """``decode`` of a frame whose fields already have their types (int, int, bytes, bool),
        e.g. parsed from a recording: no conversions."""
        plan = None if is_extended_id else self._plan.get(aid)
        if plan is None:
            self._bus["unknown_id_extended" if is_extended_id else "unknown_id"] += 1
            return []
        spec = plan.spec
        if len(payload) != spec.dlc:
            self._counts[spec.name]["dlc_mismatch"] += 1
            return []
        got = self._accept(plan, t_ns, payload)
        if got is None:
            return []
        if spec.group:
            return self._grouped(plan, t_ns, *got)
        return [Sample(t_ns, self._source, spec.kind, got[0], 0, got[1])]  # positional: the hot path

    def _accept(self, plan: _DecodePlan, t_ns: int, payload: bytes) -> tuple[dict, bool] | None:
        """A frame of the message's length checked (CRC, counter, range) and scaled: (fields,
        valid), or None with the reject counted (module docstring)."""
        spec = plan.spec
        counts = self._counts[spec.name]
        if plan.compiled is not None:
            raw = plan.compiled.raw(payload)
        else:
            try:
                d = spec.message.decode(payload, decode_choices=False, scaling=False)
                raw = [d[n] for n in plan.names]
            except Exception:  # cantools' DecodeError and friends: count, never raise
                counts["undecodable"] += 1
                return None
        if plan.crc >= 0 and e2e_crc(payload, plan.data_id, plan.crc_reg) != raw[plan.crc]:
            counts["crc_mismatch"] += 1
            return None
        c = raw[plan.counter]
        reason = self._seq[spec.name].check(c, t_ns, plan.modulus, not spec.is_sensor, self._max_delta,
                                            counts)
        if reason is not None:
            counts[reason] += 1
            return None
        for i, lo, hi in plan.checks:
            if not lo <= raw[i] <= hi:
                counts["out_of_range"] += 1
                return None
        fields: dict[str, float] = {}
        for name, i, scale, offset, ttr in plan.values:
            r = raw[i]
            fields[name] = math.inf if ttr and r == TTR_NONE_RAW else float(r * scale + offset)
        fields[plan.counter_name] = float(c)
        counts["accepted"] += 1
        return fields, plan.status < 0 or raw[plan.status] == 0

    def decode_many(self, frames: list[tuple[int, int, bytes, bool]]) -> list[Sample | None]:
        """:meth:`decode_frame` of each typed frame, in order: its sample or None (a frame gives
        at most one), the same samples, counter states and counts, decoded as one block per
        message (``codecs.can_bulk``) where a message has ``BULK_MIN_FRAMES`` or more frames here.
        The sample groups are merged in frame order. (No list per frame: a replay decodes
        thousands at once, and containers that live that long cost the garbage collector.)"""
        out: list[Sample | None] = [None] * len(frames)
        plans = self._plan
        held = []  # accepted frames of sample groups: (frame index, plan, fields, valid)
        for aid, ks in self._by_message(frames).items():
            plan = plans[aid]
            if plan.bulk is not None and len(ks) >= BULK_MIN_FRAMES:
                ks, fields, valid = self._accept_block(plan, ks, frames)
            else:
                got = [(k, self._accept(plan, frames[k][0], frames[k][2])) for k in ks]
                got = [(k, g) for k, g in got if g is not None]
                ks, fields, valid = [k for k, _ in got], [g[0] for _, g in got], [g[1] for _, g in got]
            if plan.spec.group:
                held += zip(ks, (plan,) * len(ks), fields, valid)
                continue
            src, kind = self._source, plan.spec.kind
            for k, f, v in zip(ks, fields, valid):
                out[k] = Sample(frames[k][0], src, kind, f, 0, v)
        held.sort(key=lambda h: h[0])
        for k, plan, f, v in held:
            got = self._grouped(plan, frames[k][0], f, v)
            out[k] = got[0] if got else None
        return out

    def _by_message(self, frames) -> dict[int, list[int]]:
        """The indexes of the frames of each message that have its DLC, in order; the others
        counted (unknown IDs, extended IDs, ``dlc_mismatch``) as :meth:`decode_frame` counts them."""
        try:
            aid = np.array([f[1] for f in frames], dtype=np.int64)
        except OverflowError:  # an ID beyond 64 bits: no message of ours, but count it in Python
            aid = np.array([f[1] if -(1 << 63) <= f[1] < (1 << 63) else -1 for f in frames], dtype=np.int64)
        ext = np.array([f[3] for f in frames], dtype=bool)
        length = np.array([len(f[2]) for f in frames], dtype=np.int64)
        ours = np.zeros(len(frames), dtype=bool)
        by_id = {}
        for a, plan in self._plan.items():
            mine = (aid == a) & ~ext
            ours |= mine
            fits = length == plan.spec.dlc
            self._counts[plan.spec.name]["dlc_mismatch"] += int(np.count_nonzero(mine & ~fits))
            ks = np.flatnonzero(mine & fits)
            if len(ks):
                by_id[a] = ks.tolist()
        self._bus["unknown_id_extended"] += int(np.count_nonzero(ext))
        self._bus["unknown_id"] += int(np.count_nonzero(~ours & ~ext))
        return by_id

    def _accept_block(self, plan: _DecodePlan, ks: list[int], frames) -> tuple[list[int], list[dict], list[bool]]:
        """:meth:`_accept` of the frames ``ks`` (all of the plan's message and length, in order)
        as one block: (indexes, fields, valid) of the accepted frames, the rejects counted."""
        spec = plan.spec
        counts = self._counts[spec.name]
        block = payload_block([frames[k][2] for k in ks], spec.dlc)
        raw = raw_columns(plan.bulk, len(plan.names), block)
        sel = np.arange(len(ks))
        if plan.crc >= 0:
            sel = np.flatnonzero(crc_column(block, plan.crc_reg) == raw[plan.crc])
            counts["crc_mismatch"] += len(ks) - len(sel)
        reasons = self._seq[spec.name].check_many(raw[plan.counter][sel].tolist(),
                                                  [frames[ks[j]][0] for j in sel.tolist()], plan.modulus,
                                                  not spec.is_sensor, self._max_delta, counts)
        if any(r is not None for r in reasons):
            for r in reasons:
                if r is not None:
                    counts[r] += 1
            sel = sel[np.array([r is None for r in reasons], dtype=bool)]
        if plan.checks:
            bad = np.zeros(len(sel), dtype=bool)
            for i, lo, hi in plan.checks:
                col = raw[i][sel]
                bad |= (col < lo) | (col > hi)
            counts["out_of_range"] += int(bad.sum())
            sel = sel[~bad]
        counts["accepted"] += len(sel)
        cols = [scaled_column(raw[i][sel], scale, offset, TTR_NONE_RAW if ttr else None)
                for _, i, scale, offset, ttr in plan.values]
        cols.append(raw[plan.counter][sel].astype(np.float64).tolist())
        names = plan.field_names
        fields = [dict(zip(names, row)) for row in zip(*cols)]
        valid = (raw[plan.status][sel] == 0).tolist() if plan.status >= 0 else [True] * len(sel)
        return [ks[j] for j in sel.tolist()], fields, valid

    def _grouped(self, plan: _DecodePlan, t_ns: int, fields: dict, valid: bool) -> list[Sample]:
        """An accepted frame of a sample group: held, or the group's sample (module docstring)."""
        spec = plan.spec
        held = self._held[spec.group]
        if not plan.closes:
            held[spec.name] = (t_ns, fields, valid)
            return []
        merged: dict[str, float] = {}
        for name in self._members[spec.group][:-1]:
            got = held.pop(name, None)
            if got is None or not 0 <= t_ns - got[0] <= plan.max_age_ns:
                self._counts[spec.name]["group_incomplete"] += 1
                held.clear()
                return []
            merged.update(got[1])
            valid = valid and got[2]
        merged.update(fields)
        return [Sample(t_ns, self._source, spec.kind, merged, 0, valid)]
