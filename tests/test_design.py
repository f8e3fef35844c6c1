"""vdps_hil.workbench.ranking.design: the blocked cross-validation's folds (the design matrix
itself is exercised through the ranking: test_ranking, test_ranking_identification, test_gram)."""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.workbench.ranking.config import RankingConfig
from vdps_hil.workbench.ranking.design import Design


def _folds(n_blocks: int, **cfg):
    d = object.__new__(Design)  # folds reads only the block count and the configuration
    d.n_blocks, d.cfg = n_blocks, RankingConfig(**cfg)
    return d.folds()


@pytest.mark.parametrize("n_blocks", [4, 5, 7, 16, 17, 40, 121])
def test_every_block_is_held_out_once_and_fitted_on_outside_its_gap(n_blocks):
    cfg = RankingConfig()
    folds = _folds(n_blocks)
    assert len(folds) == max(2, min(cfg.folds, n_blocks // 2))
    held = np.concatenate([h for h, _ in folds])
    assert sorted(held) == list(range(n_blocks))  # each block held out exactly once
    for h, train in folds:
        assert len(train) and train.dtype.kind == "i"
        gap = set(range(h[0] - cfg.gap_blocks, h[-1] + cfg.gap_blocks + 1))
        assert set(train) == set(range(n_blocks)) - gap  # everything outside the held blocks and their gap


@pytest.mark.parametrize("n_blocks, gap", [(1, 1), (2, 1), (3, 1), (5, 3)])
def test_a_drive_too_short_to_hold_a_block_out_says_so(n_blocks, gap):
    with pytest.raises(ValueError, match="too short to judge an effect on held-out time blocks"):
        _folds(n_blocks, gap_blocks=gap)
