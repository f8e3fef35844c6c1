"""Tests of ``vdps_hil.sim.stepping``: the Runge-Kutta step against the exact solution of a
linear ODE (its order), the clock's checks and integer time, step_to / run / hooks on a minimal
subclass, and the snapshot load transfer ratio."""

from __future__ import annotations

import math

import pytest

from vdps_hil.sim.stepping import FixedStepTruth, SimulationError, rk_step, snapshot_ltr


def test_rk_steps_have_their_order_on_x_dot_equals_minus_x():
    f = lambda x: [-x[0]]  # noqa: E731
    for integ, order in (("rk2", 2), ("rk4", 4)):
        errs = []
        for h in (0.1, 0.05):
            x = [1.0]
            for _ in range(round(1.0 / h)):
                x = rk_step(f, x, f(x), h, integ)
            errs.append(abs(x[0] - math.exp(-1.0)))
        assert math.log2(errs[0] / errs[1]) == pytest.approx(order, abs=0.15)


class Counter(FixedStepTruth):
    def __init__(self, **kw):
        self._init_clock(kw.get("dt_s", 1e-3), 100.0, kw.get("integrator", "rk2"))
        self.n, self.stopped, self.duration_s = 0, False, 0.05
        self._step_hooks, self.record_truth, self.truth, self._on_truth = [], True, [], None
        self._init_inputs(None, None, None, None)

    def _emit_truth(self):
        self._deliver_truth({"t_ns": self.t_ns})

    def step(self):
        self.n += 1
        return self._after_step()


def test_clock_hooks_and_run():
    c = Counter()
    seen = []
    c.add_step_hook(lambda sim: seen.append(sim.n))
    assert c.run() is c.truth and c.n == 50 and seen == list(range(1, 51))
    assert [s["t_ns"] for s in c.truth] == [10_000_000 * k for k in range(1, 6)]
    d = Counter()
    assert d.step_to(0.0305) == pytest.approx(0.030) and d.t_ns == 30_000_000  # last step time <= t
    assert c._source(0.0, []).wheel_torque_nm == (0.0,) * 4
    for bad in ({"dt_s": 2e-3}, {"dt_s": 3e-4}, {"integrator": "euler"}):
        with pytest.raises(SimulationError):
            Counter(**bad)


def test_snapshot_ltr():
    s = {"normal_load_n_1": 1000.0, "normal_load_n_2": 3000.0, "normal_load_n_3": 2000.0, "normal_load_n_4": 0.0}
    assert snapshot_ltr(s) == pytest.approx((5000.0 - 1000.0) / 6000.0)
    assert snapshot_ltr({f"normal_load_n_{i}": 0.0 for i in range(1, 5)}) == 0.0
