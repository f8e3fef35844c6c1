"""What the decoders need from a DBC, parsed once by cantools and cached as JSON.

``import cantools`` costs 0.2-0.27 s of CPU per process (cantools imports python-can, which
imports its MF4 reader, asammdf and pandas): 15-25 % of replaying a 20-30 s drive, paid again
by the decoding child of ``vdps replay --jobs 2``. The decoders only need numbers from the DBC,
so :func:`load_description` returns a :class:`DbcDescription` -- messages, IDs, lengths,
signal layouts, scale/offset/range, conversions, the DBC attributes -- read from a JSON file
keyed by the DBC's bytes when one exists, and parsed by cantools (then written) otherwise.

Cache file::

    <root>/dbc/<sha256 of the DBC bytes>.<strict|lax>.v<FORMAT_VERSION>.<parser tag>.json
    <root> = $VDPS_CACHE_DIR  or  ${XDG_CACHE_HOME:-~/.cache}/vdps-hil

The parser tag (12 hex digits) hashes the installed cantools' version and its DBC parser file,
so an upgraded cantools misses the old entries. The file repeats its key (format, DBC sha256,
strict, parser), carries ``content_sha256`` -- the SHA-256 of its own attributes and messages
in canonical JSON (sorted keys, no spaces), so a changed number of the right type is caught --
and is checked field by field on load (JSON only: nothing in it can execute); an unreadable,
corrupt, tampered, foreign or stale file -- or an unwritable directory -- is ignored: the DBC is
parsed by cantools again (counted in :data:`STATS`, logged at debug level), never an error.

Numbers no CAN decoder can use are refused in every DBC, parsed or cached (:class:`DbcValueError`,
one line naming the message and signal): a message longer than 64 bytes (the largest CAN FD
frame), a signal scale that is zero (every raw value would mean the same number; the encoders
divide by it) or not finite, a non-finite offset.

The description's classes carry the attribute names of cantools' ``Message``/``Signal`` for the
same meanings (``frame_id``, ``length``, ``signals``, ``start``, ``byte_order``, ``conversion``
...), so ``codecs.dbc_compile`` compiles either. Scaled values are cantools'
``raw_to_scaled(raw, decode_choices=False)`` with the same operands::

    identity (scale 1, offset 0, no choices):   x = raw
    linear:                                     x = raw * scale + offset

(``scale``/``offset`` keep the types cantools parsed: int for ``LinearIntegerConversion``; JSON
keeps int and float apart and writes floats with ``repr``, which round-trips exactly). Value
tables (choices) are not cached: the decoders never decode choices. What needs the parsed
database -- ``Message.decode`` of a layout that does not compile (multiplexed, float,
overlapping signals) or of a frame of another length, ``Message.encode`` -- parses the very
bytes the description was made from with cantools, imported then, once per description.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import logging
import math
import os
import tempfile
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

__all__ = ["FORMAT_VERSION", "ENV_CACHE_DIR", "STATS", "DbcDescription", "DbcValueError",
           "MessageDescription", "SignalDescription", "Conversion", "cache_dir", "cache_path", "load_description"]

log = logging.getLogger(__name__)

FORMAT_VERSION = 2
"""Bumped whenever the JSON layout or the meaning of a field changes (old files then miss)."""

ENV_CACHE_DIR = "VDPS_CACHE_DIR"
"""Environment variable naming the cache root (overrides XDG_CACHE_HOME / ~/.cache)."""

DBC_ENCODING = "cp1252"
"""cantools' default encoding for DBC files (``load_file`` reads them so, errors replaced)."""

STATS: dict[str, int] = dict.fromkeys(("hit", "miss", "rejected", "stored", "store_failed"), 0)
"""Process-wide counts: cache hits, misses (cantools parsed), files ignored as corrupt/foreign/
stale, files written, writes that failed."""


class _BadCache(ValueError):
    """A cache file that cannot be used (the reason is logged at debug level)."""


class DbcValueError(ValueError):
    """A DBC whose numbers no decoder can use (module docstring); the message is one line."""


MAX_FRAME_BYTES = 64
"""The longest CAN frame (CAN FD); a DBC message may not be longer."""


# ---------------------------------------------------------------------------------------------
# The description
# ---------------------------------------------------------------------------------------------
class Conversion:
    """cantools' numeric conversion of one signal (module docstring): ``raw_to_scaled``."""

    __slots__ = ("kind", "scale", "offset", "is_float", "has_choices")

    def __init__(self, kind: str, scale: int | float, offset: int | float, is_float: bool,
                 has_choices: bool):
        self.kind, self.scale, self.offset = kind, scale, offset
        self.is_float, self.has_choices = is_float, has_choices

    def raw_to_scaled(self, raw_value, decode_choices: bool = True):
        if decode_choices and self.has_choices:
            raise ValueError("value tables are not cached: decode choices with cantools "
                             "(DbcDescription.cantools())")
        if self.kind == "identity":
            return raw_value
        return raw_value * self.scale + self.offset


