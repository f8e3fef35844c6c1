"""Chassis parts (model/chassis.py): the anti-roll bar's roll moment, the roll centre's lever,
the Ackermann fraction, the [chassis] table of a vehicle file, and the physics core carrying
them in both variants (the paper's model unchanged without them)."""

import dataclasses
import math
import re

import pytest

from vdps_hil.model.chassis import (PAPER_CHASSIS, Chassis, anti_roll_forces_n, blend_ackermann,
                                    roll_centre_forces_n)
from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.params import VehicleFileError, load_vehicle, parse_vehicle, resolve_vehicle_path
from vdps_hil.model.stages import ackermann_angles, steer_angles

SEDAN = load_vehicle("sedan-truth")
TF, TR = 2 * SEDAN.geometry.track_half_front_m, 2 * SEDAN.geometry.track_half_rear_m


def _with(veh, **chassis):
    return dataclasses.replace(veh, chassis=Chassis(**chassis))


def test_anti_roll_forces_resist_the_relative_roll_and_sum_to_zero_per_axle():
    kf, kr, phi = 12000.0, 4000.0, 0.02  # right side down: the right struts compress
    h = (-phi * TF / 2, phi * TF / 2, phi * TR / 2, -phi * TR / 2)  # FL FR RR RL
    f = anti_roll_forces_n(kf, kr, TF, TR, h)
    y = [c[1] for c in SEDAN.geometry.corner_xy_m()]
    assert f[0] + f[1] == pytest.approx(0.0, abs=1e-9) and f[2] + f[3] == pytest.approx(0.0, abs=1e-9)
    assert sum(yi * fi for yi, fi in zip(y, f)) == pytest.approx(-(kf + kr) * phi, rel=1e-12)


def test_roll_centre_forces_shorten_the_lateral_lever_by_h_rc():
    hf, hr, fyf, fyr = 0.08, 0.12, 3000.0, 2500.0
    j = roll_centre_forces_n(hf, hr, TF, TR, fyf, fyr)
    y = [c[1] for c in SEDAN.geometry.corner_xy_m()]
    assert sum(yi * ji for yi, ji in zip(y, j)) == pytest.approx(-(hf * fyf + hr * fyr), rel=1e-12)
    assert j[1] > 0 and j[2] > 0  # a force to the left loads the right (outer) wheels


def test_ackermann_fraction_blends_full_ackermann_and_parallel_steer():
    L, tf, dm = SEDAN.geometry.wheelbase_m, SEDAN.geometry.track_half_front_m, 0.1
    full = ackermann_angles(dm, L, tf)
    assert steer_angles(dm, L, tf, 1.0) == full
    assert steer_angles(dm, L, tf, 0.0) == pytest.approx((dm, dm), abs=1e-15)
    half = steer_angles(dm, L, tf, 0.5)
    assert half == pytest.approx(((dm + full[0]) / 2, (dm + full[1]) / 2), abs=1e-15)
    assert full[0] > dm > full[1]  # left turn: the inner (left) wheel steers more
    assert blend_ackermann(dm, *full, 1.0) == full


def test_vehicle_file_chassis_table_is_optional_checked_and_one_line():
    text = resolve_vehicle_path("sedan-model").read_text()
    assert parse_vehicle(text).chassis == PAPER_CHASSIS and PAPER_CHASSIS.is_paper
    v = parse_vehicle(text + "\n[chassis]\nanti_roll_stiffness_front_nmprad = 9000\nackermann_fraction = 0\n")
    assert v.chassis == Chassis(anti_roll_stiffness_front_nmprad=9000.0, ackermann_fraction=0.0)
    assert v.chassis.has_anti_roll_bars and not v.chassis.has_roll_centres and not v.chassis.is_paper
    for bad, why in (("anti_roll_stiffness_front_nmprad = -1", "must not be negative"),
                     ("roll_centre_height_front_m = 'high'", "finite number"),
                     ("bar = 1", "unknown key 'bar'"), ("ackermann_fraction = 5", "within [-1, 2]"),
                     ("wheel_roll_coupling = 1.5", "within [0, 1]")):
        with pytest.raises(VehicleFileError, match=re.escape(why)) as e:
            parse_vehicle(text + f"\n[chassis]\n{bad}\n")
        assert "\n" not in str(e.value)


