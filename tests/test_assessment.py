"""Tests of vdps_hil.prediction.assessment: the rollover measures of a prediction and the
assessment's time to rollover at a later instant."""

import numpy as np
import pytest

from vdps_hil.prediction.assessment import RolloverAssessment, load_transfer_ratio

MS = 1_000_000


def test_load_transfer_ratio_sign_and_zero_total():
    fz = np.array([[4000.0, 4000.0, 4000.0, 4000.0],  # even
                   [0.0, 5000.0, 5000.0, 0.0],  # left wheels off: +1 (roll right side down)
                   [3000.0, 1000.0, 1000.0, 3000.0],  # (2000 - 6000) / 8000
                   [0.0, 0.0, 0.0, 0.0]])
    assert np.allclose(load_transfer_ratio(fz), [0.0, 1.0, -0.5, 0.0])


def test_time_to_rollover_ages_from_t0_and_stops_at_zero():
    a = RolloverAssessment(1000 * MS, 2.0, None, 0.0, 0.0, 0.0, 5.0, "horizon")
    assert a.ttr_at(1000 * MS) == 2.0 and a.ttr_at(1600 * MS) == pytest.approx(1.4)
    assert a.ttr_at(5000 * MS) == 0.0
    assert RolloverAssessment(0, None, None, 0.0, 0.0, 0.0, 5.0, "horizon").ttr_at(10 * MS) is None
