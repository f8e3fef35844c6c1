"""The output types of the Figure 2 node (``pipeline.node.VdpsSystem``) that are its own --
``CanFrame``, ``IdentReport``, ``PredictionReport`` (the pipeline's ``Innovation``, ``Estimate``
and ``FilteredSignals`` come from ``estimation.pipeline``) -- and the canonical JSON of any
output: ``output_to_json`` and ``outputs_digest`` (equal digests: bit-identical outputs)."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from typing import Iterable, Mapping

from vdps_hil.estimation.estimates import FilteredSignals

__all__ = ["CanFrame", "IdentReport", "PredictionReport", "finite_or_none", "output_to_json", "outputs_digest"]


@dataclass(frozen=True)
class CanFrame:
    """A classic CAN frame the system sends (VDPS_Warning), time-stamped at ``t_ns``."""

    t_ns: int
    bus: str
    arbitration_id: int
    data: bytes

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "bus": self.bus, "arbitration_id": self.arbitration_id,
                "data_hex": self.data.hex()}


@dataclass(frozen=True)
class IdentReport:
    """Identifier state at ``t_ns``: parameter values and sigmas (field names of
    ``IdentifiedParams``, SI), minimum eigenvalue of A^T Q^T Q A per problem, converged flags,
    updates per problem, and per parameter "identified" or why not (``param_status``)."""

    t_ns: int
    params: Mapping[str, float]
    sigmas: Mapping[str, float]
    identifiability: Mapping[str, float]
    converged: Mapping[str, bool]
    updates: Mapping[str, int]
    param_status: Mapping[str, str] = None  # parameter -> "identified" or why not (identification.status)

    def to_json(self) -> dict:
        return {"t_ns": self.t_ns, "params": dict(self.params), "sigmas": dict(self.sigmas),
                "identifiability": dict(self.identifiability), "converged": dict(self.converged),
                "updates": dict(self.updates), "param_status": dict(self.param_status or {})}


@dataclass(frozen=True)
class PredictionReport:
    """A new prediction started at ``t0_ns`` and its rollover assessment (times after t0 [s])."""

    t0_ns: int
    time_to_point_of_no_return_s: float | None
    time_to_tip_up_s: float | None
    peak_ltr: float
    peak_roll_rad: float
    horizon_s: float
    stop_reason: str

    def to_json(self) -> dict:
        return dict(self.__dict__)


def output_to_json(o) -> dict:
    """A JSON-ready document of any system output, with its type under ``"type"``."""
    if isinstance(o, FilteredSignals):
        d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in o.__dict__.items()}
    else:
        d = o.to_json()
    d["type"] = type(o).__name__
    return d


def outputs_digest(outputs: Iterable) -> str:
    """SHA-256 over the canonical JSON of the outputs (NaN written as null): equal digests mean
    bit-identical outputs (floats are printed with their shortest exact repr)."""
    h = hashlib.sha256()
    for o in outputs:
        h.update(json.dumps(finite_or_none(output_to_json(o)), sort_keys=True, separators=(",", ":")).encode())
        h.update(b"\n")
    return h.hexdigest()


def finite_or_none(o):
    """``o`` with every non-finite float replaced by None, recursively (dict keys as str, tuples
    as lists): the canonical JSON of the outputs."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): finite_or_none(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [finite_or_none(v) for v in o]
    return o
