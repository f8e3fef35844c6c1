"""The simulator's compiled steps (sim/step_kernel.py) equal the Python simulator (``Model.f``
on the stages, ``stepping.rk_step``, the recorder's step hook; ``jit.ENABLED`` off) bit for bit
-- 0 ulp on every truth snapshot, every recorder row and the final state: Heun and RK4, the
truth and the reduced model, open-loop schedules (several steps per compiled call), held inputs
with a step hook and an override (one step per call), effects with compiled forms. A compiled
run repeated gives the same bits."""

import numpy as np
import pytest

from vdps_hil import jit
from vdps_hil.model.core import Inputs
from vdps_hil.model.effects import EffectSet, LinearTire, make_effect
from vdps_hil.sim.sampling import StepRecorder
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import Simulator


def _scripted(sim: Simulator) -> None:
    """The bench's way of driving: a step hook, then an ECU override acting on the schedule."""
    hits = []
    sim.add_step_hook(lambda s: hits.append(s.n))
    sim.step_to(0.4)
    sim.set_input_override(lambda t, u: Inputs(u.steer_wheel_angle_rad, u.wheel_torque_nm, (300.0,) * 4))
    sim.step_to(0.8)
    assert hits == list(range(1, 801))


CASES = {
    "paper-rk2": (lambda: dict(scenario=load_scenario("paper")), lambda s: s.step_to(1.5)),
    "paper-rk4": (lambda: dict(scenario=load_scenario("paper"), integrator="rk4"), lambda s: s.step_to(1.0)),
    "paper-reduced": (lambda: dict(scenario=load_scenario("paper"), unsprung_dof=False), lambda s: s.step_to(1.0)),
    "fishhook-suv": (lambda: dict(scenario=load_scenario("fishhook-suv")), lambda s: s.step_to(2.5)),
    "held-effects-hook": (lambda: dict(vehicle="suv-truth", inputs=Inputs(0.8, (200.0,) * 4), initial_speed_mps=22.0,
                                       effects=EffectSet([LinearTire(), make_effect("aero_drag"),
                                                          make_effect("rolling_resistance"),
                                                          make_effect("load_dependent_cornering_stiffness")])),
                          _scripted),
}


def _run(case: str):
    kwargs, drive = CASES[case]
    sim = Simulator(**kwargs())
    rec = StepRecorder(sim)
    drive(sim)
    return sim, rec.take().a


@pytest.mark.parametrize("case", list(CASES))
def test_compiled_steps_equal_the_python_simulator_bit_for_bit(case, monkeypatch):
    sim, rows = _run(case)
    assert sim._compiled == jit.ENABLED
    again, rows_again = _run(case)
    assert again.truth == sim.truth and np.array_equal(rows_again, rows)  # repeatable
    monkeypatch.setattr(jit, "ENABLED", False)
    ref, ref_rows = _run(case)
    assert not ref._compiled and ref.model.f is ref.model.f_python
    assert sim.n == ref.n and sim.x == ref.x
    assert len(sim.truth) == len(ref.truth) and len(rows) == len(ref_rows) == sim.n + 1
    for a, b in zip(sim.truth, ref.truth):
        assert a == b, a["t_s"]
    assert np.array_equal(rows, ref_rows)
