"""The predictor's configuration (prediction/config.py): the shipped default is the documented one."""

from vdps_hil.prediction.config import PredictorConfig, load_predictor_config


def test_default_config_is_the_documented_one():
    cfg = load_predictor_config()
    assert cfg == PredictorConfig()
    assert (cfg.horizon_s, cfg.step_s, cfg.integrator, cfg.cadence_hz) == (5.0, 0.01, "ros2", 10.0)
    assert cfg.effects == ("linear_tire",) and cfg.unsprung_dof is False
    assert cfg.n_steps == 500
