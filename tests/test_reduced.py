"""The specialised reduced core (model/reduced.py) is the same equations as the generic core:
equal to Model.f on random states, inputs and roads (relative 1e-9; measured ~1e-12), its
diagnostics equal the core's, and its closed-form wheel-spin Jacobian equals a forward
difference of Model.f."""

import math
import random

import pytest

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet, LinearTire, make_effect
from vdps_hil.model.params import load_vehicle
from vdps_hil.model.reduced import ReducedLinearCore, supports


def _random_case(model: Model, rng: random.Random, lift: bool):
    """A state near trim at 5-30 m/s with perturbed attitude, rates, slips (and a large roll when
    ``lift``, so wheels leave the ground), random steering, drive torques and brakes, and a road."""
    env = Env(rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08))
    x = model.design_state(rng.uniform(5.0, 30.0), env, heading_rad=rng.uniform(-3.0, 3.0))
    x[3] += rng.gauss(0.0, 0.3 if lift else 0.02)
    x[4] += rng.gauss(0.0, 0.02)
    for j in (0, 1, 2):
        x[j] += rng.gauss(0.0, 0.02)  # heave: loads from compressed to unloaded
    for j in (7, 8, 9, 10, 11):
        x[j] += rng.gauss(0.0, 0.5)
    for j in range(12, 16):
        x[j] *= 1.0 + rng.gauss(0.0, 0.05)
    brakes = [rng.uniform(0.0, 800.0) if rng.random() < 0.5 else 0.0 for _ in range(4)]
    u = Inputs(rng.uniform(-3.0, 3.0), [rng.gauss(0.0, 400.0) for _ in range(4)], brakes)
    return x, u, env


@pytest.mark.parametrize("name", ["sedan-model", "suv-model"])
@pytest.mark.parametrize("extra", [(), ("low_pressure_tire",)])
def test_equals_the_generic_core(name, extra):
    model = Model(load_vehicle(name), EffectSet([LinearTire(), *(make_effect(e) for e in extra)]),
                  unsprung_dof=False)
    core = ReducedLinearCore(model)
    rng = random.Random(6)
    n_lifted = 0
    for k in range(300):
        x, u, env = _random_case(model, rng, lift=k % 3 == 0)
        out = {}
        ref = model.f(x, u, env, out)
        xd, fz, nb, kap, den = core.f(x, core.inputs(u), env)
        scale = [max(1.0, abs(v)) for v in ref]
        assert max(abs(a - b) / s for a, b, s in zip(xd, ref, scale)) < 1e-9
        assert max(abs(a - b) for a, b in zip(nb, out["_normal_b"])) < 1e-12
        for i in range(4):
            assert fz[i] == pytest.approx(out["_rec"][i][2], rel=1e-9, abs=1e-6)
            assert kap[i] == pytest.approx(out["_rec"][i][3], rel=1e-9, abs=1e-12)
        n_lifted += any(f == 0.0 for f in fz)
    assert n_lifted >= 10  # the lift-off branch was exercised


def test_wheel_spin_jacobian_equals_a_forward_difference_of_the_core():
    model = Model(load_vehicle("sedan-model"), EffectSet([LinearTire()]), unsprung_dof=False)
    core = ReducedLinearCore(model)
    rng = random.Random(7)
    for _ in range(100):
        x, u, env = _random_case(model, rng, lift=False)
        x[12] = rng.choice([x[12], 0.7, -1.9, 3.0])  # also inside the brake's hold band
        f0 = model.f(x, u, env)
        _, fz, _, _, den = core.f(x, core.inputs(u), env)
        jd = core.wheel_spin_jacobian(x, core.inputs(u), fz, den)
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
    xd, fz, _, kap, _ = core.f(x, core.inputs(Inputs()), Env())
    assert all(abs(k) < 1e-12 for k in kap) and all(abs(v) < 1e-9 for v in xd[12:16])
    assert abs(xd[6]) < 1e-9 and abs(xd[11]) < 1e-9
    assert fz[0] == pytest.approx(fz[1], rel=1e-12) and fz[3] == pytest.approx(fz[2], rel=1e-12)
    assert min(fz) > 0.0
    assert math.isclose(xd[0], 20.0, rel_tol=1e-12)
