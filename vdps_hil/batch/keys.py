"""Resume keys: a batch result is reused only when everything that produced it is unchanged.

Key of one task (SHA-256 over a canonical JSON document)::

    key = sha256( canonical_json({
        "kind":    task kind ("replay", "diagnose", "study.snr", ...),
        "input":   sha256 of the input file's bytes (None for generated inputs such as a study trial),
        "config":  the task's options (JSON-able, key order irrelevant),
        "files":   {role: sha256 of the file's bytes}  (vehicle, model, config, DBC files ...),
        "effects": the effect list, sorted and de-duplicated,
        "tool":    tool_version() = "<package version>+src.<digest of the tool's own files>",
    }) )

The *tool version* is ``vdps_hil.__version__`` plus a digest of every ``*.py`` file of the
package and of the shipped configs (``configs/**/*.toml``) and DBCs (``dbc/*.dbc``): a code
change invalidates old results even when nobody bumped the version (what a developer running a
batch twice expects). Paths are not part of the key: a drive moved or renamed keeps its result
only if it keeps its result file name (``runner``); the key itself depends on content only.

Hashing a fleet's recordings is I/O bound (hundreds of MB per hour of driving). A
:class:`DigestCache` (``<out>/.digests.json``) remembers ``(path, size, mtime_ns, inode) ->
digest``, so a rerun over unchanged files reads none of them; a file rewritten in place with
the same size within the file system's time resolution would be missed (the usual trade-off of
make-like tools; ``--rehash`` ignores the cache).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import threading
from pathlib import Path
from typing import Any, Iterable, Mapping

from vdps_hil import __version__

__all__ = ["file_digest", "canonical_json", "tool_version", "task_key", "DigestCache"]

_PACKAGE_DIR = Path(__file__).resolve().parents[1]
_REPO_DIR = _PACKAGE_DIR.parent
_BLOCK = 1 << 20


def file_digest(path: str | os.PathLike) -> str:
    """``sha256:<hex>`` of a file's bytes, read in 1 MiB blocks (never whole in memory)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(_BLOCK):
            h.update(block)
    return "sha256:" + h.hexdigest()


def _jsonable(o: Any) -> Any:
    if isinstance(o, float):
        return o if math.isfinite(o) else repr(o)  # nan/inf as text: still a stable key
    if isinstance(o, Mapping):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    if hasattr(o, "item") and callable(o.item):  # numpy scalar
        return _jsonable(o.item())
    if o is None or isinstance(o, (str, int, bool)):
        return o
    raise TypeError(f"cannot put a {type(o).__name__} into a resume key")


def canonical_json(doc: Any) -> str:
    """JSON with sorted keys, no spaces, non-finite floats as strings (stable across runs)."""
    return json.dumps(_jsonable(doc), sort_keys=True, separators=(",", ":"), ensure_ascii=True)


_tool_lock = threading.Lock()
_tool_cache: dict[str, str] = {}


def _tool_files() -> list[Path]:
    files = sorted(p for p in _PACKAGE_DIR.rglob("*.py") if "__pycache__" not in p.parts)
    for sub, pattern in (("configs", "*.toml"), ("dbc", "*.dbc")):
        root = _REPO_DIR / sub
        if root.is_dir():
            files += sorted(root.rglob(pattern))
    return files


def tool_version() -> str:
    """``<version>+src.<12 hex>``: the package version and a digest of its source, shipped
    configs and DBCs (module docstring). Computed once per process."""
    with _tool_lock:
        if "v" not in _tool_cache:
            h = hashlib.sha256()
            for p in _tool_files():
                h.update(p.relative_to(_REPO_DIR).as_posix().encode())
                h.update(b"\0")
                h.update(p.read_bytes())
                h.update(b"\0")
            _tool_cache["v"] = f"{__version__}+src.{h.hexdigest()[:12]}"
        return _tool_cache["v"]


def task_key(kind: str, input_digest: str | None, *, config: Mapping[str, Any] | None = None,
             files: Mapping[str, str | os.PathLike | None] | None = None,
             effects: Iterable[str] = (), tool: str | None = None,
             digests: "DigestCache | None" = None) -> str:
    """The resume key of one task (module docstring). ``files`` maps a role to a path (hashed
    by content; None = not used); ``digests`` is an optional cache for those files too."""
    hashed = {}
    for role, path in sorted((files or {}).items()):
        if path is None:
            hashed[role] = None
        else:
            hashed[role] = digests.digest(path) if digests is not None else file_digest(path)
    doc = {"kind": str(kind), "input": input_digest, "config": dict(config or {}),
           "files": hashed, "effects": sorted(set(map(str, effects))),
           "tool": tool if tool is not None else tool_version()}
    return "sha256:" + hashlib.sha256(canonical_json(doc).encode()).hexdigest()


class DigestCache:
    """``path -> sha256`` memo keyed by ``(size, mtime_ns, inode)`` and saved as JSON.

    ``DigestCache(path)`` loads the file if present (a damaged cache is ignored, never an
    error); ``digest(p)`` returns the cached digest when the file's stat matches, otherwise
    reads the file; ``save()`` writes the cache atomically. ``enabled=False`` always reads.
    Thread-safe (digests of many files may be computed in a thread pool).
    """

    def __init__(self, path: str | os.PathLike | None = None, *, enabled: bool = True):
        self.path = None if path is None else Path(path)
        self.enabled = enabled
        self._lock = threading.Lock()
        self._entries: dict[str, dict] = {}
        self.hits = 0
        self.misses = 0
        if self.path is not None and enabled:
            try:
                doc = json.loads(self.path.read_text(encoding="utf-8"))
                if isinstance(doc, dict) and isinstance(doc.get("files"), dict):
                    self._entries = {k: v for k, v in doc["files"].items() if isinstance(v, dict)}
            except (OSError, ValueError):
                self._entries = {}

    @staticmethod
    def _stat_id(st: os.stat_result) -> list[int]:
        return [st.st_size, st.st_mtime_ns, st.st_ino]

    def digest(self, path: str | os.PathLike) -> str:
        p = os.path.abspath(os.fspath(path))
        st = os.stat(p)
        sid = self._stat_id(st)
        if self.enabled:
            with self._lock:
                e = self._entries.get(p)
                if e is not None and e.get("stat") == sid and isinstance(e.get("sha256"), str):
                    self.hits += 1
                    return e["sha256"]
        d = file_digest(p)
        with self._lock:
            self.misses += 1
            self._entries[p] = {"stat": sid, "sha256": d}
        return d

    def save(self) -> None:
        if self.path is None or not self.enabled:
            return
        with self._lock:
            text = json.dumps({"version": 1, "files": self._entries}, sort_keys=True)
        tmp = self.path.with_name(self.path.name + f".tmp{os.getpid()}")
        try:
            tmp.write_text(text, encoding="utf-8")
            os.replace(tmp, self.path)
        except OSError:
            tmp.unlink(missing_ok=True)  # a cache that cannot be written only costs time