class SignalDescription:
    """One signal (attribute names as cantools' ``Signal``)."""

    __slots__ = ("name", "start", "length", "byte_order", "is_signed", "is_float",
                 "is_multiplexer", "multiplexer_ids", "scale", "offset", "minimum", "maximum",
                 "unit", "conversion")

    def __init__(self, d: Mapping[str, Any]):
        for k in self.__slots__[:-1]:
            setattr(self, k, d[k])
        kind, scale, offset, is_float, has_choices = d["conversion"]
        self.conversion = Conversion(kind, scale, offset, is_float, has_choices)


class MessageDescription:
    """One message (attribute names as cantools' ``Message``; ``attributes``: its DBC ``BA_``
    values by name). ``decode``/``encode`` are cantools' own, on the parsed database."""

    __slots__ = ("name", "frame_id", "is_extended_frame", "length", "is_fd", "is_container",
                 "cycle_time", "multiplexed", "attributes", "signals", "index", "_owner")

    def __init__(self, d: Mapping[str, Any], index: int, owner: "DbcDescription"):
        for k in ("name", "frame_id", "is_extended_frame", "length", "is_fd", "is_container",
                  "cycle_time", "multiplexed"):
            setattr(self, k, d[k])
        self.attributes = MappingProxyType(dict(d["attributes"]))
        self.signals = tuple(SignalDescription(s) for s in d["signals"])
        self.index = index
        self._owner = owner

    def is_multiplexed(self) -> bool:
        return self.multiplexed

    def cantools_message(self):
        """The cantools ``Message`` this describes (parses the DBC on first use)."""
        return self._owner.cantools().messages[self.index]

    def decode(self, data: bytes, **kw):
        return self.cantools_message().decode(data, **kw)

    def encode(self, data, **kw) -> bytes:
        return self.cantools_message().encode(data, **kw)


class DbcDescription:
    """A DBC as the decoders see it: ``messages`` (in cantools' order), ``attributes`` (the
    database's ``BA_`` values), ``sha256`` of the bytes, ``strict``, ``from_cache``."""

    def __init__(self, path: Path, data: bytes, strict: bool, doc: Mapping[str, Any],
                 from_cache: bool, db=None):
        self.path = path
        self.strict = strict
        self.sha256 = doc["dbc_sha256"]
        self.from_cache = from_cache
        self.attributes = MappingProxyType(dict(doc["attributes"]))
        self.messages = tuple(MessageDescription(m, i, self) for i, m in enumerate(doc["messages"]))
        self._data = data
        self._db = db

    def cantools(self):
        """The cantools database of the same bytes (imports and parses on first use)."""
        if self._db is None:
            self._db = _parse(self._data, self.strict)
        return self._db


# ---------------------------------------------------------------------------------------------
# cantools -> JSON document
# ---------------------------------------------------------------------------------------------
def _parse(data: bytes, strict: bool):
    """cantools' ``load_file`` of these bytes: cp1252 with errors replaced, universal newlines
    (without its optional pickle cache, ``CANTOOLS_CACHE_DIR``). cantools' warnings
    ("Overwriting message ..." for names a real DBC repeats: expected) are silenced."""
    import cantools

    text = io.TextIOWrapper(io.BytesIO(data), encoding=DBC_ENCODING, errors="replace").read()
    quiet = logging.getLogger("cantools")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        return cantools.database.load_string(text, database_format="dbc", strict=strict)
    finally:
        quiet.setLevel(level)


def _scalar_attrs(attrs) -> dict[str, Any]:
    out = {}
    for name, a in (attrs or {}).items():
        v = getattr(a, "value", None)
        if isinstance(v, (str, int, float)) and not isinstance(v, bool):
            out[str(name)] = v
    return out


def _conversion_doc(conv) -> list:
    num = getattr(conv, "_conversion", conv)  # named values: the numeric conversion
    kind = "identity" if type(num).__name__ == "IdentityConversion" else "linear"
    return [kind, num.scale, num.offset, bool(num.is_float), conv.choices is not None]


