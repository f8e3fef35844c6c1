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
    # one cornering coefficient c for the four tires: the front tire's stiffness is c F_z0
    c = ca / fz
    assert abs(W._saturation_angle_deg(rk, 1.0, c) - a) < 1e-9 * a
    assert abs(W._saturation_angle_deg(rk, 1.0, 2.0 * c) - 0.5 * a) < 1e-9 * a


def test_known_groups_have_their_maneuvers():
    assert "kinematics-and-compliance" in W.separating_maneuver("steering_compliance", "cornering_stiffness_front")
    assert "circle" in W.separating_maneuver("load_dependent_cornering_stiffness", "magic_formula_tire")
    assert "out-and-back" in W.separating_maneuver("imu_bias", "rolling_resistance")
    assert "kinematics" in W.group_maneuver(["cornering_stiffness_front", "magic_formula_tire", "steering_compliance"])
    assert "vary" in W.separating_maneuver("crosswind", "low_pressure_tire")


def test_equation_phrases():
    assert W.equation_phrase("lat") == "lateral residual"
    assert W.equation_phrase("innov_vel") == "GNSS velocity innovations"


def _param_entry(value, plausible):
    from vdps_hil.workbench.ranking.results import RankEntry

    ref = 1655.0
    used = min(max(value, 0.2 * ref), 5.0 * ref)
    return RankEntry(effect="inertia_z", kind="parameter", explained_fraction=0.3, explained_by_equation={},
                     parameters={"inertia_z_kgm2": (value, 48.0)}, plausible=plausible, excited=True,
                     excitation_z=float("nan"), group=[], reference={"inertia_z_kgm2": ref},
                     model_value={"inertia_z_kgm2": used}, plausible_range={"inertia_z_kgm2": (0.2 * ref, 5.0 * ref)})


def test_an_implausible_parameter_is_never_called_identified():
    """A negative yaw inertia (seen on a CommonRoad sine) is labelled as not identified, in the
    one-line form the text summary prints too (up to the first ';'), with the value the model keeps."""
    msg = W.describe_entry(_rk(), _param_entry(-14.92, False))
    head = msg.split(";")[0]
    assert "NOT identified" in head and "implausible" in head and "negative" in head
    assert "identified -14" not in msg
    assert "the model keeps 331 kg m^2" in head  # the lower bound, 0.2 x the model file's 1655
    ok = W.describe_entry(_rk(), _param_entry(1800.0, True))
    assert ok.startswith("yaw inertia: identified 1800") and "NOT" not in ok


def test_undetermined_parameters_are_said_to_be_undetermined():
    """A fit whose sigma is not below its value is no identified number: alone it is 'not
    determined', two or more such (a collinear front/rear pair, as on CommonRoad's set-3 circle:
    1.71e+04 +- 7.2e+08 each) 'cannot be told apart'; determined ones are printed plainly."""
    pair = {"anti_roll_stiffness_front_nmprad": (1.71e4, 7.2e8), "anti_roll_stiffness_rear_nmprad": (1.71e4, 7.2e8)}
    text = W._generic_words(pair)
    assert "cannot be told apart on this drive" in text and "only a combination" in text
    one = W._generic_words({"a": (2.0, 0.1), "b": (0.5, 3.0)})
    assert one.count("not determined on this drive") == 1 and one.index("not determined") > one.index("b = ")
    assert "not determined" not in W._generic_words({"a": (2.0, 0.1)})
    assert "cannot be told apart" not in W._generic_words({"a": (2.0, 0.1), "b": (3.0, 0.5)})


def test_a_fitted_parameter_is_called_identified_only_when_the_identifier_agrees():
    """The identifier's verdict (``ranking.rls_check``) in the one-line form the summary prints:
    'identified' only on agreement (or without the identifier); otherwise 'not confirmed' with the
    identifier's value and z, or its status."""
    e = _param_entry(1800.0, True)
    e.identifier = {"param": "inertia_z_kgm2", "value": 1790.0, "sigma": 60.0, "status": "identified", "z": 0.13,
                    "verdict": "agrees"}
    head = W.describe_entry(_rk(), e).split(";")[0]
    assert head.startswith("yaw inertia: identified 1800") and "the identifier agrees (1790 +- 60 kg m^2)" in head
    e.identifier = dict(e.identifier, value=1500.0, z=3.9, verdict="disagrees")
    head = W.describe_entry(_rk(), e).split(";")[0]
    assert head.startswith("yaw inertia: not confirmed -- fitted 1800") and "the identifier 1500" in head
    assert "z = 3.9" in head and "identified" not in head
    e.identifier = dict(e.identifier, status="model mismatch", verdict="unconfirmed")
    head = W.describe_entry(_rk(), e).split(";")[0]
    assert head.startswith("yaw inertia: not confirmed") and 'the identifier says "model mismatch"' in head
