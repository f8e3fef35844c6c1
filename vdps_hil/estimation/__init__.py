"""State estimation of the paper, sections 3.2-3.5: the multi-rate EKF (eq 7-11) with its
documented corrections, alpha-beta filters (eq 12) and numerical observability, fed from bus
samples by the pipeline node.

Data flow: ``Sample`` -> ``pipeline.EstimatorPipeline`` (settings ``pipeline_config``), which
reads each sample's fields (``imu_input`` for the IMU: mounting, ESC substitution, lever arm,
mean input; ``sensor_samples`` for GNSS and chassis), holds measurements until the IMU has
reached their time (``sequencing``), builds (z, R) (``measurements``, ``wheel_speed``),
initialises and re-acquires from the newest aiding data (``initialisation``), and drives
``ekf.MultiRateEKF`` (configuration ``ekf_config``; process model ``kinematics``, measurement
models ``observations``, named states ``states``, gate ``chi2``, latency history
``ekf_history``) and the alpha-beta filters ``alpha_beta``; out come ``estimates.Estimate`` /
``Innovation`` / ``FilteredSignals`` and, per window, ``observability`` reports whose null
spaces ``observability_explain`` puts in words.
``sensorsets``: named sensor sets (``configs/sensorsets``) and the one a recording provides;
``suspension``: the suspension conditioning of the Figure-2 node. The analytic test trajectories
with their truth are ``vdps_hil.experiments.synthetic``.
"""

from vdps_hil.estimation.alpha_beta import AlphaBetaFilter, TimedAlphaBeta, critically_damped_gains, kalata_gains
from vdps_hil.estimation.ekf import MultiRateEKF, UpdateResult
from vdps_hil.estimation.ekf_config import EkfConfig, PaperFaithful, SensorSet
from vdps_hil.estimation.observability import ObservabilityReport, ObservabilityWindow, observability_rank
from vdps_hil.estimation.estimates import Estimate, FilteredSignals, Innovation
from vdps_hil.estimation.observations import ObsKind
from vdps_hil.estimation.pipeline import EstimatorPipeline
from vdps_hil.estimation.pipeline_config import Bandwidths, Latencies, PipelineConfig
from vdps_hil.estimation.states import STATE_NAMES, States, StateLayout

__all__ = ["AlphaBetaFilter", "Bandwidths", "EkfConfig", "Estimate", "EstimatorPipeline", "FilteredSignals",
           "Innovation", "Latencies", "MultiRateEKF", "ObsKind", "ObservabilityReport", "ObservabilityWindow",
           "PaperFaithful", "PipelineConfig", "STATE_NAMES", "SensorSet", "StateLayout", "States", "TimedAlphaBeta",
           "UpdateResult", "critically_damped_gains", "kalata_gains", "observability_rank"]
