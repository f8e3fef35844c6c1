"""The compiled physics core (model/core_kernel.py) equals the stages (``Model.f_python``, the
reference) bit for bit -- 0 ulp, stricter than the 1e-12 relative the compiled forms are allowed:
the kernel mirrors the stages operation for operation and calls the same inline force laws, so
compiled (LLVM, no fast-math) and CPython execute the same IEEE operations with the same libm.
Checked for the truth model (unsprung DOF) and the reduced model, with each built-in dynamics
effect alone and all together, and with the chassis parts (``model.chassis``: anti-roll bars,
roll centres, Ackermann fraction) each alone and all together, on x_dot and on every diagnostic
of ``Model.evaluate``; models whose effects have no compiled form run on the stages, and say
so."""

import dataclasses
import random

import numpy as np
import pytest

from vdps_hil import jit
from vdps_hil.model import core_kernel
from vdps_hil.model.chassis import PAPER_CHASSIS, Chassis
from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.effects import EffectSet, LinearTire, make_effect
from vdps_hil.model.effects.aero import AeroDrag
from vdps_hil.model.params import load_vehicle

from core_cases import random_case

EFFECTS = ("magic_formula_tire", "aero_drag", "rolling_resistance", "load_dependent_cornering_stiffness",
           "low_pressure_tire", "crosswind", "steering_compliance")
SUV = load_vehicle("suv-truth")
BARS = dict(anti_roll_stiffness_front_nmprad=25000.0, anti_roll_stiffness_rear_nmprad=9000.0)
CENTRES = dict(roll_centre_height_front_m=0.06, roll_centre_height_rear_m=0.14)
CHASSIS = {"anti_roll_bars": Chassis(**BARS), "roll_centres": Chassis(**CENTRES),
           "parallel_steer": Chassis(ackermann_fraction=0.0), "half_ackermann": Chassis(ackermann_fraction=0.5),
           "all_chassis": Chassis(**BARS, **CENTRES, ackermann_fraction=0.5)}
CASES = ([((), PAPER_CHASSIS)] + [((e,), PAPER_CHASSIS) for e in EFFECTS] + [(EFFECTS, PAPER_CHASSIS)]
         + [(extra, ch) for ch in CHASSIS.values() for extra in ((), EFFECTS)]
         + [(("roll_stiffness",), CHASSIS["all_chassis"]), (EFFECTS, "cr1-model")])
CASE_IDS = (["linear_tire"] + list(EFFECTS) + ["all"] + [f"{name}-{e}" for name in CHASSIS for e in ("linear", "all")]
            + ["all_chassis-roll_stiffness", "cr1-model-all"])


def _model(extra, dof: bool, chassis=PAPER_CHASSIS) -> Model:
    """``chassis``: a ``Chassis`` for the SUV, or the name of a vehicle file (its own chassis)."""
    veh = load_vehicle(chassis) if isinstance(chassis, str) else dataclasses.replace(SUV, chassis=chassis)
    tire = [] if "magic_formula_tire" in extra else [LinearTire()]
    return Model(veh, EffectSet(tire + [make_effect(e) for e in extra]), unsprung_dof=dof)


@pytest.mark.parametrize("dof", [True, False], ids=["truth", "reduced"])
@pytest.mark.parametrize("extra, chassis", CASES, ids=CASE_IDS)
def test_compiled_core_equals_the_stages_bit_for_bit(extra, chassis, dof):
    model = _model(extra, dof, chassis)
    assert model.compiled_status == ("compiled" if jit.ENABLED else "python (VDPS_JIT=0)")
    rng = random.Random(3)
    n_lifted = 0
    for k in range(120):
        x, u, env = random_case(model, rng, lift=k % 3 == 0, wind=True)
        assert model.f(x, u, env) == model.f_python(x, u, env)
        out, ref = {}, {}
        xd = model.f(x, u, env, out)
        assert xd == model.f_python(x, u, env, ref)
        assert out["_rec"] == [tuple(r) for r in ref["_rec"]]
        for key in ("_acc_b", "_g_b", "_force_b", "_moment_b", "_normal_b", "_height_cg", "_air_b"):
            assert out[key] == (ref[key] if key == "_height_cg" else tuple(ref[key])), key
        n_lifted += any(r[2] == 0.0 for r in out["_rec"])
    assert n_lifted >= 5  # the lift-off branches were exercised


@pytest.mark.parametrize("chassis", [PAPER_CHASSIS, CHASSIS["all_chassis"]], ids=["paper", "all_chassis"])
def test_the_kernel_equals_its_python_source_and_evaluate_from_equals_evaluate(chassis):
    """``core_rhs`` as compiled equals ``core_rhs.py_func`` (the kernel's source run by CPython)
    bit for bit, and the named diagnostics rebuilt from its array (``Model.evaluate_from``, what
    the simulator's snapshots use) equal ``Model.evaluate``."""
    model = _model(EFFECTS, True, chassis)
    K, C, E = model.kernel_arrays
    rng = random.Random(5)
    for k in range(20):
        x, u, env = random_case(model, rng, lift=k % 2 == 0, wind=True)
        args = (np.array(x), np.array((u.steer_wheel_angle_rad, *u.wheel_torque_nm, *u.brake_torque_nm)),
                np.array((*env.normal_g, *env.wind_enu_mps)), K, C, E)
        outs = [(np.empty(24), np.empty(core_kernel.N_DIAG)) for _ in range(2)]
        core_kernel.core_rhs(*args, np.empty((4, 15)), *outs[0])
        core_kernel.core_rhs.py_func(*args, np.empty((4, 15)), *outs[1])
        assert np.array_equal(outs[0][0], outs[1][0]) and np.array_equal(outs[0][1], outs[1][1])
        xd, named = model.evaluate(x, u, env)
        assert model.evaluate_from(x, outs[0][0].tolist(), outs[0][1], env) == (xd, named)


def test_a_model_without_compiled_forms_runs_on_the_stages_and_says_why(monkeypatch):
    class GustyDrag(AeroDrag):  # a user's subclass overriding the compiled hook: its own formula
        def body_wrench(self, vel_b, omega_b, air_b):
            fx = super().body_wrench(vel_b, omega_b, air_b)[0]
            return (2.0 * fx, 0.0, 0.0, 0.0, 0.0, 0.0)

    model = Model(SUV, EffectSet([LinearTire(), GustyDrag()]), unsprung_dof=True)
    assert model.kernel_arrays is None and "has no compiled form" in model.compiled_status
    assert model.f is model.f_python
    x = model.design_state(20.0, Env())
    plain = Model(SUV, EffectSet([LinearTire(), AeroDrag()]), unsprung_dof=True)
    # its drag is twice the built-in one: the override acts, not the inherited compiled form
    assert model.f(x, Inputs(), Env())[6] < plain.f(x, Inputs(), Env())[6] < 0.0
    monkeypatch.setattr(jit, "ENABLED", False)
    off = _model(EFFECTS, True)
    assert off.compiled_status == "python (VDPS_JIT=0)" and off.f is off.f_python
