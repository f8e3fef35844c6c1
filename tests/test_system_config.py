"""The system node's configuration (``pipeline.system_config``): every bad setting is a one-line
``ValueError`` naming it; ``for_profile`` gives the EKF the suspension sigma of the conditioned
sample (window means of n sensor samples: k sigma / sqrt(n))."""

from __future__ import annotations

import math

import pytest

from vdps_hil.estimation.suspension import CONDITIONING_SIGMA_FACTOR
from vdps_hil.pipeline.system_config import LIVE_PREDICTIONS, PREDICT_FROM, SystemConfig


@pytest.mark.parametrize("kw,name", [
    ({"estimate_period_s": 0.0}, "estimate_period_s"), ({"ident_period_s": math.nan}, "ident_period_s"),
    ({"ident_report_period_s": -1.0}, "ident_report_period_s"),
    ({"convergence_period_s": math.inf}, "convergence_period_s"),
    ({"suspension_rate_hz": 0.0}, "suspension_rate_hz"), ({"prediction_worker": "gpu"}, "prediction_worker"),
    ({"prediction_deadline": "later"}, "prediction_deadline"), ({"predict_from": "truth"}, "predict_from"),
    ({"suspension_stamp": "middle"}, "suspension_stamp")])
def test_a_bad_setting_is_a_one_line_error_naming_it(kw, name):
    with pytest.raises(ValueError, match=name) as e:
        SystemConfig(**kw)
    assert "\n" not in str(e.value)


def test_defaults_and_the_live_settings_are_accepted():
    cfg = SystemConfig()
    assert cfg.predict_from == PREDICT_FROM[0] == "identified" and cfg.suspension_rate_hz == 100.0
    live = SystemConfig(**LIVE_PREDICTIONS)
    assert live.prediction_worker == "process" and live.prediction_deadline == "drop" and not live.keep_input_log


@pytest.mark.parametrize("rate_hz,stamp,factor", [(1000.0, "mean", 1.0 / math.sqrt(10)),
                                                 (1000.0, "end", CONDITIONING_SIGMA_FACTOR / math.sqrt(10)),
                                                 (1.0, "end", 1.0), (100.0, "mean", 1.0)])
def test_for_profile_gives_the_conditioned_samples_sigma(rate_hz, stamp, factor):
    cfg = SystemConfig.for_profile(rate_hz, 0.002, suspension_stamp=stamp)
    assert cfg.pipeline.susp_sigma_m == pytest.approx(0.002 * factor, rel=1e-12)
