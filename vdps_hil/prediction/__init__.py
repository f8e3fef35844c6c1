"""Prediction (paper section 6-7.3): the 6-DOF predictor on the shared physics core, the
prediction metrics used everywhere, and the rollover warning on CAN.

``predictor``: ``Predictor(model_vehicle, config).predict(PredictorInitialState, inputs=None)``
(held inputs, or input-driven) -> ``PredictionResult``; ``config`` its configuration
(``configs/prediction/default.toml``), ``initial_state`` what it starts from and is driven by,
``integration`` its integration loops (ROS2 W-method on the stiff wheel spin), ``result`` what it
returns.
``metrics``: errors in the road frame relative to the pose at t0 and the paper-style inaccuracy.
``warning``: rollover measures of a prediction, ``WarningPolicy``, the pure ``WarningNode``
(VDPS_Warning at 50 Hz and on level change) and ``WarningChain`` (lead time and false alarms
against the truth: ``vdps_hil.experiments.scoring``).
"""

from vdps_hil.prediction.config import (PredictionConfigError, PredictorConfig, load_prediction_document,
                                        load_predictor_config)
from vdps_hil.prediction.initial_state import InputTrajectory, PredictorInitialState
from vdps_hil.prediction.metrics import (PAPER_INACCURACY_PCT, PoseTrajectory, compare_trajectories,
                                         format_metrics, prediction_metrics)
from vdps_hil.prediction.predictor import Cadence, Predictor
from vdps_hil.prediction.result import PredictionResult
from vdps_hil.prediction.warning import (RolloverAssessment, WarningChain, WarningLevel, WarningNode,
                                         WarningNodeConfig, WarningPolicy, WarningStatus, load_warning_config,
                                         replay_assessments)

__all__ = [
    "Cadence", "InputTrajectory", "PAPER_INACCURACY_PCT", "PoseTrajectory", "PredictionConfigError",
    "PredictionResult", "Predictor", "PredictorConfig", "PredictorInitialState", "RolloverAssessment",
    "WarningChain", "WarningLevel", "WarningNode", "WarningNodeConfig", "WarningPolicy",
    "WarningStatus", "compare_trajectories", "format_metrics",
    "load_prediction_document", "load_predictor_config", "load_warning_config", "prediction_metrics",
    "replay_assessments",
]
