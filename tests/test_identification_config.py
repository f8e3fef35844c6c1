"""The identification configuration: the default file loads, bad files give one-line errors,
the p0_scaled and moment_form options."""

import numpy as np
import pytest

from ident_forward import MODEL
from vdps_hil.identification.config import (DEFAULT_CONFIG_PATH, IdentConfigError, load_ident_config,
                                            parse_ident_config)
from vdps_hil.identification.identifier import Identifier


def test_default_config_loads():
    cfg = load_ident_config()
    assert cfg.form == "covariance" and cfg.bounds_factor == (0.3, 3.0)
    assert len(cfg.tracking.q) == 4 and len(cfg.inertia.excitation_min) == 3


@pytest.mark.parametrize("mutation,msg", [
    (lambda s: s.replace('form = "covariance"', 'form = "magic"'), "form"),
    (lambda s: s.replace("forgetting = 1.0", "forgetting = 1.5", 1), "forgetting"),
    (lambda s: s.replace("q = [0.005]", "q = [0.005, 1.0]"), "list of 1"),
    (lambda s: s.replace("q = [0.005]", "q = [-1.0]"), "positive"),
    (lambda s: s.replace("[general]", "[general]\nbogus = 1"), "unknown key"),
    (lambda s: s.replace("schema_version = 1", "schema_version = 7"), "schema_version"),
    (lambda s: s.replace("bounds_factor = [0.3, 3.0]", "bounds_factor = [1.3, 3.0]"), "lo < 1 < hi"),
    (lambda s: s + "\n[[[", "malformed TOML"),
])
def test_bad_configs_give_one_line_errors(mutation, msg):
    text = mutation(DEFAULT_CONFIG_PATH.read_text())
    with pytest.raises(IdentConfigError, match=msg) as e:
        parse_ident_config(text, "bad.toml")
    assert "\n" not in str(e.value)


def test_p0_scaled_option_sets_the_papers_initial_covariance():
    text = DEFAULT_CONFIG_PATH.read_text().replace(
        "[inertia]                        # eq 23: x = [I_x, I_y, I_z]; b in N m\n",
        "[inertia]\np0_scaled = 4.0\n").replace(
        'q = [0.01, 0.01, 0.01]\nw = "prior"', "q = [0.01, 0.01, 0.01]\nw = [1.0, 1.0, 1.0]")
    cfg = parse_ident_config(text)
    assert cfg.inertia.p0_scaled == 4.0 and cfg.inertia.w == (1.0, 1.0, 1.0)
    ident = Identifier(MODEL, cfg)
    assert np.allclose(ident.problem("inertia").covariance_scaled, 4.0 * np.eye(3))


def test_moment_form_config_key_is_optional_and_checked():
    text = DEFAULT_CONFIG_PATH.read_text()
    assert load_ident_config().moment_form == "measured"
    assert parse_ident_config(text.replace('moment_form = "measured"', "")).moment_form == "stiffness"
    with pytest.raises(IdentConfigError, match="moment_form"):
        parse_ident_config(text.replace('moment_form = "measured"', 'moment_form = "nope"'))


def test_load_band_is_a_tracking_key_off_by_default():
    text = DEFAULT_CONFIG_PATH.read_text()
    assert load_ident_config().tracking.load_band == float("inf")
    cfg = parse_ident_config(text.replace("# load_band = inf", "load_band = 0.1"))
    assert cfg.tracking.load_band == 0.1
    with pytest.raises(IdentConfigError, match="applies to \\[tracking\\] only"):
        parse_ident_config(text.replace("[mass]                           # eq 20", "[mass]\nload_band = 0.1\n# eq 20"))


@pytest.mark.parametrize("value,ok", [("0.05", True), ("0", False), ("-1", False), ("nan", False), ('"x"', False)])
def test_suspension_max_interval_is_a_positive_number(value, ok):
    text = DEFAULT_CONFIG_PATH.read_text().replace("suspension_max_interval_s = 0.02",
                                                   f"suspension_max_interval_s = {value}", 1)
    if ok:
        assert parse_ident_config(text).suspension_max_interval_s == float(value)
    else:
        with pytest.raises(IdentConfigError, match="suspension_max_interval_s"):
            parse_ident_config(text)
