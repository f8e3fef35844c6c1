"""Identified parameters kept between drives (``--save-params FILE`` / ``--params FILE``).

File format (JSON, UTF-8, written atomically: temporary file + rename)::

    {
      "schema": "vdps-hil/identified-params",
      "schema_version": 1,
      "vehicle": "sedan-model",              # the model file the values belong to
      "vehicle_sha256": "...",               # its hash when saved (informative)
      "params": {"mass_kg": 1601.2, ...},    # all ten IdentifiedParams fields, SI
      "sigmas": {"mass_kg": 3.1, ...},       # optional, same keys, >= 0
      "meta": {...}                          # optional free-form JSON (counters, time, source)
    }

``vdps replay --save-params`` saves the identifier's estimates except those "at bound" (never a
value, ``identification.status``), which keep the run's start value (``Identifier.handover_params``;
named in ``meta.at_bound_kept_start``).
``meta.status`` (written by ``vdps replay --save-params``): problem -> the identifier's status
when saved ("converged", or why not: ``identification.status``); ``meta.param_status``: parameter ->
its status ("identified", or why not). :func:`unsettled_problems` and :func:`unidentified_params`
read them back: a warning chain started from such a file stays invalid until the live identifier
has identified those of the unsettled problems the warning's validity rule names (the cornering
problem; ``pipeline.node``), and the commands say which values were not identified when saved.

Loading checks (each failure is one line, :class:`ParamsFileError`): size <= 1 MB, valid JSON,
the schema name, a supported schema version, the vehicle name of the model file in use, all
ten parameters present as finite numbers and no unknown ones, and the **sanity bounds**: each
value within ``bounds_factor`` x the model file's prior (default [0.3, 3], the identifier's own
physical bounds, ``configs/identification/default.toml``). JSON cannot execute code.
``reset_params`` deletes the file (the next drive starts from the model file's priors).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

from vdps_hil.identification.config import PROBLEM_NAMES
from vdps_hil.model.params import PARAM_NAMES, IdentifiedParams, Vehicle

SCHEMA = "vdps-hil/identified-params"
SCHEMA_VERSION = 1
MAX_FILE_BYTES = 1_000_000
DEFAULT_BOUNDS_FACTOR = (0.3, 3.0)


class ParamsFileError(ValueError):
    """A parameter file that cannot be used; the message is one line for the user."""


@dataclass(frozen=True)
class PersistedParams:
    params: IdentifiedParams
    sigmas: dict[str, float] = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    vehicle: str = ""
    vehicle_sha256: str = ""


def _finite(v) -> bool:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:  # a JSON integer beyond the float range
        return False


def check_params(params: IdentifiedParams, prior: IdentifiedParams,
                 bounds_factor: tuple[float, float] = DEFAULT_BOUNDS_FACTOR, where: str = "params") -> None:
    """Raise :class:`ParamsFileError` unless every value is finite and within
    ``bounds_factor`` x prior."""
    lo, hi = bounds_factor
    for n in PARAM_NAMES:
        v, p = getattr(params, n), getattr(prior, n)
        if not _finite(v):
            raise ParamsFileError(f"{where}: {n} is not a finite number ({v!r})")
        if not (lo * p <= v <= hi * p):
            raise ParamsFileError(f"{where}: {n} = {v:g} is outside the sanity bounds "
                                  f"[{lo * p:g}, {hi * p:g}] ({lo:g}-{hi:g} x the model file's prior {p:g})")


def save_params(path: str | Path, params: IdentifiedParams, vehicle: Vehicle,
                sigmas: Mapping[str, float] | None = None, meta: Mapping | None = None,
                bounds_factor: tuple[float, float] = DEFAULT_BOUNDS_FACTOR) -> None:
    """Write ``params`` (checked against the sanity bounds first) for ``vehicle`` (a model file).
    Atomic: a crash never leaves a half-written file."""
    if vehicle.kind != "model":
        raise ParamsFileError(f"parameters belong to a model vehicle file, got a {vehicle.kind!r} file")
    check_params(params, vehicle.params, bounds_factor, where="refusing to save")
    sig = {}
    for k, v in (sigmas or {}).items():
        if k not in PARAM_NAMES:
            raise ParamsFileError(f"refusing to save: unknown sigma name {k!r}")
        sig[k] = float(v) if _finite(v) and v >= 0 else None
    doc = {"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "vehicle": vehicle.name,
           "vehicle_sha256": vehicle.source_sha256, "params": params.as_dict(), "sigmas": sig,
           "meta": dict(meta or {})}
    try:
        text = json.dumps(doc, indent=2, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ParamsFileError(f"refusing to save: meta is not plain JSON ({e})") from None
    p = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent or ".")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text + "\n")
            os.replace(tmp, p)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
    except OSError as e:
        raise ParamsFileError(f"cannot write parameter file {p}: {e.strerror or e}") from None


def parse_params(text: str, vehicle: Vehicle, origin: str = "<string>",
                 bounds_factor: tuple[float, float] = DEFAULT_BOUNDS_FACTOR) -> PersistedParams:
    """Parse and check the JSON text of a parameter file for ``vehicle`` (a model file)."""
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as e:
        why = str(e).splitlines()[0] if str(e) else "too deep"
        raise ParamsFileError(f"{origin}: not valid JSON ({why})") from None
    if not isinstance(doc, dict):
        raise ParamsFileError(f"{origin}: expected a JSON object")
    if doc.get("schema") != SCHEMA:
        raise ParamsFileError(f"{origin}: not a vdps-hil parameter file (schema {doc.get('schema')!r})")
    ver = doc.get("schema_version")
    if not isinstance(ver, int) or isinstance(ver, bool) or ver != SCHEMA_VERSION:
        raise ParamsFileError(f"{origin}: unsupported schema_version {ver!r} (this version reads {SCHEMA_VERSION})")
    name = doc.get("vehicle")
    if name != vehicle.name:
        raise ParamsFileError(f"{origin}: saved for vehicle {name!r}, this run uses {vehicle.name!r}")
    vals = doc.get("params")
    if not isinstance(vals, dict):
        raise ParamsFileError(f"{origin}: 'params' must be an object")
    unknown = sorted(set(vals) - set(PARAM_NAMES))
    if unknown:
        raise ParamsFileError(f"{origin}: unknown parameter {unknown[0]!r}")
    for n in PARAM_NAMES:
        if n not in vals:
            raise ParamsFileError(f"{origin}: missing parameter {n!r}")
        if not _finite(vals[n]):
            raise ParamsFileError(f"{origin}: {n} must be a finite number, got {vals[n]!r}")
    params = IdentifiedParams(**{n: float(vals[n]) for n in PARAM_NAMES})
    check_params(params, vehicle.params, bounds_factor, where=origin)
    sig_doc = doc.get("sigmas", {})
    if not isinstance(sig_doc, dict):
        raise ParamsFileError(f"{origin}: 'sigmas' must be an object")
    sigmas = {}
    for k, v in sig_doc.items():
        if k not in PARAM_NAMES:
            raise ParamsFileError(f"{origin}: unknown sigma name {k!r}")
        if v is None:
            continue
        if not _finite(v) or v < 0:
            raise ParamsFileError(f"{origin}: sigma of {k} must be a non-negative number, got {v!r}")
        sigmas[k] = float(v)
    meta = doc.get("meta", {})
    if not isinstance(meta, dict):
        raise ParamsFileError(f"{origin}: 'meta' must be an object")
    sha = doc.get("vehicle_sha256", "")
    return PersistedParams(params=params, sigmas=sigmas, meta=meta, vehicle=name,
                           vehicle_sha256=sha if isinstance(sha, str) else "")


def load_params(path: str | Path, vehicle: Vehicle,
                bounds_factor: tuple[float, float] = DEFAULT_BOUNDS_FACTOR) -> PersistedParams:
    """Read a parameter file saved by :func:`save_params` for ``vehicle``; one-line errors."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ParamsFileError(f"{p}: {size} bytes is too large for a parameter file")
        text = p.read_bytes().decode("utf-8")
    except OSError as e:
        raise ParamsFileError(f"cannot read parameter file {p}: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise ParamsFileError(f"{p}: not UTF-8 text") from None
    return parse_params(text, vehicle, str(p), bounds_factor)


def reset_params(path: str | Path) -> bool:
    """Delete the parameter file so the next drive starts from the priors. Returns whether a
    file was removed."""
    p = Path(path)
    try:
        p.unlink()
        return True
    except FileNotFoundError:
        return False
    except OSError as e:
        raise ParamsFileError(f"cannot remove parameter file {p}: {e.strerror or e}") from None


__all__ = ["SCHEMA", "SCHEMA_VERSION", "ParamsFileError", "PersistedParams", "check_params",
           "load_params", "not_settled", "parse_params", "reset_params", "save_params",
           "unidentified_params", "unsettled_problems"]


def unidentified_params(persisted: PersistedParams) -> dict[str, str] | None:
    """Parameter -> status of the parameters that were not "identified" when the file was saved
    (``meta.param_status``, written since 2026-12-07: "at bound", "model mismatch", ...); None
    when the file does not say (older files: only the problems' statuses)."""
    st = persisted.meta.get("param_status") if isinstance(persisted.meta, dict) else None
    if not isinstance(st, dict):
        return None
    return {n: str(st.get(n, "unknown")) for n in PARAM_NAMES if st.get(n) != "identified"}


def not_settled(persisted: PersistedParams) -> dict:
    """What the file had not settled when saved, as the commands' JSON says it:
    {"params_unsettled": :func:`unsettled_problems`, "params_not_identified":
    :func:`unidentified_params`}, or {} when it settled every problem."""
    un = unsettled_problems(persisted)
    return {"params_unsettled": un, "params_not_identified": unidentified_params(persisted)} if un else {}


def unsettled_problems(persisted: PersistedParams) -> dict[str, str]:
    """Problem -> status of the problems that were not "converged" when the file was saved
    (``meta.status``); every problem ("unknown") when the file does not say."""
    st = persisted.meta.get("status") if isinstance(persisted.meta, dict) else None
    if not isinstance(st, dict):
        return {name: "unknown" for name in PROBLEM_NAMES}
    return {name: str(st.get(name, "unknown")) for name in PROBLEM_NAMES if st.get(name) != "converged"}

