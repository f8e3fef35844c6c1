"""Rollover definitions (tip-up, point of no return, outcome) and the chosen rollover scenario's
timings."""

import math

import pytest

from vdps_hil.model.params import load_vehicle
from vdps_hil.model.rollover import (RolloverMonitor, assess, classify_outcome, static_tip_angle_rad,
                                     with_static_stability_factor)
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import Simulator

STATIC = (4000.0, 4000.0, 3500.0, 3500.0)


def test_static_tip_angle():
    assert static_tip_angle_rad(0.79, 0.55) == pytest.approx(math.atan(0.79 / 0.55))
    assert static_tip_angle_rad(0.745, 0.745) == pytest.approx(math.pi / 4)


def test_tip_up_needs_both_inside_tires_below_1_percent_for_0_2_s():
    m = RolloverMonitor(STATIC, 0.79, 0.55)
    t = 0.0
    # one left tire light only: nothing
    for _ in range(50):
        assert m.update(t, (10.0, 7000, 6000, 3000.0), 0.1, 0.0) == []
        t += 0.01
    # both left tires below 1 % of static (40 N and 35 N) for 0.19 s: nothing yet
    start = t
    for _ in range(20):
        assert m.update(t, (39.0, 7000, 6000, 34.0), 0.2, 0.0) == []
        t += 0.01
    ev = m.update(t, (39.0, 7000, 6000, 34.0), 0.2, 0.0)
    assert len(ev) == 1 and ev[0].kind == "tip_up" and ev[0].side == "left"
    assert ev[0].t_s == pytest.approx(start) and ev[0].detail["confirmed_t_s"] == pytest.approx(start + 0.2)
    # an interruption restarts the clock (checked on a fresh monitor)
    m2 = RolloverMonitor(STATIC, 0.79, 0.55)
    for k in range(30):
        fl = 500.0 if k == 15 else 0.0
        assert m2.update(k * 0.01, (fl, 7000, 6000, 0.0), 0.2, 0.0) == []


def test_point_of_no_return_needs_roll_beyond_tip_angle_and_still_increasing():
    m = RolloverMonitor(STATIC, 0.79, 0.55)
    tip = m.tip_angle_rad
    assert m.update(0.0, STATIC, tip + 0.01, -0.1) == []  # beyond, but coming back
    assert m.update(0.01, STATIC, tip - 0.01, 0.5) == []  # rising, not beyond yet
    ev = m.update(0.02, STATIC, -(tip + 0.01), -0.5)
    assert ev and ev[0].kind == "point_of_no_return" and ev[0].side == "right"


def test_outcome_classes():
    assert classify_outcome(True, 0.5) == "tip-up"
    assert classify_outcome(False, math.radians(25)) == "spin-out"
    assert classify_outcome(False, math.radians(5)) == "stable"


def test_ssf_axis_changes_only_the_cg_height():
    v = load_vehicle("sedan-truth")
    w = with_static_stability_factor(v, 1.2)
    assert w.geometry.static_stability_factor == pytest.approx(1.2)
    assert w.params == v.params and w.front == v.front and w.geometry.l_f_m == v.geometry.l_f_m


def test_rollover_scenario_timings():
    """fishhook-suv (the rollover scenario): tip-up and point of no return happen, the simulator
    stops at the PONR, and >= 1.5 s pass between the first causal input (steering at 1.0 s) and
    the PONR."""
    sc = load_scenario("fishhook-suv")
    first_input = min(t for t in (k * 0.001 for k in range(3000)) if sc.scheduled_inputs(t).steer_wheel_angle_rad != 0.0)
    assert first_input == pytest.approx(1.0, abs=0.002)
    sim = Simulator(scenario=sc)
    sim.run()
    a = assess(sim)
    assert a.outcome == "tip-up"
    assert sim.stopped and sim.stop_reason == "point_of_no_return"
    assert sim.t_s == pytest.approx(a.point_of_no_return_t_s)
    assert first_input < a.tip_up_t_s < a.point_of_no_return_t_s
    assert a.point_of_no_return_t_s - first_input >= 1.5
    assert abs(sim.truth[-1]["roll_v_rad"]) > math.pi / 4  # SSF 1.00: tip angle 45 deg
    kinds = [e["kind"] for s in sim.truth for e in s["events"]]
    assert kinds == ["tip_up", "point_of_no_return"]


def test_paper_rollover_input_does_not_roll_the_sedan():
    """The paper's rollover input (T2 = T3 = 1000 N m in a held left turn) spins the realistic
    sedan out instead of tipping it up (hence the SUV fishhook as the rollover scenario)."""
    sim = Simulator(scenario=load_scenario("paper-rollover"))
    sim.run()
    a = assess(sim, t_from_s=10.25)
    assert a.outcome == "spin-out" and math.isnan(a.tip_up_t_s)
    assert a.max_abs_roll_rel_road_rad < math.radians(10)
