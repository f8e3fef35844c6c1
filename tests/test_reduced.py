"""The specialised reduced core (model/reduced.py) is the same equations as the generic core:
equal to Model.f on random states, inputs and roads (relative 1e-9; measured ~1e-12), its
diagnostics equal the core's, and its closed-form wheel-spin Jacobian equals a forward
difference of Model.f. The compiled kernels equal their Python source run by CPython
(``py_func``) bit for bit (0 ulp: the same IEEE operations in the same order, the same libm)."""

import dataclasses
import math
import random

import numpy as np
import pytest

from vdps_hil.model.chassis import Chassis
from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet, LinearTire, make_effect
from vdps_hil.model.params import load_vehicle
from vdps_hil.model.reduced import ReducedLinearCore, reduced_rhs, supports, wheel_spin_jacobian

from core_cases import random_case

CHASSIS = Chassis(anti_roll_stiffness_front_nmprad=30000.0, anti_roll_stiffness_rear_nmprad=12000.0,
                  roll_centre_height_front_m=0.05, roll_centre_height_rear_m=0.12, ackermann_fraction=0.5)
"""Every chassis part at once (``model.chassis``), on the sedan."""


def _vehicle(name):
    if name == "sedan-chassis":
        return dataclasses.replace(load_vehicle("sedan-model"), chassis=CHASSIS)
    return load_vehicle(name)


@pytest.mark.parametrize("name", ["sedan-model", "suv-model", "cr1-model", "cr3-model", "sedan-chassis"])
@pytest.mark.parametrize("extra", [(), ("low_pressure_tire",), ("roll_stiffness",)])
def test_equals_the_generic_core(name, extra):
    """Also with the chassis parts (the CommonRoad model files' anti-roll bars and parallel steer;
    every part at once on the sedan; a ``roll_stiffness`` effect's auxiliary roll stiffness)."""
    model = Model(_vehicle(name), EffectSet([LinearTire(), *(make_effect(e) for e in extra)]),
                  unsprung_dof=False)
    core = ReducedLinearCore(model)
    rng = random.Random(6)
    n_lifted = 0
    for k in range(300):
        x, u, env = random_case(model, rng, lift=k % 3 == 0)
        out = {}
        ref = model.f(x, u, env, out)
        xd, fz, nb, kap, den, tfz = core.f(x, core.inputs(u), env)
        scale = [max(1.0, abs(v)) for v in ref]
        assert max(abs(a - b) / s for a, b, s in zip(xd, ref, scale)) < 1e-9
        assert max(abs(a - b) for a, b in zip(nb, out["_normal_b"])) < 1e-12
        for i in range(4):
            assert fz[i] == pytest.approx(out["_rec"][i][2], rel=1e-9, abs=1e-6)
            assert kap[i] == pytest.approx(out["_rec"][i][3], rel=1e-9, abs=1e-12)
        n_lifted += any(f == 0.0 for f in tfz)
        if not model.vehicle.chassis.has_roll_centres:
            assert tfz == fz
    assert n_lifted >= 10  # the lift-off branch was exercised


@pytest.mark.parametrize("name", ["sedan-model", "sedan-chassis"])
def test_wheel_spin_jacobian_equals_a_forward_difference_of_the_core(name):
    model = Model(_vehicle(name), EffectSet([LinearTire()]), unsprung_dof=False)
    core = ReducedLinearCore(model)
    rng = random.Random(7)
    for _ in range(100):
        x, u, env = random_case(model, rng, lift=False)
        x[12] = rng.choice([x[12], 0.7, -1.9, 3.0])  # also inside the brake's hold band
        f0 = model.f(x, u, env)
        _, _, _, _, den, tfz = core.f(x, core.inputs(u), env)
        jd = core.wheel_spin_jacobian(x, core.inputs(u), tfz, den)
        for i in range(4):
            xp = list(x)
            e = 1e-4 * max(1.0, abs(x[12 + i]))
            xp[12 + i] += e
            fd = (model.f(xp, u, env)[12 + i] - f0[12 + i]) / e
            assert jd[i] == pytest.approx(fd, rel=1e-6, abs=1e-6 * max(1.0, abs(fd)))
        assert all(j <= 0.0 for j in jd)


def test_supports_only_the_reduced_linear_model():
    veh = load_vehicle("sedan-model")
    assert supports(Model(veh, EffectSet([LinearTire()]), unsprung_dof=False))
    assert not supports(Model(veh, EffectSet([LinearTire()]), unsprung_dof=True))
    assert not supports(Model(veh, EffectSet([make_effect("magic_formula_tire")]), unsprung_dof=False))
    assert not supports(Model(veh, EffectSet([LinearTire(), make_effect("aero_drag")]), unsprung_dof=False))
    with pytest.raises(ValueError, match="reduced model"):
        ReducedLinearCore(Model(veh, EffectSet([LinearTire()]), unsprung_dof=True))


def test_straight_rolling_on_a_level_road_is_steady():
    """Physics sanity of the specialised path alone: design state, no inputs, no slip -> no
    wheel acceleration, no yaw, no x-acceleration, equal loads left and right."""
    model = Model(load_vehicle("sedan-model"), EffectSet([LinearTire()]), unsprung_dof=False)
    core = ReducedLinearCore(model)
    x = model.design_state(20.0)
    xd, fz, _, kap, _, _ = core.f(x, core.inputs(Inputs()), Env())
    assert all(abs(k) < 1e-12 for k in kap) and all(abs(v) < 1e-9 for v in xd[12:16])
    assert abs(xd[6]) < 1e-9 and abs(xd[11]) < 1e-9
    assert fz[0] == pytest.approx(fz[1], rel=1e-12) and fz[3] == pytest.approx(fz[2], rel=1e-12)
    assert min(fz) > 0.0
    assert math.isclose(xd[0], 20.0, rel_tol=1e-12)


def test_compiled_kernels_equal_their_python_source_bit_for_bit():
    """0 ulp on x_dot, loads, n_b, slips, slip denominators and the wheel-spin Jacobian (the
    kernel as compiled vs ``py_func``; with ``VDPS_JIT=0`` both sides are the Python source)."""
    model = Model(dataclasses.replace(load_vehicle("suv-model"), chassis=CHASSIS), EffectSet([LinearTire()]),
                  unsprung_dof=False)
    core = ReducedLinearCore(model)
    rng = random.Random(11)
    for k in range(100):
        x, u, env = random_case(model, rng, lift=k % 3 == 0)
        csd, tq, br = core.inputs(u)
        args = (np.array(x), csd, tq, br, np.array(env.normal_g), core.K, core.C)
        outs = [[np.empty(16), np.empty(4), np.empty(3), np.empty(4), np.empty(4), np.empty(4)] for _ in range(2)]
        reduced_rhs(*args, *outs[0])
        reduced_rhs.py_func(*args, *outs[1])
        for a, b in zip(*outs):
            assert np.array_equal(a, b)
        jd = [np.empty(4), np.empty(4)]
        wheel_spin_jacobian(np.array(x), br, outs[0][5], outs[0][4], core.K, core.C, jd[0])
        wheel_spin_jacobian.py_func(np.array(x), br, outs[0][5], outs[0][4], core.K, core.C, jd[1])
        assert np.array_equal(jd[0], jd[1])
