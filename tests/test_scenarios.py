"""Scenario files: loader (one-line errors) and the paper scenarios as the issue
specifies them (A_sw for a 4 m/s^2 peak, T0 holding the speed, the 10.25 s holds)."""

import math

import pytest

from vdps_hil.model.core import Inputs
from vdps_hil.sim.scenarios import load_scenario, parse_scenario, scenario_names
from vdps_hil.sim.signals import ScenarioError
from vdps_hil.sim.simulator import Simulator
from vdps_hil.units import GRAVITY_MPS2 as G

MINIMAL = """
name = "t"
duration_s = 2.0
[inputs]
steer_wheel_angle_rad = 0.1
"""


def test_every_shipped_scenario_loads():
    names = scenario_names()
    assert {"paper", "paper-left-turn", "paper-rollover"} <= set(names)
    for n in names:
        sc = load_scenario(n)
        assert sc.name == n and sc.duration_s > 0
        sc.effect_set()  # effects resolve against the vehicle file


@pytest.mark.parametrize("text,msg", [
    (MINIMAL + "bogus = 1\n", "unknown key 'bogus'"),
    (MINIMAL.replace("[inputs]", "[inputs]\nwheel_torque_nm_9 = 1.0"), "unknown key 'wheel_torque_nm_9'"),
    (MINIMAL + "[road]\nbank = 2\n", "unknown key 'bank'"),
    (MINIMAL.replace("duration_s = 2.0", "duration_s = -1.0"), "must be positive"),
    (MINIMAL.replace("= 0.1", "= { type = \"square\" }"), "unknown signal type"),
    (MINIMAL.replace("= 0.1", "= { type = [1, 2] }"), "unknown signal type"),  # was TypeError: unhashable
    (MINIMAL.replace("= 0.1", "= { type = \"sine\", amplitude = 1.0 }"), "missing key 'frequency_hz'"),
    (MINIMAL.replace("= 0.1", "= { type = \"sine\", amplitude = 1.0, frequency_hz = 1, freq = 2 }"), "unknown key 'freq'"),
    (MINIMAL.replace("[inputs]", "effects = [\"warp_drive\"]\n[inputs]"), "unknown effect 'warp_drive'"),
    ("name = \"t\"\nduration_s = 1.0\neffects = [\"aero_drag\"]\n[effect_params.aero_drag]\ncd = 1\n", "unknown parameter 'cd'"),
    (MINIMAL + "[[[", "malformed TOML"),
    (MINIMAL.replace("= 0.1", "= \"left\""), "must be a table or a number"),
])
def test_bad_scenarios_give_one_line_errors(text, msg):
    with pytest.raises(ScenarioError, match=msg) as e:
        parse_scenario(text, "t.toml")
    assert "\n" not in str(e.value)


def test_unknown_scenario_name_is_one_line():
    with pytest.raises(ScenarioError, match="unknown scenario 'nope'"):
        load_scenario("nope")


def test_paper_scenarios_as_specified():
    p, lt, ro = (load_scenario(n) for n in ("paper", "paper-left-turn", "paper-rollover"))
    for sc in (p, lt, ro):
        assert sc.initial_speed_mps == 25.0
        assert sc.bank_rad == pytest.approx(math.radians(2.0)) and sc.grade_rad == pytest.approx(math.radians(-2.0))
        assert sc.effect_names == ("magic_formula_tire",)
    a_sw = 0.6342
    for t in (0.1, 3.3, 7.77):
        u = p.scheduled_inputs(t)
        s = math.sin(2 * math.pi * t)
        assert u.steer_wheel_angle_rad == pytest.approx(a_sw * s)
        assert u.wheel_torque_nm == pytest.approx((-42.44 + 200.0 * s,) * 4)
    for t in (10.25, 12.0, 14.99):  # held at the peak: a left turn
        u = lt.scheduled_inputs(t)
        assert u.steer_wheel_angle_rad == pytest.approx(a_sw) and u.wheel_torque_nm == pytest.approx((157.56,) * 4)
        r = ro.scheduled_inputs(t)
        assert r.steer_wheel_angle_rad == pytest.approx(a_sw)
        assert r.wheel_torque_nm == pytest.approx((157.56, 1000.0, 1000.0, 157.56))
    assert lt.scheduled_inputs(10.0).steer_wheel_angle_rad == pytest.approx(0.0, abs=1e-9)
    assert ro.stop_at_point_of_no_return


def test_paper_t0_is_the_grade_force():
    """T0 = -m g sin(2 deg) r / 4 holds the speed on the straight: with steering off the speed
    changes by < 0.02 m/s over 3 s (only the T0 part; the sine part averages out per period)."""
    sc = load_scenario("paper")
    veh = sc.vehicle
    t0 = -veh.params.mass_kg * G * math.sin(math.radians(2.0)) * veh.tire.rolling_radius_m / 4
    assert t0 == pytest.approx(-42.44, abs=0.005)
    sim = Simulator(scenario=sc, inputs=Inputs(0.0, (-42.44,) * 4), record_truth=False)
    sim.step_to(3.0)
    assert abs(sim.x[6] - 25.0) < 0.02


@pytest.mark.slow
def test_paper_peak_lateral_acceleration_is_4_mps2():
    sim = Simulator(scenario=load_scenario("paper"))
    sim.run(10.25)
    peak = max(abs(s["accel_b_mps2_y"]) for s in sim.truth if s["t_s"] >= 1.0)
    assert peak == pytest.approx(4.0, abs=0.02)


def test_scenario_faults_are_validated_at_load():
    from vdps_hil.sim.scenarios import parse_scenario
    from vdps_hil.sim.signals import ScenarioError
    base = 'name = "x"\nduration_s = 1.0\n'
    sc = parse_scenario(base + 'faults = ["gnss_outage:t_s=0.2,duration_s=0.3"]\n')
    assert sc.raw["faults"] == ["gnss_outage:t_s=0.2,duration_s=0.3"]
    import pytest as _pytest
    with _pytest.raises(ScenarioError, match="faults"):
        parse_scenario(base + 'faults = ["no_such_fault"]\n')
    with _pytest.raises(ScenarioError, match="faults"):
        parse_scenario(base + 'faults = "gnss_outage"\n')
