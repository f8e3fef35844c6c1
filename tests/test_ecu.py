"""Tests of hil.ecu: the simulated ECU trusts a VDPS_Warning only with a good CRC, a counter that
advances and status 0; it detects the warning stopping (timeout); with --react it cuts the drive
torque and ramps the brakes with the stated dead time and pressure rise; on the rollover scenario
that reaction, started by a warning 1.7 s before the point of no return, keeps the SUV upright."""

from __future__ import annotations

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.codecs.can_e2e import crc8_j1850
from vdps_hil.codecs.can_encode import VdpsCanEncoder
from vdps_hil.hil.ecu import ActuatorConfig, Ecu, WarningMonitor
from vdps_hil.model.core import Inputs
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import Simulator

S = 1_000_000_000
DRIVER = Inputs(0.3, (100.0, 100.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))


def frames(levels, status=0):
    enc = VdpsCanEncoder()
    return [enc.warning(lv, 1.0 if lv >= 2 else None, 0.5, 0.9, status) for lv in levels]


def corrupt(msg: can.Message, byte: int, bit: int) -> can.Message:
    data = bytearray(msg.data)
    data[byte] ^= 1 << bit
    return can.Message(arbitration_id=msg.arbitration_id, data=bytes(data), is_extended_id=False)


def test_actuator_config_states_the_dynamics_and_refuses_a_dead_time_below_100_ms():
    c = ActuatorConfig()
    assert c.delay_s == 0.1 and c.rise_time_s == 0.3 and c.brake_torque_full_nm == 2500.0
    assert c.brake_rate_nmps == pytest.approx(2500.0 / 0.3)
    with pytest.raises(ValueError, match="dead time"):
        ActuatorConfig(delay_s=0.05)
    with pytest.raises(ValueError):
        ActuatorConfig(rise_time_s=0.0)
    with pytest.raises(ValueError):
        ActuatorConfig(trigger_level=0)


def test_monitor_checks_crc_counter_and_status():
    m = WarningMonitor()
    f = frames([0, 0, 2, 2, 2])
    assert m.feed(0, f[0]) is not None
    assert m.feed(20_000_000, corrupt(f[1], 3, 5)) is None  # one flipped bit: CRC
    assert m.feed(40_000_000, f[1]) is not None
    assert m.feed(60_000_000, f[1]) is None  # the same frame again: counter repeat
    got = m.feed(80_000_000, f[2])
    assert got["warning_level"] == 2 and got["t_ns"] == 80_000_000
    bad_status = frames([2], status=1)[0]
    m2 = WarningMonitor()
    assert m2.feed(0, bad_status) is None and m2.not_valid == 1
    c = m.counters()
    assert c["crc_mismatch"] == 1 and c["counter_repeat"] == 1 and c["accepted"] == 3


def test_monitor_times_out_once_when_the_warning_stops_and_recovers():
    m = WarningMonitor(timeout_s=0.1)
    f = frames([0, 0])
    assert not m.check(5 * S)  # nothing received yet: no link to lose
    m.feed(1 * S, f[0])
    assert not m.check(1 * S + 90_000_000)
    assert m.check(1 * S + 110_000_000) and m.timed_out and m.last is None
    assert not m.check(1 * S + 500_000_000) and m.timeouts == 1  # counted once
    m.feed(2 * S, f[1])
    assert not m.timed_out and m.last is not None


