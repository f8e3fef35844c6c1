"""Vehicle-dynamics words: the saturation angle, the maneuvers that separate known groups."""

from __future__ import annotations

from types import SimpleNamespace

from vdps_hil.model.effects import MagicFormulaTire
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import words as W


def _rk():
    return SimpleNamespace(base_vehicle=load_vehicle("sedan-model").with_params(cornering_stiffness_front_nprad=120000.0))


def test_saturation_angle_is_where_the_magic_formula_drops_five_percent():
    rk = _rk()
    a = W._saturation_angle_deg(rk, 1.0)
    veh = rk.base_vehicle
    fz = veh.params.mass_kg * 9.80665 * veh.geometry.l_r_m / veh.geometry.wheelbase_m / 2.0
    ca = 60000.0
    import math
    alpha = math.radians(a)
    f = MagicFormulaTire().tire_forces(fz, fz, 0.0, alpha, 80000.0, ca)[1]
    assert abs(f / (ca * alpha) - 0.95) < 0.01
    assert W._saturation_angle_deg(rk, 0.5) < a  # less friction saturates earlier


def test_known_groups_have_their_maneuvers():
    assert "kinematics-and-compliance" in W.separating_maneuver("steering_compliance", "cornering_stiffness_front")
    assert "circle" in W.separating_maneuver("load_dependent_cornering_stiffness", "magic_formula_tire")
    assert "out-and-back" in W.separating_maneuver("imu_bias", "rolling_resistance")
    assert "kinematics" in W.group_maneuver(["cornering_stiffness_front", "magic_formula_tire", "steering_compliance"])
    assert "vary" in W.separating_maneuver("crosswind", "low_pressure_tire")


def test_equation_phrases():
    assert W.equation_phrase("lat") == "lateral residual"
    assert W.equation_phrase("innov_vel") == "GNSS velocity innovations"
