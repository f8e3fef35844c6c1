import math

import pytest

from vdps_hil.model.params import PARAM_NAMES, VehicleFileError, load_vehicle, parse_vehicle, VEHICLE_DIR


def test_default_vehicles_load_and_priors_differ():
    truth = load_vehicle("sedan-truth", "truth")
    model = load_vehicle("sedan-model", "model")
    assert 1.1 <= truth.geometry.static_stability_factor <= 1.5
    for n in PARAM_NAMES:
        t, p = getattr(truth.params, n), getattr(model.params, n)
        rel = p / t - 1.0
        assert abs(rel) >= 0.149, n  # every prior is off by >= 15 %
    assert math.isclose(model.params.mass_kg / truth.params.mass_kg, 1.15)
    # the known figures agree between the two files
    assert truth.geometry == model.geometry and truth.front == model.front and truth.tire == model.tire


def test_static_spring_balance_matches_corner_load():
    v = load_vehicle("sedan-truth")
    g = 9.80665
    lf, lr = v.geometry.l_f_m, v.geometry.l_r_m
    front = v.sprung_mass_kg * g * lr / (lf + lr) / 2
    rear = v.sprung_mass_kg * g * lf / (lf + lr) / 2
    for axle, load in ((v.front, front), (v.rear, rear)):
        k = axle.spring_c1_npm * math.exp(axle.spring_c2_per_m * (axle.static_compression_m - axle.spring_c3_m))
        assert k * axle.static_compression_m == pytest.approx(load, rel=1e-3)


@pytest.mark.parametrize("mutation,msg", [
    (lambda s: s.replace("mass_kg = 1840.0", "mass_kg = -1.0"), r"mass_kg = -1 is outside .* \[50, 100000\]"),
    (lambda s: s.replace("h_cg_m = 0.55", "h_cg_m = \"high\""), "finite number"),
    (lambda s: s.replace("[tire]", "[tire]\nbogus = 1"), "unknown key"),
    (lambda s: s.replace("kind = \"model\"", "kind = \"python\""), "kind must be"),
    (lambda s: s + "\n[[[", "malformed TOML"),
    (lambda s: s.replace("imu_lever_arm_m = [0.0, 0.0, 0.0]", "imu_lever_arm_m = [0.0, 0.0]"), "list of 3"),
    # absurd numbers of the right type (issue 20, finding 6): outside the physical range
    (lambda s: s.replace("l_f_m = 1.20", "l_f_m = 0.0").replace("l_r_m = 1.50", "l_r_m = 0.0"),
     r"l_f_m = 0 is outside its physical range \[0.05, 10\]"),
    (lambda s: s.replace("track_half_front_m = 0.79", "track_half_front_m = -0.79"),
     "track_half_front_m = -0.79 is outside"),
    (lambda s: s.replace("rolling_radius_m = 0.31", "rolling_radius_m = 0.0"), "rolling_radius_m = 0 is outside"),
    (lambda s: s.replace("h_cg_m = 0.55", "h_cg_m = 1e308"), "h_cg_m = 1e[+]308 is outside"),
    (lambda s: s.replace("gnss_lever_arm_m = [0.30, 0.0, 0.85]", "gnss_lever_arm_m = [0.30, 0.0, 1e9]"),
     "gnss_lever_arm_m = 1e[+]09 is outside"),
    (lambda s: s.replace("mass_kg = 1840.0", "mass_kg = 150.0"), "leaves no sprung mass"),
])
def test_bad_files_give_one_line_errors(mutation, msg):
    text = (VEHICLE_DIR / "sedan-model.toml").read_text()
    with pytest.raises(VehicleFileError, match=msg) as ei:
        parse_vehicle(mutation(text), "x.toml")
    assert "\n" not in str(ei.value)


def test_with_params_is_a_new_object():
    v = load_vehicle("sedan-model")
    w = v.with_params(mass_kg=1500.0)
    assert v.params.mass_kg == 1840.0 and w.params.mass_kg == 1500.0


def test_model_file_may_not_hold_truth_effects():
    text = (VEHICLE_DIR / "sedan-model.toml").read_text() + "\n[effects]\naero_drag = { cd_a_m2 = 0.7 }\n"
    with pytest.raises(VehicleFileError, match="truth only"):
        parse_vehicle(text, "x.toml")


def test_every_shipped_vehicle_file_is_inside_the_ranges():
    """The ranges admit every vehicle the project uses (city car to heavy truck, module doc)."""
    files = sorted(VEHICLE_DIR.glob("*.toml"))
    assert len(files) >= 6
    for f in files:
        load_vehicle(f)


def test_ranges_cover_every_number_of_a_vehicle_file():
    from dataclasses import fields

    from vdps_hil.model.params import _SECTIONS, RANGES

    names = {f.name for cls in _SECTIONS.values() for f in fields(cls)}
    assert names == set(RANGES)
    assert all(lo < hi for lo, hi in RANGES.values())
