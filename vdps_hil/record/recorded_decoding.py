"""The signal map and DBC a recording was decoded with, found again from its metadata.

``vdps import`` and ``vdps log`` write, into the ``vdps.recording`` metadata record, the signal
map (``signalmap``: name, path, sha256 of its text) and per bus the DBC that decoded it
(``decoding.<bus>``: ``dbc`` path as given, ``dbc_sha256`` of its bytes). A replay or a diagnosis
of that file should decode ``/raw/can/`` the same way without being told again:
:func:`find_recorded_decoding` looks for each file where it was, next to the recording and beside
the signal map, and takes a candidate only when its content hash is the recorded one, so a file
edited since (or another file of the same name) is never used in its place.

Where a file is looked for (first match by content hash wins):

==============  =================================================================================
signal map      the recorded path (as written; relative paths from the working directory, then
                from the recording's directory); ``<its file name>`` next to the recording; the
                shipped map of the recorded file name in ``configs/signalmaps/``
DBC of a bus    the recorded path (as above); ``<its file name>`` next to the recording; beside the
                signal map found; the map's own ``dbc`` of that bus
==============  =================================================================================

What the person gives wins: ``--signalmap`` (and ``--dbc``) are used as given, nothing is
looked up. A recording without a recorded signal map decodes as before (the ``vdps`` bus with
``dbc/vdps.dbc``). When a recorded file cannot be found, :class:`RecordedDecodingError` says in
one line what is missing (name, sha256 prefix, where it was looked for) and which option gives
it. The decoders take one DBC for all buses; a recording whose buses were decoded with
different DBCs needs ``--signalmap``/``--dbc`` (said so in one line).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from vdps_hil.record import schemas as S

__all__ = ["RecordedDecoding", "RecordedDecodingError", "find_recorded_decoding"]


class RecordedDecodingError(ValueError):
    """A file the recording names cannot be found (one line, with the option that gives it)."""


@dataclass(frozen=True)
class RecordedDecoding:
    """What to decode ``/raw/can/`` with: ``signalmap`` and ``dbc`` (paths or None, for
    ``record.decode.decode_recording``), ``source`` (``"options"``, ``"recording"`` or
    ``"default"``) and ``found`` (role -> path, the files taken from the metadata)."""

    signalmap: str | None
    dbc: str | None
    source: str
    found: dict = field(default_factory=dict)


def _json_field(md: dict, key: str):
    raw = md.get(key)
    if not raw:
        return None
    try:
        return json.loads(raw)
    except (TypeError, ValueError):
        return None


def _candidates(recorded: str, rec_dir: Path, extra: tuple[Path, ...] = ()) -> list[Path]:
    """Where a recorded file may be now (module docstring), duplicates removed, in order."""
    p = Path(recorded)
    out = [p] if p.is_absolute() else [Path.cwd() / p, rec_dir / p]
    out.append(rec_dir / p.name)
    out.extend(extra)
    seen, uniq = set(), []
    for c in (Path(os.path.normpath(c)) for c in out):
        try:
            key = c.resolve()
        except OSError:
            continue
        if key not in seen:
            seen.add(key)
            uniq.append(c)
    return uniq


def _file_sha256(p: Path) -> str | None:
    try:
        return S.content_hash(p).removeprefix("sha256:") if p.is_file() else None
    except OSError:
        return None


def _find_signalmap(info: dict, rec_dir: Path):
    """(SignalMap, path) of the recorded signal map, or RecordedDecodingError."""
    from vdps_hil.adapters.signalmap import SIGNALMAP_DIR, SignalMapError, load_signalmap

    want = str(info.get("sha256", ""))
    recorded = str(info.get("path") or info.get("name") or "")
    name = Path(recorded).name or f"{info.get('name', '')}.toml"
    looked = _candidates(recorded, rec_dir, (SIGNALMAP_DIR / name,)) if recorded else [SIGNALMAP_DIR / name]
    differs = None
    for c in looked:
        if not c.is_file():
            continue
        try:
            sm = load_signalmap(c)
        except SignalMapError:
            continue
        if not want or sm.sha256 == want:
            return sm, c
        differs = c
    raise _not_found(f"signal map {info.get('name', name)!r} (sha256 {want[:12]}...)", differs, recorded,
                     f"next to the recording or in {SIGNALMAP_DIR}", "--signalmap FILE (and --dbc FILE)")


def _not_found(what: str, differs, recorded: str, where: str, option: str) -> "RecordedDecodingError":
    """The one-line error of a file the recording names that was not found (or only with other content)."""
    if differs is not None:
        return RecordedDecodingError(f"the recording was decoded with {what}; {differs} has other content: "
                                     f"give {option}")
    return RecordedDecodingError(f"the recording was decoded with {what}, recorded at {recorded}: not found there, "
                                 f"{where}: give {option}")


def _find_dbc(bus: str, info: dict, rec_dir: Path, sigmap, sigmap_path: Path) -> Path:
    """The DBC that decoded ``bus`` (content hash checked), or RecordedDecodingError."""
    want = str(info.get("dbc_sha256", ""))
    recorded = str(info.get("dbc", ""))
    name = Path(recorded).name
    extra = [sigmap_path.parent / name]
    bm = sigmap.bus(bus)
    if bm is not None and bm.dbc is not None:
        extra.append(Path(bm.dbc))
    differs = None
    for c in _candidates(recorded, rec_dir, tuple(extra)):
        h = _file_sha256(c)
        if h is None:
            continue
        if not want or h == want:
            return c
        differs = c
    raise _not_found(f"DBC {name!r} for bus {bus} (sha256 {want[:12]}...)", differs, recorded,
                     "next to the recording or beside the signal map", "--dbc FILE")


def find_recorded_decoding(reader, path, *, dbc=None, signalmap=None) -> RecordedDecoding:
    """The signal map and DBC to decode the recording ``reader`` (a ``RecordingReader`` of the
    file at ``path``) with (module docstring). ``dbc``/``signalmap``: the person's options,
    which win. Raises :class:`RecordedDecodingError` (one line)."""
    if signalmap is not None or dbc is not None:
        return RecordedDecoding(None if signalmap is None else os.fspath(signalmap),
                                None if dbc is None else os.fspath(dbc), "options")
    md = reader.metadata().get(S.METADATA_NAME, {})
    sm_info = _json_field(md, "signalmap")
    if not isinstance(sm_info, dict):
        return RecordedDecoding(None, None, "default")
    rec_dir = Path(os.fspath(path)).resolve().parent
    sigmap, sm_path = _find_signalmap(sm_info, rec_dir)
    decoding = _json_field(md, "decoding")
    dbcs: dict[str, Path] = {}
    for bus, info in (decoding.items() if isinstance(decoding, dict) else ()):
        if isinstance(info, dict) and info.get("decoded", True) and info.get("dbc") and sigmap.bus(bus) is not None:
            dbcs[bus] = _find_dbc(bus, info, rec_dir, sigmap, sm_path)
    distinct = {p.resolve() for p in dbcs.values()}
    if len(distinct) > 1:
        raise RecordedDecodingError(f"the recording's buses {', '.join(sorted(dbcs))} were decoded with different DBCs; "
                                    "replay one bus at a time with --signalmap FILE --dbc FILE")
    found = {"signalmap": str(sm_path), **{f"dbc.{b}": str(p) for b, p in dbcs.items()}}
    dbc_path = None if not dbcs else str(next(iter(dbcs.values())))
    return RecordedDecoding(str(sm_path), dbc_path, "recording", found)
