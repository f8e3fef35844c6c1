"""State estimation of the paper, sections 3.2-3.5: the multi-rate EKF (eq 7-11) with its
documented corrections, alpha-beta filters (eq 12), numerical observability, and the pipeline
node that feeds them from bus samples.

Data flow: ``Sample`` -> ``pipeline.EstimatorPipeline`` -> ``ekf.MultiRateEKF`` (process model
``kinematics``, measurement models ``observations``, named states ``states``) and
``alpha_beta.TimedAlphaBeta`` -> ``Estimate`` / ``Innovation`` / ``FilteredSignals``.
``sensorsets``: named sensor sets (``configs/sensorsets``) and the one a recording provides. The
analytic test trajectories with their truth are ``vdps_hil.experiments.synthetic``.
"""

from vdps_hil.estimation.alpha_beta import AlphaBetaFilter, TimedAlphaBeta, critically_damped_gains, kalata_gains
from vdps_hil.estimation.ekf import EkfConfig, MultiRateEKF, PaperFaithful, SensorSet, UpdateResult
from vdps_hil.estimation.observability import ObservabilityReport, ObservabilityWindow, observability_rank
from vdps_hil.estimation.observations import ObsKind
from vdps_hil.estimation.pipeline import (Bandwidths, Estimate, EstimatorPipeline, FilteredSignals, Innovation,
                                          Latencies, PipelineConfig)
from vdps_hil.estimation.states import STATE_NAMES, States, StateLayout

__all__ = ["AlphaBetaFilter", "Bandwidths", "EkfConfig", "Estimate", "EstimatorPipeline", "FilteredSignals",
           "Innovation", "Latencies", "MultiRateEKF", "ObsKind", "ObservabilityReport", "ObservabilityWindow",
           "PaperFaithful", "PipelineConfig", "STATE_NAMES", "SensorSet", "StateLayout", "States", "TimedAlphaBeta",
           "UpdateResult", "critically_damped_gains", "kalata_gains", "observability_rank"]