def test_cr_model_files_carry_the_packages_roll_stiffness_and_parallel_steer():
    c1, c3 = load_vehicle("cr1-model").chassis, load_vehicle("cr3-model").chassis
    assert c1.anti_roll_stiffness_front_nmprad == pytest.approx(12880.27, abs=0.01) and c1.anti_roll_stiffness_rear_nmprad == 0
    assert c3.anti_roll_stiffness_front_nmprad == pytest.approx(33948.22, abs=0.01)
    assert c3.anti_roll_stiffness_rear_nmprad == pytest.approx(7731.374, abs=0.001)
    assert c1.ackermann_fraction == c3.ackermann_fraction == 0.0 and not (c1.has_roll_centres or c3.has_roll_centres)
    assert c1.wheel_roll_coupling == c3.wheel_roll_coupling == 0.0  # its slip uses the sprung CG's v


def _rolled_state(model, phi):
    """At rest, body rolled by phi about its CG relative to the level road (unsprung DOF: the
    deflections of that roll)."""
    x = model.design_state(0.0)
    x[3] = phi
    if model.unsprung_dof:
        for i, (_, y) in enumerate(SEDAN.geometry.corner_xy_m()):
            x[16 + i] = -y * math.sin(phi)  # right side down: the right corners compress
    return x


@pytest.mark.parametrize("dof", [False, True])
def test_core_roll_moment_grows_by_the_bar_stiffness(dof):
    phi, kf, kr = 0.01, 15000.0, 6000.0
    base = Model(SEDAN, unsprung_dof=dof)
    bars = Model(_with(SEDAN, anti_roll_stiffness_front_nmprad=kf, anti_roll_stiffness_rear_nmprad=kr),
                 unsprung_dof=dof)
    x = _rolled_state(base, phi)
    m0 = base.evaluate(x, Inputs(), Env())[1]["moment_b_nm_x"]
    m1 = bars.evaluate(x, Inputs(), Env())[1]["moment_b_nm_x"]
    assert m1 - m0 == pytest.approx(-(kf + kr) * phi, rel=1e-3)


@pytest.mark.parametrize("dof", [False, True])
def test_core_roll_centre_moves_the_lateral_lever(dof):
    hf, hr = 0.10, 0.05
    base = Model(SEDAN, unsprung_dof=dof)
    rc = Model(_with(SEDAN, roll_centre_height_front_m=hf, roll_centre_height_rear_m=hr), unsprung_dof=dof)
    x = base.design_state(20.0)
    x[7] = -0.5  # sideslip to the right: the tires push left
    d0 = base.evaluate(x, Inputs(), Env())[1]
    d1 = rc.evaluate(x, Inputs(), Env())[1]
    fyf = sum(d0[f"tire_force_lat_n_{i}"] for i in (1, 2))
    fyr = sum(d0[f"tire_force_lat_n_{i}"] for i in (3, 4))
    assert fyf > 1000 and fyr > 1000
    assert d1["moment_b_nm_x"] - d0["moment_b_nm_x"] == pytest.approx(-(hf * fyf + hr * fyr), rel=1e-6)
    assert d1["force_b_n_z"] == pytest.approx(d0["force_b_n_z"], abs=1e-6)


def test_paper_chassis_is_bit_identical_and_parallel_steer_reaches_the_wheels(rng):
    explicit = Model(_with(SEDAN), unsprung_dof=False)
    plain = Model(SEDAN, unsprung_dof=False)
    for _ in range(20):
        x = plain.design_state(15.0)
        x[3:6] = rng.normal(0, 0.02, 3).tolist()
        x[7], x[11] = rng.normal(0, 0.5), rng.normal(0, 0.2)
        u = Inputs(float(rng.normal(0, 0.5)), tuple(rng.normal(0, 100, 4)))
        assert explicit.f(x, u, Env()) == plain.f(x, u, Env())
    par = Model(_with(SEDAN, ackermann_fraction=0.0), unsprung_dof=False)
    d = par.evaluate(plain.design_state(15.0), Inputs(0.8), Env())[1]
    assert d["road_wheel_angle_rad_1"] == d["road_wheel_angle_rad_2"] == pytest.approx(0.8 / SEDAN.geometry.steer_ratio)