def _document(db, sha256: str, strict: bool) -> dict[str, Any]:
    msgs = []
    for m in db.messages:
        sigs = [{"name": s.name, "start": s.start, "length": s.length, "byte_order": s.byte_order,
                 "is_signed": bool(s.is_signed), "is_float": bool(s.is_float),
                 "is_multiplexer": bool(s.is_multiplexer),
                 "multiplexer_ids": list(s.multiplexer_ids) if s.multiplexer_ids else None,
                 "scale": s.scale, "offset": s.offset, "minimum": s.minimum,
                 "maximum": s.maximum, "unit": s.unit, "conversion": _conversion_doc(s.conversion)}
                for s in m.signals]
        msgs.append({"name": m.name, "frame_id": m.frame_id,
                     "is_extended_frame": bool(m.is_extended_frame), "length": m.length,
                     "is_fd": bool(m.is_fd), "is_container": bool(m.is_container),
                     "cycle_time": m.cycle_time, "multiplexed": bool(m.is_multiplexed()),
                     "attributes": _scalar_attrs(m.dbc.attributes if m.dbc else None),
                     "signals": sigs})
    attrs = _scalar_attrs(db.dbc.attributes if db.dbc else None)
    return {"format": FORMAT_VERSION, "dbc_sha256": sha256, "strict": strict,
            "parser": _parser_tag(), "content_sha256": _content_sha256(attrs, msgs),
            "attributes": attrs, "messages": msgs}


def _content_sha256(attributes, messages) -> str:
    """SHA-256 of the description's content in canonical JSON (sorted keys, no spaces)."""
    text = json.dumps([attributes, messages], sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _check_numbers(doc) -> None:
    """:class:`DbcValueError` for a frame longer than :data:`MAX_FRAME_BYTES` or a zero or
    non-finite scale, or a non-finite offset (module docstring)."""
    for m in doc["messages"]:
        if m["length"] > MAX_FRAME_BYTES:
            raise DbcValueError(f"message {m['name']}: length {m['length']} bytes, a CAN frame "
                                f"carries at most {MAX_FRAME_BYTES}")
        for s in m["signals"]:
            scale, offset = s["conversion"][1], s["conversion"][2]
            if scale == 0 or not math.isfinite(scale) or not math.isfinite(offset):
                raise DbcValueError(f"signal {m['name']}.{s['name']}: scale {scale!r} and offset "
                                    f"{offset!r} must be finite, the scale non-zero")


# ---------------------------------------------------------------------------------------------
# JSON document -> checked (a file is data from outside: every field's type is checked)
# ---------------------------------------------------------------------------------------------
_INT, _BOOL, _STR, _NUM = (int,), (bool,), (str,), (int, float)
_OPT_NUM, _OPT_STR, _OPT_INT = (int, float, type(None)), (str, type(None)), (int, type(None))

_SIGNAL_TYPES = {"name": _STR, "start": _INT, "length": _INT, "byte_order": _STR,
                 "is_signed": _BOOL, "is_float": _BOOL, "is_multiplexer": _BOOL,
                 "multiplexer_ids": (list, type(None)), "scale": _NUM, "offset": _NUM,
                 "minimum": _OPT_NUM, "maximum": _OPT_NUM, "unit": _OPT_STR,
                 "conversion": (list,)}
_MESSAGE_TYPES = {"name": _STR, "frame_id": _INT, "is_extended_frame": _BOOL, "length": _INT,
                  "is_fd": _BOOL, "is_container": _BOOL, "cycle_time": _OPT_INT,
                  "multiplexed": _BOOL, "attributes": (dict,), "signals": (list,)}


def _check_fields(d, types: Mapping[str, tuple], where: str) -> None:
    if not isinstance(d, dict) or set(d) != set(types):
        raise _BadCache(f"{where}: not the expected fields")
    for k, allowed in types.items():
        v = d[k]
        if type(v) not in allowed:  # exact types: a bool is not taken for an int
            raise _BadCache(f"{where}.{k}: {type(v).__name__}")


def _check_attrs(attrs, where: str) -> None:
    for k, v in attrs.items():
        if type(v) not in (str, int, float):
            raise _BadCache(f"{where} attribute {k}: {type(v).__name__}")


def _check_document(doc, sha256: str, strict: bool) -> None:
    if not isinstance(doc, dict):
        raise _BadCache("not an object")
    key = (doc.get("format"), doc.get("dbc_sha256"), doc.get("strict"), doc.get("parser"))
    if key != (FORMAT_VERSION, sha256, strict, _parser_tag()):
        raise _BadCache("made for another DBC, format or parser")
    if not isinstance(doc.get("attributes"), dict) or not isinstance(doc.get("messages"), list):
        raise _BadCache("no attributes or messages")
    if doc.get("content_sha256") != _content_sha256(doc["attributes"], doc["messages"]):
        raise _BadCache("content does not match its content_sha256")
    _check_attrs(doc["attributes"], "database")
    for i, m in enumerate(doc["messages"]):
        _check_fields(m, _MESSAGE_TYPES, f"message {i}")
        if m["length"] < 0 or m["frame_id"] < 0:
            raise _BadCache(f"message {i}: negative length or ID")
        _check_attrs(m["attributes"], f"message {i}")
        for j, s in enumerate(m["signals"]):
            _check_fields(s, _SIGNAL_TYPES, f"message {i} signal {j}")
            if s["byte_order"] not in ("little_endian", "big_endian") or s["length"] <= 0:
                raise _BadCache(f"message {i} signal {j}: layout")
            if s["multiplexer_ids"] is not None and any(type(x) is not int for x in s["multiplexer_ids"]):
                raise _BadCache(f"message {i} signal {j}: multiplexer ids")
            c = s["conversion"]
            if (len(c) != 5 or c[0] not in ("identity", "linear") or type(c[1]) not in _NUM
                    or type(c[2]) not in _NUM or type(c[3]) is not bool or type(c[4]) is not bool):
                raise _BadCache(f"message {i} signal {j}: conversion")


# ---------------------------------------------------------------------------------------------
# Where, and loading
# ---------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _parser_tag() -> str:
    """12 hex digits naming the installed cantools (its distribution version, size and mtime of
    its DBC parser) without importing it."""
    import importlib.metadata
    import importlib.util

    spec = importlib.util.find_spec("cantools")
    if spec is None or not spec.origin:
        return "none"
    pkg = Path(spec.origin).parent
    try:
        parts = [importlib.metadata.version("cantools")]
    except importlib.metadata.PackageNotFoundError:
        parts = ["unknown version"]
    try:
        st = (pkg / "database" / "can" / "formats" / "dbc.py").stat()
        parts.append(f"{st.st_size}:{st.st_mtime_ns}")
    except OSError:
        parts.append("no parser file")
    return hashlib.sha256("\n".join(sorted(parts)).encode()).hexdigest()[:12]


def cache_dir() -> Path:
    """``$VDPS_CACHE_DIR/dbc``, else ``${XDG_CACHE_HOME:-~/.cache}/vdps-hil/dbc``."""
    root = os.environ.get(ENV_CACHE_DIR)
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME")
        root = Path(xdg) / "vdps-hil" if xdg else Path.home() / ".cache" / "vdps-hil"
    return Path(root) / "dbc"


def cache_path(sha256: str, strict: bool) -> Path:
    """The cache file of a DBC with these bytes (module docstring)."""
    mode = "strict" if strict else "lax"
    return cache_dir() / f"{sha256}.{mode}.v{FORMAT_VERSION}.{_parser_tag()}.json"


def _read_cache(path: Path, sha256: str, strict: bool) -> dict | None:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError, RuntimeError) as e:  # RuntimeError: no home directory
        STATS["rejected"] += 1
        log.debug("DBC cache %s unreadable (%s): parsing the DBC", path, e)
        return None
    try:
        doc = json.loads(text)
        _check_document(doc, sha256, strict)
        _check_numbers(doc)
    except (ValueError, RecursionError) as e:  # JSONDecodeError and _BadCache are ValueErrors
        STATS["rejected"] += 1
        log.debug("DBC cache %s ignored (%s): parsing the DBC", path, e)
        return None
    return doc


