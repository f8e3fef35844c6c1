"""The ranking's thresholds (:class:`RankingConfig`) and its row groups (``GROUP_NAMES``).

Row groups: every whitened row of the design belongs to one group -- one of the 14 equations of
eq 13 (``residuals.EQUATIONS``) or one of the three kinds of GNSS innovation (attitude,
velocity, position; ``innovations.INNOVATION_CHANNELS`` 0-2, 3-4, 5-7). The held-out sums of
squares are kept per group, so every explained fraction can be read per equation too.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..candidate_base import BASE_PARAMS
from ..residuals import EQUATIONS

__all__ = ["RankingConfig", "GROUP_NAMES", "INNOVATION_GROUPS", "INNOVATION_GROUP_OF_CHANNEL"]

INNOVATION_GROUPS = ("innov_att", "innov_vel", "innov_pos")
GROUP_NAMES: tuple[str, ...] = EQUATIONS + INNOVATION_GROUPS
"""Row groups: the 14 equations then the GNSS innovations (attitude, velocity, position)."""
INNOVATION_GROUP_OF_CHANNEL = {0: 14, 1: 14, 2: 14, 3: 15, 4: 15, 5: 16, 6: 16, 7: 16}
"""Innovation channel (``INNOVATION_CHANNELS`` index) -> its row group (index into ``GROUP_NAMES``)."""


@dataclass(frozen=True)
class RankingConfig:
    """Thresholds of the ranking (package docstring of :mod:`~vdps_hil.workbench.ranking`).

    The evidence thresholds were set from the hidden-effect study (seeds 100-103, every effect
    and every nothing-hidden maneuver): the smallest explained fraction of a true hit on its
    evidence path was 0.29 (tire saturation, balance equations; every other effect >= 0.47
    overall or >= 0.95 of the innovations), the largest of a false recommendation 0.16 (IMU
    lever arm on the weaving straight, overall and balance) and 0.56 of the innovations (IMU
    bias on accel-coast). ``min_explained_overall`` = ``min_explained_dynamics`` = 0.2 and
    ``min_explained_innovations`` = 0.8 sit between the two. A sensor effect judged on the force
    balance instead of its innovations needs ``min_explained_sensor_balance`` = 0.3 overall: on
    the weaving straight with nothing hidden the lever arm reached 0.15-0.20 (seeds 102, 1000,
    1004), on the lane change with 0.5 m hidden it explains 0.55-0.73.

    Those innovation figures were taken while the design whitened the innovations' nuisance
    twice (fixed 2026-12-03): the initial-state columns could not fit the innovations, so a bias
    explained the misfit (0.96 of the held-out innovations on a 60 s sine sweep with no bias).
    A sensor effect is now also fitted on its innovations alone (``sensor_fit``) and passes on
    them when their held-out SSE gains more than its parameters cost (BIC < -``bic_margin``, no
    new threshold); ``min_explained_innovations`` still applies to the whole-design fit."""

    micro_block_s: float = 0.5
    nuisance_knot_s: float = 2.0
    velocity_sigma_floor_mps: float = 0.02
    velocity_fast_sigma_mps: float = 0.003
    nuisance_cap_sigma: float = 3.0
    nuisance_rms_trigger: float = 10.0
    nuisance_cap_rounds: int = 4
    excite_lat_mps2: float = 0.5
    excite_angacc_radps2: float = 0.05
    excite_torque_nm: float = 20.0
    structure_terms: bool = False
    folds: int = 8
    gap_blocks: int = 1
    bic_margin: float = 10.0
    min_explained: float = 0.05
    min_explained_overall: float = 0.2
    min_explained_innovations: float = 0.8
    min_explained_dynamics: float = 0.2
    min_explained_sensor_balance: float = 0.3
    material_fraction: float = 0.1
    corr_threshold: float = 0.95
    excitation_z: float = 5.0
    base_iterations: int = 2
    base_prior_rel_sigma: float = 0.5
    base_bounds: tuple[float, float] = (0.2, 5.0)
    max_effects: int = 3
    shortlist: int = 3
    joint_iterations: int = 1
    profile_steps: int = 5
    identify: tuple[str, ...] = BASE_PARAMS
    max_fit_s: float = 150.0
    """Row budget [s of drive]: a longer drive is fitted on evenly spread segments (``fit_budget``)."""
    fit_segment_s: float = 50.0
    """Length [s] of each of those segments."""
