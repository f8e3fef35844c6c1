"""Model files (``--save-model`` / ``--model``): a model vehicle's identified parameters and the
effects the workbench added, as data (TOML or JSON by suffix; nothing in it can execute code).

Layout (TOML; the JSON document has the same keys)::

    schema = "vdps-model"
    schema_version = 1
    vehicle = "sedan-model"            # the model vehicle file it refines (name)
    vehicle_sha256 = "..."             # of that file's text (a mismatch is reported, not fatal)
    source = "vdps diagnose drive.mcap --add aero_drag"   # optional, free text

    [params]                           # the ten identified parameters (section 5.2), SI
    mass_kg = 1601.2
    ...
    [sigmas]                           # optional: 1-sigma of the parameters above
    [[effects]]                        # zero or more
    name = "aero_drag"
    params = { cda_m2 = 0.69, air_density_kgpm3 = 1.225 }
    sigmas = { cda_m2 = 0.004 }        # optional

``load_model(path, vehicle)`` returns the vehicle with the identified parameters and the
:class:`~vdps_hil.model.effects.EffectSet` (``vdps replay --model``, ``vdps bench --model``:
``Predictor(vehicle, config, effects)``). Effect names are looked up in the effect registry
(plus user effects the caller passes): a model file can name an effect but never bring code.
Errors are one line (:class:`ModelFileError`).
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

from vdps_hil.model.effects import REGISTRY, EffectSet
from vdps_hil.model.effects.base import Effect, EffectConfigError
from vdps_hil.model.params import PARAM_NAMES, Vehicle, VehicleFileError, check_range

__all__ = ["ModelFileError", "ModelFile", "save_model", "load_model", "read_model", "SCHEMA", "SCHEMA_VERSION"]

SCHEMA = "vdps-model"
SCHEMA_VERSION = 1
_TOP = {"schema", "schema_version", "vehicle", "vehicle_sha256", "source", "params", "sigmas", "effects"}


class ModelFileError(ValueError):
    """A model file that cannot be used (one-line message)."""


@dataclass
class ModelFile:
    """The parsed document."""

    vehicle: str
    vehicle_sha256: str
    params: dict[str, float]
    effects: list[tuple[str, dict[str, float]]]
    sigmas: dict[str, float] = field(default_factory=dict)
    effect_sigmas: dict[str, dict[str, float]] = field(default_factory=dict)
    source: str = ""

    def to_doc(self) -> dict:
        doc = {"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "vehicle": self.vehicle,
               "vehicle_sha256": self.vehicle_sha256, "params": dict(self.params)}
        if self.source:
            doc["source"] = self.source
        if self.sigmas:
            doc["sigmas"] = dict(self.sigmas)
        doc["effects"] = []
        for name, p in self.effects:
            e = {"name": name, "params": dict(p)}
            if self.effect_sigmas.get(name):
                e["sigmas"] = dict(self.effect_sigmas[name])
            doc["effects"].append(e)
        return doc


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if not math.isfinite(float(v)):
            raise ModelFileError("cannot write a non-finite number to a model file")
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string is a JSON string for these characters
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise ModelFileError(f"cannot write {type(v).__name__} to a model file")


def _to_toml(doc: dict) -> str:
    lines = []
    for k in ("schema", "schema_version", "vehicle", "vehicle_sha256", "source"):
        if k in doc:
            v = doc[k]
            lines.append(f"{k} = {v if isinstance(v, int) and not isinstance(v, bool) else _toml_value(v)}")
    for table in ("params", "sigmas"):
        if doc.get(table):
            lines.append("")
            lines.append(f"[{table}]")
            for k, v in doc[table].items():
                lines.append(f"{k} = {_toml_value(v)}")
    for e in doc.get("effects", []):
        lines.append("")
        lines.append("[[effects]]")
        lines.append(f"name = {_toml_value(e['name'])}")
        lines.append(f"params = {_toml_value(e['params'])}")
        if e.get("sigmas"):
            lines.append(f"sigmas = {_toml_value(e['sigmas'])}")
    return "\n".join(lines) + "\n"


def save_model(path: str | Path, vehicle: Vehicle, effects: EffectSet | Sequence[Effect],
               sigmas: Mapping[str, float] | None = None,
               effect_sigmas: Mapping[str, Mapping[str, float]] | None = None, source: str = "") -> Path:
    """Write the model (``.toml`` or ``.json``; other suffixes are refused)."""
    p = Path(path)
    eff = [e for e in (effects if isinstance(effects, EffectSet) else EffectSet(effects)) if e.name != "linear_tire"]
    mf = ModelFile(vehicle=vehicle.name, vehicle_sha256=vehicle.source_sha256,
                   params={k: float(getattr(vehicle.params, k)) for k in PARAM_NAMES},
                   effects=[(e.name, e.params) for e in eff],
                   sigmas={k: float(v) for k, v in (sigmas or {}).items() if v is not None and math.isfinite(v)},
                   effect_sigmas={k: {q: float(s) for q, s in v.items() if s is not None and math.isfinite(s)}
                                  for k, v in (effect_sigmas or {}).items()},
                   source=source)
    doc = mf.to_doc()
    if p.suffix.lower() == ".json":
        text = json.dumps(doc, indent=2) + "\n"
    elif p.suffix.lower() == ".toml":
        text = _to_toml(doc)
    else:
        raise ModelFileError(f"{p}: a model file ends in .toml or .json")
    try:
        p.write_text(text, encoding="utf-8")
    except OSError as e:
        raise ModelFileError(f"cannot write {p}: {e.strerror or e}") from None
    return p


def _num(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ModelFileError(f"{where}: expected a finite number, got {v!r}")
    return float(v)


def read_model(path: str | Path) -> ModelFile:
    """Parse and check a model file (no vehicle or registry needed)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ModelFileError(f"cannot read model file {p}: {e.__class__.__name__}") from None
    try:
        if p.suffix.lower() == ".json":
            doc = json.loads(text)
        else:
            doc = tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as e:
        raise ModelFileError(f"{p}: malformed {'JSON' if p.suffix.lower() == '.json' else 'TOML'}: "
                             f"{str(e).splitlines()[0]}") from None
    if not isinstance(doc, dict):
        raise ModelFileError(f"{p}: expected a table at the top")
    unknown = sorted(set(doc) - _TOP)
    if unknown:
        raise ModelFileError(f"{p}: unknown key {unknown[0]!r}")
    if doc.get("schema") != SCHEMA:
        raise ModelFileError(f"{p}: not a model file (schema must be {SCHEMA!r})")
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise ModelFileError(f"{p}: schema_version {doc.get('schema_version')!r} is not {SCHEMA_VERSION}")
    params = doc.get("params")
    if not isinstance(params, dict):
        raise ModelFileError(f"{p}: missing table [params]")
    bad = sorted(set(params) - set(PARAM_NAMES))
    if bad:
        raise ModelFileError(f"{p}[params]: unknown parameter {bad[0]!r}")
    vals = {k: _num(v, f"{p}[params].{k}") for k, v in params.items()}
    for k, v in vals.items():  # the vehicle file's physical ranges (model.params.RANGES)
        try:
            check_range(k, v, f"{p}[params]")
        except VehicleFileError as e:
            raise ModelFileError(str(e)) from None
    sig = doc.get("sigmas", {})
    if not isinstance(sig, dict):
        raise ModelFileError(f"{p}[sigmas]: expected a table")
    sigmas = {k: _num(v, f"{p}[sigmas].{k}") for k, v in sig.items()}
    effs = doc.get("effects", [])
    if not isinstance(effs, list):
        raise ModelFileError(f"{p}: effects must be a list of tables")
    out_e, out_s = [], {}
    for i, e in enumerate(effs):
        where = f"{p} effects[{i}]"
        if not isinstance(e, dict) or not isinstance(e.get("name"), str):
            raise ModelFileError(f"{where}: needs a name")
        extra = sorted(set(e) - {"name", "params", "sigmas"})
        if extra:
            raise ModelFileError(f"{where}: unknown key {extra[0]!r}")
        ep = e.get("params", {})
        if not isinstance(ep, dict):
            raise ModelFileError(f"{where}.params: expected a table")
        out_e.append((e["name"], {k: _num(v, f"{where}.params.{k}") for k, v in ep.items()}))
        es = e.get("sigmas", {})
        if not isinstance(es, dict):
            raise ModelFileError(f"{where}.sigmas: expected a table")
        out_s[e["name"]] = {k: _num(v, f"{where}.sigmas.{k}") for k, v in es.items()}
    return ModelFile(vehicle=str(doc.get("vehicle", "")), vehicle_sha256=str(doc.get("vehicle_sha256", "")),
                     params=vals, effects=out_e, sigmas=sigmas, effect_sigmas=out_s, source=str(doc.get("source", "")))


def load_model(path: str | Path, vehicle: Vehicle, user_effects: Sequence[type[Effect]] = ()
               ) -> tuple[Vehicle, EffectSet, ModelFile]:
    """(vehicle with the file's parameters, the file's effects, the parsed file). ``vehicle`` is
    the model vehicle file the parameters refine (kind ``model``)."""
    if vehicle.kind != "model":
        raise ModelFileError("a model file refines a model vehicle file (kind = \"model\"), not a truth file")
    mf = read_model(path)
    reg = dict(REGISTRY)
    for cls in user_effects:
        reg[cls.name] = cls
    effects = []
    for name, params in mf.effects:
        if name not in reg:
            raise ModelFileError(f"{path}: unknown effect {name!r} (load its code with --effect-file)")
        try:
            effects.append(reg[name](**params))
        except EffectConfigError as e:
            raise ModelFileError(f"{path}: {e}") from None
    try:
        eset = EffectSet(effects)
    except EffectConfigError as e:
        raise ModelFileError(f"{path}: {e}") from None
    return vehicle.with_params(**mf.params), eset, mf
