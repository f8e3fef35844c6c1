"""Tests of ``vdps_hil.sim.truth_backends``: spec parsing (one-line errors), our own simulator as
the default, the CommonRoad backend loaded lazily (a drive on our truth never imports the
package), and every backend error a configuration error of ``vdps sim``."""

from __future__ import annotations

import subprocess
import sys

import pytest

from vdps_hil.sim.truth_backends import BACKENDS, OURS, TruthBackendError, parse_truth_spec, truth_backend


def test_specs_parse_and_ours_is_the_default():
    assert parse_truth_spec("commonroad-mb:3") == ("commonroad-mb", "3")
    assert parse_truth_spec(" ours ") == (OURS, "")
    assert truth_backend(None) is None and truth_backend("ours") is None
    for bad in ("nope", "ours:1", "", "commonroad"):
        with pytest.raises(TruthBackendError) as e:
            parse_truth_spec(bad)
        assert "\n" not in str(e.value)


def test_the_commonroad_backend_is_registered_and_refuses_bad_sets():
    assert "commonroad-mb" in BACKENDS
    b = truth_backend("commonroad-mb:1", flat_road=True)
    assert b.spec == "commonroad-mb:1" and b.flat_road and b.vehicle.kind == "truth"
    for bad in ("commonroad-mb", "commonroad-mb:x", "commonroad-mb:2", "commonroad-mb:4", "commonroad-mb:1:brush",
                "commonroad-mb:2:linear-lateral"):
        with pytest.raises(TruthBackendError) as e:
            truth_backend(bad)
        assert "\n" not in str(e.value)


def test_the_linear_lateral_variant_is_the_same_vehicle_without_saturation():
    b = truth_backend("commonroad-mb:3:linear-lateral")
    assert b.spec == "commonroad-mb:3:linear-lateral" and b.set_id == 3 and b.lateral_law == "linear"
    assert b.vehicle == truth_backend("commonroad-mb:3").vehicle
    assert b.describe()["lateral_law"] == "linear" and truth_backend("commonroad-mb:3").describe()["lateral_law"] == "pacejka"


def test_backend_errors_are_configuration_errors_of_a_drive():
    from vdps_hil.sim.cr_model import CrParameterError
    from vdps_hil.sim.drive import CONFIG_ERRORS
    from vdps_hil.sim.cr_convert import TruthRangeError
    assert issubclass(CrParameterError, CONFIG_ERRORS) and issubclass(TruthRangeError, CONFIG_ERRORS)


def test_a_drive_on_our_truth_does_not_import_the_commonroad_package():
    code = ("import sys; from vdps_hil.sim.drive import Drive; Drive('paper', duration_s=0.05); "
            "print(any(m.startswith('vehiclemodels') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "False"
