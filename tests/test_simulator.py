"""Truth simulator: stepping and time, truth rate, input port, kinematic truth, integrator
convergence on `paper`."""

import math

import pytest

from vdps_hil.model.core import Inputs
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import load_vehicle
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import SimulationError, Simulator

SEDAN = load_vehicle("sedan-truth")


def test_step_to_keeps_integer_time_and_truth_at_100_hz():
    sim = Simulator(SEDAN, inputs=Inputs(), initial_speed_mps=10.0)
    assert sim.step_to(0.0995) == pytest.approx(0.099)
    assert sim.t_ns == 99_000_000
    sim.step_to(1.0)
    assert sim.t_ns == 1_000_000_000
    ts = [s["t_ns"] for s in sim.truth]
    assert ts == list(range(0, 1_000_000_001, 10_000_000))


def test_bad_step_is_rejected():
    with pytest.raises(SimulationError, match="dt_s"):
        Simulator(SEDAN, inputs=Inputs(), dt_s=2e-3)
    with pytest.raises(SimulationError, match="dt_s"):
        Simulator(SEDAN, inputs=Inputs(), dt_s=3e-4)  # does not divide 10 ms
    with pytest.raises(SimulationError, match="integrator"):
        Simulator(SEDAN, inputs=Inputs(), integrator="euler")


def test_input_override_acts_from_the_next_step_and_can_be_cleared():
    sim = Simulator(SEDAN, inputs=Inputs(0.0, (100.0,) * 4), initial_speed_mps=20.0)
    sim.step_to(0.5)
    sim.set_input_override(Inputs(0.0, (0.0,) * 4, (600.0,) * 4))  # an ECU brakes
    sim.step_to(1.5)
    s = sim.truth[-1]
    assert s["brake_torque_nm_1"] == 600.0 and s["accel_b_mps2_x"] < -3.0
    # a callable override sees the scheduled inputs
    seen = []
    sim.set_input_override(lambda t, sched: (seen.append(sched.wheel_torque_nm[0]), sched)[1])
    sim.step_to(1.6)
    assert seen and seen[0] == 100.0
    sim.set_input_override(None)
    sim.step_to(2.0)
    assert sim.truth[-1]["wheel_torque_nm_1"] == pytest.approx(100.0)


def test_kinematics_is_consistent_with_truth_and_finite_differences():
    """Specific force = a - g at the CG; angular acceleration = d omega/dt (central difference
    over +-0.1 ms with a 0.1 ms step, error O(dt^2): 1e-3 relative)."""
    sc = load_scenario("paper")
    sim = Simulator(scenario=sc, dt_s=1e-4)
    sim.step_to(0.6)
    w_prev = sim.x[9:12]
    sim.step()
    kin = sim.kinematics()
    snap = sim.snapshot()
    w_now = sim.x[9:12]
    sim.step()
    w_next = sim.x[9:12]
    for k, a in enumerate("xyz"):
        assert kin.specific_force_mps2[k] == pytest.approx(snap[f"specific_force_b_mps2_{a}"], abs=1e-12)
        assert kin.angular_rate_radps[k] == w_now[k]
        fd = (w_next[k] - w_prev[k]) / (2 * sim.dt_s)
        assert kin.angular_accel_radps2[k] == pytest.approx(fd, abs=2e-3 * (1 + abs(fd)))
    # at rest on a level road the accelerometer reads +g up
    rest = Simulator(SEDAN, inputs=Inputs(), effects=EffectSet())
    f = rest.kinematics().specific_force_mps2
    assert f[2] == pytest.approx(9.80665, rel=1e-9) and abs(f[0]) < 1e-9


def test_step_hook_runs_every_step():
    sim = Simulator(SEDAN, inputs=Inputs(), initial_speed_mps=5.0)
    calls = []
    sim.add_step_hook(lambda s: calls.append(s.t_ns))
    sim.step_to(0.01)
    assert calls == list(range(1_000_000, 10_000_001, 1_000_000))


@pytest.mark.slow
def test_integrator_convergence_on_paper():
    """Halving the step over 10 s of `paper`: max position difference < 0.1 % of the distance
    travelled and attitude difference < 0.01 deg (issue 3 acceptance)."""
    sc = load_scenario("paper")
    runs = []
    for dt in (1e-3, 5e-4):
        sim = Simulator(scenario=sc, dt_s=dt)
        sim.run(10.0)
        runs.append(sim.truth)
    a, b = runs
    assert len(a) == len(b) == 1001
    dist = sum(math.dist((p["pos_e_m"], p["pos_n_m"], p["pos_u_m"]), (q["pos_e_m"], q["pos_n_m"], q["pos_u_m"]))
               for p, q in zip(a, a[1:]))
    dpos = max(math.dist((p["pos_e_m"], p["pos_n_m"], p["pos_u_m"]), (q["pos_e_m"], q["pos_n_m"], q["pos_u_m"]))
               for p, q in zip(a, b))
    datt = max(abs(p[k] - q[k]) for p, q in zip(a, b) for k in ("roll_g_rad", "pitch_g_rad", "yaw_g_rad"))
    assert dist > 240.0
    assert dpos < 1e-3 * dist
    assert math.degrees(datt) < 0.01


def test_rk4_and_rk2_agree_on_paper():
    sc = load_scenario("paper")
    out = []
    for integ in ("rk2", "rk4"):
        sim = Simulator(scenario=sc, integrator=integ)
        sim.run(3.0)
        out.append(sim.truth[-1])
    a, b = out
    assert math.dist((a["pos_e_m"], a["pos_n_m"]), (b["pos_e_m"], b["pos_n_m"])) < 1e-4
    assert abs(a["roll_g_rad"] - b["roll_g_rad"]) < 1e-6


def test_reduced_model_runs_in_the_simulator_and_tracks_truth_model():
    """The paper's reduced model (no unsprung DOF, rigid tires) driven by the same inputs stays
    close to the truth model over 3 s of `paper` (same tires): position within 0.5 m, roll within
    0.5 deg (the truth's tire compliance adds about 20 % roll: each corner's rate falls from K_s
    to K_s k_t / (K_s + k_t))."""
    sc = load_scenario("paper")
    out = []
    for dof in (True, False):
        sim = Simulator(scenario=sc, unsprung_dof=dof)
        sim.run(3.0)
        out.append(sim.truth)
    for p, q in zip(*out):
        assert math.dist((p["pos_e_m"], p["pos_n_m"]), (q["pos_e_m"], q["pos_n_m"])) < 0.5
        assert abs(p["roll_v_rad"] - q["roll_v_rad"]) < math.radians(0.5)
