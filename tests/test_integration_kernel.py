"""The compiled prediction loop (prediction/integration_kernel.py) equals its Python source run by
CPython (``reduced_loop.py_func`` over the Python sources of the reduced core and the helpers)
bit for bit -- 0 ulp on every kept state, load, time, roll and roll rate, and the same step and
evaluation counts and stop reason: ROS2 with and without the wheel/body coupling, Heun, held
and per-step inputs, and each stop rule. (The loop's agreement with the generic loop over
``Model.f`` is tests/test_predictor.py's.)"""

import random

import numpy as np
import pytest

from vdps_hil.model.core import Inputs, Model
from vdps_hil.model.effects import EffectSet, LinearTire
from vdps_hil.model.params import load_vehicle
from vdps_hil.model.reduced import ReducedLinearCore
from vdps_hil.prediction import integration_kernel as ik
from vdps_hil.prediction.integration import ROS2_GAMMA

from core_cases import random_case

MODEL = Model(load_vehicle("suv-model"), EffectSet([LinearTire()]), unsprung_dof=False)
CORE = ReducedLinearCore(MODEL)
N_STEPS = 150


def _inputs(rng, per_step: bool):
    """Moderate steering, drive torques and brakes (held, or one set per step)."""
    us = [Inputs(rng.uniform(-1.0, 1.0), [rng.uniform(0.0, 150.0) for _ in range(4)],
                 [rng.uniform(0.0, 300.0) if rng.random() < 0.3 else 0.0 for _ in range(4)])
          for _ in range(N_STEPS + 1 if per_step else 1)]
    ucs = [CORE.inputs(u) for u in us]
    return [np.stack([uc[j] for uc in ucs]) for j in range(3)]


def _run(loop, x0, U, ng, ros2, coupling, stop_ponr, tip, roll_limit, out_every=3):
    h = 0.01 if ros2 else 0.001  # Heun is explicit: the wheel-spin mode needs the short step
    m = N_STEPS // out_every + 3
    out = [np.full((m, 16), -1.0), np.full((m, 4), -1.0), np.full(m, -1.0), np.full(m, -1.0), np.full(m, -1.0)]
    counts = loop(x0, *U, ng, CORE.K, CORE.C, h, N_STEPS, out_every, 2, ros2, coupling, stop_ponr, tip,
                  roll_limit, ROS2_GAMMA, *out)
    return counts, out


@pytest.mark.parametrize("case", ["ros2", "ros2-uncoupled", "heun", "ros2-driven", "ponr", "roll-limit",
                                  "non-finite"])
def test_compiled_loop_equals_its_python_source_bit_for_bit(case, monkeypatch):
    rng = random.Random(21)
    x, _, env = random_case(MODEL, rng, lift=case in ("ponr", "roll-limit"))
    x0 = np.array(x)
    if case == "non-finite":
        x0[12] = np.nan
    U = _inputs(rng, per_step=case == "ros2-driven")
    ng = np.array(env.normal_g)
    kw = dict(ros2=case != "heun", coupling=case != "ros2-uncoupled", stop_ponr=case == "ponr",
              tip=0.0 if case == "ponr" else 0.8, roll_limit=0.05 if case == "roll-limit" else 1.5)
    compiled = _run(ik.reduced_loop, x0, U, ng, **kw)
    for name in ("reduced_rhs", "wheel_spin_jacobian", "_coupling_geometry", "_w_factors", "_roll_v", "_keep"):
        fn = getattr(ik, name)
        monkeypatch.setattr(ik, name, getattr(fn, "py_func", fn))
    reference = _run(ik.reduced_loop.py_func, x0, U, ng, **kw)
    assert compiled[0] == reference[0]
    for a, b in zip(compiled[1], reference[1]):
        assert np.array_equal(a, b, equal_nan=True)
    n_out, n_fed, n, n_eval, stop = compiled[0]
    expected = {"ponr": 1, "roll-limit": 2, "non-finite": 3}.get(case, 0)
    assert ik.STOP_REASONS[stop] == ik.STOP_REASONS[expected]
    assert (n == N_STEPS) == (expected == 0) and n_out >= 1 and n_eval >= n
