"""The paper's values beside ours (vdps_hil.experiments.paper_report): aggregation over the seeds
and the text table."""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.experiments import paper_report as P

PROFILE = "table1-susp1k"


def test_aggregate_identification_median_p90_and_two_sigma_fraction():
    rng = np.random.default_rng(3)
    docs = []
    for seed in range(10):
        e = rng.normal(0.0, 0.01)
        docs.append({"rel_err": {"mass_kg": e}, "rel_err_mean_window": {"mass_kg": e / 2},
                     "prior_rel_err": {"mass_kg": 0.15}, "sigma_ratio": {"mass_kg": abs(e) / 0.01}})
    agg = P.aggregate_identification(docs)["mass_kg"]
    errs = np.abs([d["rel_err"]["mass_kg"] for d in docs]) * 100
    assert agg["median_rel_err_pct"] == pytest.approx(np.median(errs))
    assert agg["p90_rel_err_pct"] == pytest.approx(np.percentile(errs, 90))
    assert agg["within_2_sigma"] == pytest.approx(np.mean([d["sigma_ratio"]["mass_kg"] <= 2 for d in docs]))
    assert agg["paper_rel_err_pct"] == P.PAPER["identification_rel_err_pct"]["mass_kg"]
    text = P.format_report({"profile": PROFILE, "seeds": list(range(10)), "identification": {"mass_kg": agg}})
    assert "mass_kg" in text and "paper" in text
