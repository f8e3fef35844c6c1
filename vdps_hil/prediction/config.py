"""The predictor's configuration (``configs/prediction/default.toml``, table ``[predictor]``):
horizon, step, integrator, Jacobian refresh, output decimation, cadence, effect set, model
variant, slip speed floor, stop rule and pose source (:mod:`vdps_hil.prediction.predictor`
says what each does). Loading uses :mod:`tomllib` only; errors are one line
(:class:`PredictionConfigError`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from vdps_hil.model.params import CONFIG_DIR
from vdps_hil.units import NS_PER_S

DEFAULT_CONFIG_PATH = CONFIG_DIR / "prediction" / "default.toml"
INTEGRATORS = ("ros2", "rk2")
POSE_SOURCES = ("suspension", "estimate", "estimate_plane")


class PredictionConfigError(ValueError):
    """A prediction config that cannot be used; the message is one line."""


@dataclass(frozen=True)
class PredictorConfig:
    """Horizon, step, integrator, cadence and model variant of the predictor.

    Defaults (``configs/prediction/default.toml``): horizon 5 s, step 10 ms with ``ros2``
    (linearly implicit wheel spin), Jacobian every step, one output sample per step (100 Hz),
    cadence 10 Hz, effects ``["linear_tire"]``, reduced model (``unsprung_dof = false``), slip
    speed floor 5 m/s, stop at the predicted point of no return, pose from the suspension
    (``pose_source``: "suspension", "estimate" or "estimate_plane", module docstring)."""

    horizon_s: float = 5.0
    step_s: float = 0.01
    integrator: str = "ros2"
    jacobian_every: int = 2
    jacobian_coupling: bool = True
    output_every: int = 1
    cadence_hz: float = 10.0
    effects: tuple[str, ...] = ("linear_tire",)
    effect_params: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    unsprung_dof: bool = False
    slip_speed_floor_mps: float = 5.0
    stop_at_point_of_no_return: bool = True
    pose_source: str = "suspension"

    def __post_init__(self):
        for name in ("horizon_s", "step_s", "cadence_hz", "slip_speed_floor_mps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise PredictionConfigError(f"predictor.{name} must be a positive finite number, got {v!r}")
        for name in ("jacobian_every", "output_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise PredictionConfigError(f"predictor.{name} must be an integer >= 1, got {v!r}")
        if self.integrator not in INTEGRATORS:
            raise PredictionConfigError(f"predictor.integrator must be one of {', '.join(INTEGRATORS)}, "
                                        f"got {self.integrator!r}")
        if self.pose_source not in POSE_SOURCES:
            raise PredictionConfigError(f"predictor.pose_source must be one of {', '.join(POSE_SOURCES)}, "
                                        f"got {self.pose_source!r}")
        if self.step_s > self.horizon_s:
            raise PredictionConfigError("predictor.step_s must not exceed horizon_s")
        if not isinstance(self.effects, tuple):
            object.__setattr__(self, "effects", tuple(self.effects))

    @property
    def n_steps(self) -> int:
        """Steps per prediction: round(horizon / step)."""
        return max(1, int(round(self.horizon_s / self.step_s)))

    @property
    def cadence_ns(self) -> int:
        return int(round(NS_PER_S / self.cadence_hz))


_PRED_KEYS = {f for f in PredictorConfig.__dataclass_fields__}


def _check_table(t: Any, allowed: set[str], where: str) -> dict:
    if not isinstance(t, Mapping):
        raise PredictionConfigError(f"{where}: expected a table")
    unknown = sorted(set(t) - allowed)
    if unknown:
        raise PredictionConfigError(f"{where}: unknown key {unknown[0]!r}")
    return dict(t)


def predictor_config_from_table(t: Mapping, where: str = "[predictor]") -> PredictorConfig:
    """A PredictorConfig from a TOML table (unknown keys and bad values: one-line errors)."""
    d = _check_table(t, _PRED_KEYS, where)
    if "effects" in d:
        e = d["effects"]
        if not isinstance(e, list) or not all(isinstance(n, str) for n in e):
            raise PredictionConfigError(f"{where}.effects: expected a list of effect names")
        d["effects"] = tuple(e)
    if "effect_params" in d:
        ep = d["effect_params"]
        if not isinstance(ep, Mapping) or not all(isinstance(v, Mapping) for v in ep.values()):
            raise PredictionConfigError(f"{where}.effect_params: expected tables of parameters")
    for b in ("unsprung_dof", "stop_at_point_of_no_return", "jacobian_coupling"):
        if b in d and not isinstance(d[b], bool):
            raise PredictionConfigError(f"{where}.{b}: expected true or false")
    for k in ("horizon_s", "step_s", "cadence_hz", "slip_speed_floor_mps"):
        if k in d and isinstance(d[k], int) and not isinstance(d[k], bool):
            d[k] = float(d[k])
    try:
        return PredictorConfig(**d)
    except TypeError as e:  # pragma: no cover - keys are checked above
        raise PredictionConfigError(f"{where}: {e}") from None


def load_prediction_document(path: str | Path | None = None) -> dict:
    """The prediction config TOML (``configs/prediction/default.toml`` by default) as a dict
    (tomllib: data only). Tables: ``[predictor]`` and ``[warning]``."""
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise PredictionConfigError(f"cannot read prediction config {p}: {e.__class__.__name__}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise PredictionConfigError(f"{p}: malformed TOML: {e}") from None
    unknown = sorted(set(doc) - {"schema_version", "predictor", "warning"})
    if unknown:
        raise PredictionConfigError(f"{p}: unknown key {unknown[0]!r}")
    if doc.get("schema_version", 1) != 1:
        raise PredictionConfigError(f"{p}: unsupported schema_version {doc.get('schema_version')!r}")
    return doc


def load_predictor_config(path: str | Path | None = None) -> PredictorConfig:
    """The ``[predictor]`` table of a prediction config file."""
    doc = load_prediction_document(path)
    return predictor_config_from_table(doc.get("predictor", {}), f"{path or DEFAULT_CONFIG_PATH}[predictor]")


__all__ = ["DEFAULT_CONFIG_PATH", "INTEGRATORS", "POSE_SOURCES", "PredictionConfigError", "PredictorConfig",
           "load_prediction_document", "load_predictor_config", "predictor_config_from_table"]
