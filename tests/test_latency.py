"""Tests of hil.latency: the latency of a cycle is measured from the send time of the exact frame
or byte that carried its input to its output on the bus; lost inputs are left out, not guessed;
lead times are taken to this run's truth events, or to the open-loop reference when the ECU
prevented the point of no return."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vdps_hil.codecs.can_encode import VdpsCanEncoder
from vdps_hil.hil.latency import CycleLog, cycle_latencies, latency_summary, lead_times, reference_events
from vdps_hil.hil.serial_device import SendLog
from vdps_hil.sim.drive import Drive

MS = 1_000_000


def test_latency_uses_the_send_time_of_the_item_that_carried_the_input():
    can_log, imu_log = SendLog(), SendLog()
    can_log.add(2, 1000 * MS)  # frames 0, 1
    can_log.add(2, 1001 * MS)  # frames 2, 3
    imu_log.add(47, 1000 * MS)  # bytes 0..46
    imu_log.add(94, 1002 * MS)  # bytes 47..140
    cyc = CycleLog()
    cyc.add(0, 1, 1000 * MS + 300_000)  # frame 1 -> 0.3 ms
    cyc.add(1, 140, 1002 * MS + 500_000)  # the chunk ending at byte 140 -> 0.5 ms
    cyc.add(0, 3, 1001 * MS + 200_000, n_frames=1, first_frame=0)  # sent warning frame 0
    cyc.add(0, 7, 1003 * MS)  # frame 7 was never sent (lost): no latency
    lat = cycle_latencies(cyc, {"can": can_log, "imu": imu_log}, frame_bus_mono_ns=[1001 * MS + 900_000])
    assert lat["t_in"].tolist() == [1000 * MS, 1002 * MS, 1001 * MS, -1]
    assert lat["latency_ns"].tolist() == [300_000, 500_000, 900_000]  # the frame: its time on the bus
    assert lat["frame_latency_ns"].tolist() == [900_000]
    s = latency_summary(lat)
    assert s["cycles"] == 4 and s["cycles_unmatched"] == 1
    assert s["warning_latency_ms"]["max"] == pytest.approx(0.9) and s["warning_frame_latency_ms"]["n"] == 1


def test_without_bus_times_the_pipelines_send_time_is_used():
    log = SendLog()
    log.add(1, 0)
    cyc = CycleLog()
    cyc.add(0, 0, 2 * MS, n_frames=1, first_frame=0)
    lat = cycle_latencies(cyc, {"can": log}, frame_bus_mono_ns=None)
    assert lat["latency_ns"].tolist() == [2 * MS]
    assert CycleLog.from_arrays(cyc.arrays()).arrays()["m_out"].tolist() == [2 * MS]


def _frames(times_levels):
    enc = VdpsCanEncoder()
    out = []
    for t, lv in times_levels:
        m = enc.warning(lv, 1.0 if lv >= 2 else None, -0.5, -0.95, 0)
        m.timestamp = t
        out.append(m)
    return out


EVENTS = [{"kind": "tip_up", "t_s": 2.21, "side": "right"},
          {"kind": "point_of_no_return", "t_s": 3.72, "side": "right"}]


def test_lead_times_to_this_runs_events():
    f = _frames([(1.0, 0), (1.02, 0), (1.04, 2), (1.06, 3)])
    lt = lead_times(f, EVENTS)
    assert lt["lead_reference"] == "this_run" and lt["first_warning_t_s"] == pytest.approx(1.04)
    assert lt["warning_lead_time_s"] == pytest.approx(3.72 - 1.04)
    assert lt["warning_lead_to_tipup_s"] == pytest.approx(2.21 - 1.04)
    assert lt["false_alarms"] == 0 and lt["warning_frames_accepted"] == 4


def test_with_the_rollover_prevented_the_lead_is_to_the_open_loop_reference():
    f = _frames([(1.0, 0), (1.02, 2)])
    lt = lead_times(f, [], reference=EVENTS)
    assert lt["lead_reference"] == "open_loop" and lt["warning_lead_time_s"] == pytest.approx(2.70)
    none = lead_times(_frames([(1.0, 0), (1.02, 1)]), EVENTS)
    assert math.isnan(none["first_warning_t_s"]) and math.isnan(none["warning_lead_time_s"])


def test_reference_events_are_the_drive_without_any_ecu():
    ev = reference_events(Drive("fishhook-suv"))
    kinds = {e["kind"]: e["t_s"] for e in ev}
    assert kinds["tip_up"] == pytest.approx(2.21, abs=0.02)
    assert kinds["point_of_no_return"] == pytest.approx(3.72, abs=0.02)
    assert np.isfinite(list(kinds.values())).all()
