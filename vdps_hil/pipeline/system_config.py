"""The configuration of the system node (``pipeline.node.VdpsSystem``): ``SystemConfig``, the
system's default estimator settings (``default_pipeline_config``), how a live system predicts
(``LIVE_PREDICTIONS``) and what parameters the predictor takes (``PREDICT_FROM``). The node's
module docstring explains each setting's role."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

from vdps_hil.estimation.pipeline_config import PipelineConfig
from vdps_hil.estimation.suspension import CONDITIONING_SIGMA_FACTOR, SUSPENSION_STAMPS
from vdps_hil.identification.config import IdentConfig
from vdps_hil.identification.feeder import FeederConfig
from vdps_hil.model.params import IdentifiedParams

__all__ = ["LIVE_PREDICTIONS", "PREDICT_FROM", "SystemConfig", "default_pipeline_config"]

LIVE_PREDICTIONS = {"prediction_worker": "process", "prediction_deadline": "drop", "keep_input_log": False}
"""How a live system predicts (the bench, ``vdps log --pipeline``; ``SystemConfig`` fields,
``prediction.offpath``): in a worker process (``tools/bench_offpath.py``: it keeps the
prediction's Python off the sample path's GIL), a job late at its deadline dropped."""


# ---------------------------------------------------------------------------- configuration
def default_pipeline_config(**kw) -> PipelineConfig:
    """The system's pipeline settings: no pipeline Estimates (the system takes its own), 20 Hz
    alpha-beta bandwidths (``pipeline.node`` docstring) and a GNSS speed sigma of 0.05 m/s (Doppler
    velocity, about 1/20 of the code position sigma; Table 1 gives none; the pipeline's default
    0.1 m/s made the velocity NIS 0.26 on simulated drives); ``kw`` overrides PipelineConfig."""
    from vdps_hil.estimation.pipeline_config import Bandwidths

    d = {"emit_estimates": False, "bandwidths": Bandwidths(20.0, 20.0, 20.0), "gnss_speed_sigma_mps": 0.05}
    d.update(kw)
    return PipelineConfig(**d)


PREDICT_FROM = ("identified", "current")
"""The parameters the predictor uses: per parameter the last value the identifier called identified,
else the start value (``identification.trusted``), or the identifier's current estimates."""


@dataclass(frozen=True)
class SystemConfig:
    """Configuration of the node (module docstring). ``ident``/``predictor``/``warning_*`` None:
    the project's config files (``configs/identification``, ``configs/prediction``)."""

    pipeline: PipelineConfig = field(default_factory=lambda: default_pipeline_config())
    estimate_period_s: float = 0.01
    emit_filtered: bool = True
    suspension_rate_hz: float | None = 100.0
    suspension_stamp: str = "mean"
    tire_compliance: bool = True
    susp_rate_bandwidth_hz: float = 10.0
    identify: bool = True
    ident_period_s: float = 0.01
    ident_report_period_s: float = 1.0
    convergence_period_s: float = 0.02  # the warning chain re-reads the identifier's convergence
    ident: IdentConfig | None = None
    feeder: FeederConfig = field(default_factory=FeederConfig)
    start_params: IdentifiedParams | None = None
    predict: bool = True
    predictor: Any = None  # PredictorConfig
    warning_policy: Any = None  # WarningPolicy
    warning_node: Any = None  # WarningNodeConfig
    warning_bus: str = "vdps"
    require_converged: tuple[str, ...] | None = None  # None: the warning policy's, if started from the priors
    start_unsettled: tuple[str, ...] = ()  # problems start_params did not settle (a --params file's meta.status)
    model_effects: Any = None  # EffectSet of a saved workbench model: dynamics join the predictor,
    # IMU measurement effects are removed from the readings (estimation.imu_correction)
    prediction_worker: str = "inline"  # prediction.offpath.WORKERS: "inline", "thread", "process"
    prediction_deadline: str = "wait"  # "wait" (replay) or "drop" (live; prediction.offpath)
    keep_input_log: bool = True  # False (live bench): no replay log held, a long run's memory stays flat
    prediction_drops_t0_ns: tuple[int, ...] = ()  # a live run's dropped predictions, dropped again
    predict_from: str = "identified"  # PREDICT_FROM: the values identified (identification.trusted) or "current"

    def __post_init__(self):
        for name in ("estimate_period_s", "ident_period_s", "ident_report_period_s", "convergence_period_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"SystemConfig.{name} must be a positive finite number, got {v!r}")
        r = self.suspension_rate_hz
        if r is not None and not (math.isfinite(r) and r > 0):
            raise ValueError(f"SystemConfig.suspension_rate_hz must be positive or None, got {r!r}")
        from vdps_hil.prediction.offpath import DEADLINES, WORKERS

        if self.prediction_worker not in WORKERS or self.prediction_deadline not in DEADLINES:
            raise ValueError(f"SystemConfig: prediction_worker must be one of {WORKERS} and prediction_deadline "
                             f"one of {DEADLINES}, got {self.prediction_worker!r}, {self.prediction_deadline!r}")
        if self.predict_from not in PREDICT_FROM:
            raise ValueError(f"SystemConfig.predict_from must be one of {PREDICT_FROM}, got {self.predict_from!r}")
        if self.suspension_stamp not in SUSPENSION_STAMPS:
            raise ValueError(f"SystemConfig.suspension_stamp must be one of {SUSPENSION_STAMPS}, "
                             f"got {self.suspension_stamp!r}")

    @classmethod
    def for_profile(cls, susp_rate_hz: float, susp_sigma_m: float, **kw) -> "SystemConfig":
        """A config whose EKF suspension sigma is that of the conditioned sample:
        k sigma_H / sqrt(n), n = max(1, round(sensor rate / suspension_rate_hz)), k =
        ``CONDITIONING_SIGMA_FACTOR`` when windows are averaged (n > 1) and stamped at their
        end, else 1."""
        rate = kw.get("suspension_rate_hz", cls.__dataclass_fields__["suspension_rate_hz"].default)
        stamp = kw.get("suspension_stamp", cls.__dataclass_fields__["suspension_stamp"].default)
        n = 1 if rate is None else max(1, int(round(susp_rate_hz / rate)))
        k = CONDITIONING_SIGMA_FACTOR if n > 1 and stamp == "end" else 1.0
        pc = kw.pop("pipeline", default_pipeline_config())
        pc = replace(pc, susp_sigma_m=k * susp_sigma_m / math.sqrt(n))
        return cls(pipeline=pc, **kw)