def test_reaction_cuts_drive_torque_and_ramps_the_brakes_after_the_dead_time():
    ecu = Ecu(ActuatorConfig(), react=True)
    f = frames([1, 2, 3])
    ecu.on_frame(int(0.9 * S), f[0])  # caution: no action
    assert not ecu.triggered and ecu.override(0.95, DRIVER) is DRIVER
    ecu.on_frame(1 * S, f[1])
    assert ecu.triggered and ecu.actuation_start_ns == int(1.1 * S)
    assert ecu.override(1.05, DRIVER) is DRIVER  # inside the dead time: the driver's inputs
    u = ecu.override(1.25, DRIVER)  # half way up the 300 ms ramp
    assert u.wheel_torque_nm == (0.0, 0.0, 0.0, 0.0) and u.steer_wheel_angle_rad == 0.3
    assert u.brake_torque_nm == pytest.approx((1250.0,) * 4)
    assert ecu.override(1.4, DRIVER).brake_torque_nm == pytest.approx((2500.0,) * 4)
    assert ecu.override(9.0, DRIVER).brake_torque_nm == pytest.approx((2500.0,) * 4)
    hard = Inputs(0.0, (0.0,) * 4, (3000.0, 0.0, 0.0, 0.0))
    assert ecu.override(1.4, hard).brake_torque_nm == pytest.approx((3000.0, 2500.0, 2500.0, 2500.0))
    ecu.on_frame(int(1.02 * S), f[2])  # a later, higher level does not restart anything
    assert ecu.actuation_start_ns == int(1.1 * S)
    s = ecu.summary()
    assert s["intervention_t_s"] == 1.0 and s["actuation_t_s"] == pytest.approx(1.1)
    assert s["full_brake_t_s"] == pytest.approx(1.4) and s["max_level"] == 3


def test_without_react_the_ecu_only_listens():
    ecu = Ecu(react=False)
    for k, f in enumerate(frames([2, 3])):
        ecu.on_frame(k * 20_000_000, f)
    assert ecu.first_warning_ns == 0 and not ecu.triggered
    assert ecu.override(5.0, DRIVER) is DRIVER


def test_a_corrupted_or_not_valid_warning_never_triggers_the_brakes():
    enc = VdpsCanEncoder()
    first = enc.warning(3, 0.4, 0.5, 0.9, 0)
    ecu = Ecu(react=True)
    ecu.on_frame(0, corrupt(first, 0, 0))  # the CRC byte damaged
    ecu.on_frame(20_000_000, enc.warning(3, 0.4, 0.5, 0.9, 2))  # status 2: sensor missing
    assert not ecu.triggered and ecu.monitor.counters()["crc_mismatch"] == 1
    ecu.on_frame(40_000_000, enc.warning(3, 0.4, 0.5, 0.9, 0))  # intact and valid: acts
    assert ecu.triggered


def test_an_actuation_the_simulator_has_passed_starts_at_its_next_step():
    class FakeSim:
        t_ns = int(1.5 * S)

        def set_input_override(self, fn):
            self.fn = fn

    ecu = Ecu(react=True)
    sim = FakeSim()
    ecu.attach(sim)
    assert sim.fn == ecu.override
    ecu.on_frame(1 * S, frames([2])[0])
    assert ecu.late_actuations == 1 and ecu.actuation_start_ns == int(1.5 * S)


@pytest.mark.parametrize("warn_at_s", [None, 2.0])
def test_reaction_on_the_rollover_scenario_keeps_the_suv_upright(warn_at_s):
    """fishhook-suv reaches its point of no return at 3.72 s; a warning at 2.0 s (1.7 s ahead)
    with the stated dynamics (braking from 2.1 s, full at 2.4 s) prevents it."""
    sc = load_scenario("fishhook-suv")
    sim = Simulator(scenario=sc, record_truth=False)
    ecu = Ecu(react=True)
    ecu.attach(sim)
    if warn_at_s is not None:
        sim.step_to(warn_at_s)
        ecu.on_frame(sim.t_ns, frames([2])[0])
    sim.run(sc.duration_s)
    kinds = [e["kind"] for e in sim.events]
    if warn_at_s is None:
        assert "point_of_no_return" in kinds and sim.t_s == pytest.approx(3.72, abs=0.02)
    else:
        assert "point_of_no_return" not in kinds and sim.t_s == pytest.approx(sc.duration_s)
        assert sim.snapshot()["speed_mps"] < 1.0  # braked to a stop


@settings(max_examples=300, deadline=None)
@given(data=st.binary(min_size=0, max_size=8), aid=st.sampled_from([0x080, 0x081, 0x100]))
def test_any_frame_is_handled_without_error_and_accepted_only_with_a_valid_crc(data, aid):
    ecu = Ecu(react=True)
    msg = can.Message(arbitration_id=aid, data=data, dlc=len(data), is_extended_id=False)
    ecu.on_frame(0, msg)
    if ecu.monitor.last is not None:
        assert aid == 0x080 and len(data) == 8 and crc8_j1850(data[1:]) == data[0]