def _write_cache(path: Path, doc: dict) -> None:
    """Atomic (a temporary file in the same directory, then renamed); failures only logged."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(doc, f, separators=(",", ":"))
        os.replace(tmp, path)
        tmp = None
        STATS["stored"] += 1
    except (OSError, RuntimeError, ValueError) as e:  # ValueError: a value JSON cannot write
        STATS["store_failed"] += 1
        log.debug("DBC cache %s not written (%s)", path, e)
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def load_description(path: str | os.PathLike, *, strict: bool = True) -> DbcDescription:
    """The :class:`DbcDescription` of the DBC file ``path`` (cached; module docstring).

    Raises ``OSError`` if the file cannot be read, whatever cantools raises if it cannot
    parse it, and :class:`DbcValueError` for numbers no decoder can use (the callers turn all
    into one-line errors); a cache problem is never raised.
    """
    p = Path(path)
    data = p.read_bytes()
    sha256 = hashlib.sha256(data).hexdigest()
    strict = bool(strict)
    try:
        where = cache_path(sha256, strict)
    except RuntimeError as e:  # Path.home() without a home directory
        where = None
        log.debug("no DBC cache directory (%s)", e)
    doc = _read_cache(where, sha256, strict) if where is not None else None
    if doc is not None:
        STATS["hit"] += 1
        return DbcDescription(p, data, strict, doc, True)
    STATS["miss"] += 1
    db = _parse(data, strict)
    doc = _document(db, sha256, strict)
    _check_numbers(doc)
    if where is not None:
        _write_cache(where, doc)
    # the description always comes from the JSON form, hit or miss: one behaviour
    return DbcDescription(p, data, strict, json.loads(json.dumps(doc)), False, db)
