"""The acceptance study's evaluation (experiments.ident_study) on one independent-truth drive
(CommonRoad multibody set 3, straight drive with accelerate/brake pulses, a study seed), and the
rule that no study or test seed is a tuning seed."""

import math

import pytest

from vdps_hil.experiments.ident_drives import DriveKey
from vdps_hil.experiments.ident_study import CR_SCENARIOS, STUDY_SEEDS, TUNING_SEEDS, evaluate

TEST_SEEDS = (112,)


def test_no_study_or_test_seed_is_a_tuning_seed():
    from vdps_hil.experiments.seeds import check_held_out

    assert not set(STUDY_SEEDS) & set(TUNING_SEEDS)
    check_held_out([*STUDY_SEEDS, *TEST_SEEDS], __name__)  # every tuning set's (experiments.seeds)
    assert not set(TEST_SEEDS) & set(STUDY_SEEDS)
    assert len(CR_SCENARIOS) == 4


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    key = DriveKey("cr-straight-pulses", "commonroad-mb:3", "cr3-model", TEST_SEEDS[0])
    return evaluate(key, tmp_path_factory.mktemp("drives"))


@pytest.mark.slow
def test_straight_drive_makes_no_cornering_update_and_claims_no_cornering_stiffness(straight):
    res, st = straight
    assert st["counters"]["cornering"]["updates"] == 0
    assert st["converged"]["cornering"] is False
    assert st["status"]["cornering"]["gated"]["lateral excitation"] > 1000
    for r in res:
        if r.name.startswith("cornering"):
            assert r.status == "not excited"


@pytest.mark.slow
def test_nothing_reported_identified_sits_on_a_bound(straight):
    res, st = straight
    assert len(res) == 10
    for r in res:
        if r.status == "identified":
            assert not r.on_bound, r
            assert math.isfinite(r.sigma) and r.sigma > 0.0
        if r.on_bound:
            assert r.status == "at bound", r
    for name, ps in st["status"].items():
        if ps["status"] == "converged":
            assert all(p["status"] == "identified" for p in ps["params"].values())
