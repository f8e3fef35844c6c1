"""The roll_stiffness effect (model/effects/chassis.py): the same physics as a vehicle file's
anti-roll bars, and its regressor is the roll moment's derivative (to first order in the
road-relative angles: the reduced model's loads act along the road normal at the contact
points)."""

import dataclasses

import pytest

from vdps_hil.model.chassis import Chassis
from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet, LinearTire, RollStiffness, make_effect
from vdps_hil.model.params import load_vehicle

SEDAN = load_vehicle("sedan-truth")


def _state(model, rng):
    x = model.design_state(18.0)
    x[3], x[4] = 0.015, -0.004  # rolled and pitched over the level road
    x[7], x[9], x[11] = rng.normal(0, 0.3), 0.05, 0.1
    return x


@pytest.mark.parametrize("dof", [False, True])
def test_effect_equals_the_vehicle_files_bars(dof, rng):
    kf, kr = 14000.0, 3000.0
    eff = Model(SEDAN, EffectSet([LinearTire(), RollStiffness(anti_roll_stiffness_front_nmprad=kf,
                                                               anti_roll_stiffness_rear_nmprad=kr)]), unsprung_dof=dof)
    veh = Model(dataclasses.replace(SEDAN, chassis=Chassis(anti_roll_stiffness_front_nmprad=kf,
                                                           anti_roll_stiffness_rear_nmprad=kr)), unsprung_dof=dof)
    x = _state(veh, rng)
    if dof:
        x[16:20] = [0.004, -0.006, -0.005, 0.003]
    assert eff.f(x, Inputs(0.3), Env()) == veh.f(x, Inputs(0.3), Env())
    assert eff.anti_roll_stiffness_nmprad == (kf, kr)


def test_regressor_is_the_roll_moments_derivative(rng):
    base = Model(SEDAN, unsprung_dof=False)
    x = _state(base, rng)
    d0 = base.evaluate(x, Inputs(0.2), Env())[1]
    e = make_effect("roll_stiffness")
    reg = e.regressors(base.regressor_quantities(d0))
    assert set(reg) == {"roll"}
    for name, k in (("anti_roll_stiffness_front_nmprad", 1000.0), ("anti_roll_stiffness_rear_nmprad", 1000.0)):
        other = {n: 0.0 for n in reg["roll"] if n != name}
        m = Model(SEDAN, EffectSet([LinearTire(), RollStiffness(**{name: k}, **other)]), unsprung_dof=False)
        d1 = m.evaluate(x, Inputs(0.2), Env())[1]
        assert d1["moment_b_nm_x"] - d0["moment_b_nm_x"] == pytest.approx(reg["roll"][name] * k, rel=1e-3)
        assert abs(reg["roll"][name]) > 1e-4  # the state is rolled: the column is not zero
