"""Driver model: path geometry, pure-pursuit tracking on the ISO 3888 lane change and the
ISO 4138 circle, PI speed control."""

import math

import pytest

from vdps_hil.model.core import Inputs
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.driver import Driver, ReferencePath, make_path, path_local_points
from vdps_hil.sim.scenarios import load_scenario, parse_scenario
from vdps_hil.sim.signals import ScenarioError
from vdps_hil.sim.simulator import Simulator

SEDAN = load_vehicle("sedan-truth")


def test_iso3888_path_geometry():
    pts = path_local_points({"type": "iso3888", "entry_m": 50.0, "offset_m": 3.5})
    y_at = lambda x: min(pts, key=lambda p: abs(p[0] - x))[1]  # noqa: E731
    assert y_at(60.0) == pytest.approx(0.0, abs=1e-9)  # section 1
    assert y_at(107.5) == pytest.approx(3.5, abs=1e-9)  # section 3 (25 m at the offset)
    assert y_at(80.0) == pytest.approx(1.75, abs=0.05)  # middle of the transition
    assert y_at(170.0) == pytest.approx(0.0, abs=1e-9)  # back on the line


def test_circle_path_and_nearest_point():
    p = make_path({"type": "circle", "radius_m": 40.0, "entry_m": 10.0}, 100.0, 50.0, math.pi / 2)
    # heading north, centre to the left (west) at (60, 60)
    for k in range(0, len(p.x), 97):
        if p.s[k] > 20.0:
            assert math.hypot(p.x[k] - 60.0, p.y[k] - 60.0) == pytest.approx(40.0, abs=1e-9)
    s = p.nearest(100.0, 55.0)
    assert s == pytest.approx(10.0, abs=0.01)


def test_path_straight_extension():
    p = ReferencePath([(0.0, 0.0), (10.0, 0.0)])
    assert p.point_at(15.0) == (15.0, 0.0) and p.point_at(-3.0) == (0.0, 0.0)


def test_lane_change_is_followed_closely():
    """ISO 3888 at 80 km/h: the CG stays within 0.45 m (lateral) of the centre line (pure pursuit
    cuts the transitions a little), reaches the 3.5 m offset, peak lateral acceleration 4-7 m/s^2,
    speed within 0.3 m/s, and the car ends back on its lane."""
    import numpy as np
    sc = load_scenario("lane-change-iso3888")
    sim = Simulator(scenario=sc)
    sim.run()
    pts = path_local_points(sc.driver_spec["path"])
    px, py = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    errs = [abs(s["pos_n_m"] - float(np.interp(s["pos_e_m"], px, py))) for s in sim.truth]
    assert max(errs) < 0.45
    assert 4.0 < max(abs(s["accel_b_mps2_y"]) for s in sim.truth) < 7.0
    assert max(s["pos_n_m"] for s in sim.truth) == pytest.approx(3.5, abs=0.3)
    assert abs(sim.truth[-1]["pos_n_m"]) < 0.2
    assert all(abs(s["speed_mps"] - 22.222) < 0.3 for s in sim.truth)


@pytest.mark.slow
def test_circle_radius_and_speed_ramp_are_held():
    sc = load_scenario("circle-iso4138")
    sim = Simulator(scenario=sc)
    sim.run()
    for s in sim.truth[500::100]:
        r = math.hypot(s["pos_e_m"] - 10.0, s["pos_n_m"] - 40.0)
        assert r == pytest.approx(40.0, abs=0.5)
        target = 5.0 + 12.0 * (s["t_s"] - 2.0) / 60.0
        assert s["speed_mps"] == pytest.approx(target, abs=0.3)
    assert max(abs(s["accel_b_mps2_y"]) for s in sim.truth) > 6.5


def test_pi_speed_control_reaches_a_new_target_and_brakes():
    sim = Simulator(SEDAN, inputs=Inputs(), initial_speed_mps=20.0, record_truth=False)
    drv = Driver(sim.model, sim.env, None, lambda t: 25.0 if t < 10.0 else 15.0)
    sim._source = drv
    sim.step_to(9.9)
    assert sim.x[6] == pytest.approx(25.0, abs=0.1)
    u = sim.current_inputs()
    assert all(t >= 0 for t in u.wheel_torque_nm)
    sim.step_to(10.5)
    assert any(b > 0 for b in sim.current_inputs().brake_torque_nm)
    sim.step_to(20.0)
    assert sim.x[6] == pytest.approx(15.0, abs=0.1)


def test_driver_spec_errors_are_one_line():
    base = "name = \"t\"\nduration_s = 1.0\n[driver]\n"
    for text, msg in ((base + "gain = 1\n", "unknown key 'gain'"),
                      (base + "path = { type = \"spiral\" }\n", "path.type"),
                      (base + "path = { type = [1, 2] }\n", "path.type"),  # was TypeError: unhashable
                      (base + "drive = \"4wd\"\n", "drive must be"),
                      (base + "path = { type = \"circle\" }\n", "radius_m")):
        with pytest.raises(ScenarioError, match=msg):
            parse_scenario(text, "t.toml")
