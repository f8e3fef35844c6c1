"""The ranking's base fit (``workbench.ranking.identification``): the slow body-velocity nuisance
is kept within the estimator's own uncertainty (``cap_nuisance``), and on CommonRoad's multibody
truth that keeps the re-identified cornering stiffnesses near the truth and lets tire saturation
be found on the circle ramp (issue 18; a reduced, seeded version of ``tools/workbench_study_cr.py``,
seed 21: neither the tuning seeds 100-103 nor the study's 1000+)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from vdps_hil.experiments.workbench_study import STUDY_SEEDS, TUNING_SEEDS
from vdps_hil.workbench.ranking.config import RankingConfig
from vdps_hil.workbench.ranking.identification import cap_nuisance

SEED = 21


def _design(sigma_mps, boost=None):
    """A stand-in for a Design with a band block of estimator sigmas ``sigma_mps`` (column scale 1,
    prior weight 1 / sigma^2 times the boost already applied)."""
    boost = np.ones(len(sigma_mps)) if boost is None else np.asarray(boost, dtype=float)
    w = boost / np.asarray(sigma_mps, dtype=float) ** 2
    return SimpleNamespace(blocks={"_smooth": [3, 4, 5]}, prior_w=[0.0, 0.0, 0.0, *w])


def test_a_nuisance_within_the_estimators_sigma_is_left_alone():
    d = _design([0.02, 0.02, 0.02])
    states = SimpleNamespace()
    th = np.array([0.0, 0.0, 0.0, 0.05, -0.04, 0.0])  # 2.5 and 2 sigma
    assert not cap_nuisance(d, [0, 1, 2, 3, 4, 5], th, states, RankingConfig())
    assert getattr(states, "band_weight", None) is None


def test_a_nuisance_beyond_the_cap_gets_a_tighter_prior_kept_per_drive():
    cfg = RankingConfig()
    d = _design([0.02, 0.02, 0.04])
    states = SimpleNamespace()
    th = np.array([0.0, 0.0, 0.0, 0.7, 0.03, -0.24])  # 35, 1.5 and 6 sigma (the circle's 0.7 m/s)
    assert cap_nuisance(d, [0, 1, 2, 3, 4, 5], th, states, cfg)
    assert np.allclose(states.band_weight, [(35.0 / cfg.nuisance_cap_sigma) ** 2, 1.0, (6.0 / cfg.nuisance_cap_sigma) ** 2])
    # the next design carries the boost in its prior weights; z stays relative to the estimator's sigma
    d2 = _design([0.02, 0.02, 0.04], states.band_weight)
    th2 = np.array([0.0, 0.0, 0.0, 0.08, 0.03, -0.1])  # 4, 1.5, 2.5 sigma of the estimator
    assert cap_nuisance(d2, [0, 1, 2, 3, 4, 5], th2, states, cfg)
    assert math.isclose(states.band_weight[0], (35.0 / 3.0) ** 2 * (4.0 / 3.0) ** 2)
    assert states.band_weight[1] == 1.0 and math.isclose(states.band_weight[2], 4.0)


def test_seed_is_disjoint():
    assert SEED not in TUNING_SEEDS and SEED not in STUDY_SEEDS
