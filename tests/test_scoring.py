"""Scoring against the truth (vdps_hil.experiments.scoring): the truth between 100 Hz snapshots,
and the sent warning frames against the truth events (lead time, episodes, false alarms, CRC)."""

from __future__ import annotations

import math

import pytest

from vdps_hil.experiments.scoring import evaluate_warning_frames, truth_at
from vdps_hil.prediction.warning import RolloverAssessment, WarningNode, WarningNodeConfig, WarningPolicy

MS = 1_000_000


def assessment(t0_ns=0, ttr=None, peak_ltr=0.0, roll=0.0):
    return RolloverAssessment(t0_ns, ttr, None, peak_ltr, 0.0, roll, 5.0, "horizon")


def test_truth_between_snapshots_is_interpolated_with_wrapped_angles():
    a = {"t_s": 1.0, "yaw_v_rad": math.pi - 0.1, "pos_e_m": 10.0}
    b = {"t_s": 1.01, "yaw_v_rad": -math.pi + 0.1, "pos_e_m": 10.25}
    by_t = {1_000_000_000: a, 1_010_000_000: b}
    m = truth_at(by_t, 1_002_500_000)
    assert m["pos_e_m"] == pytest.approx(10.0625) and m["t_s"] == pytest.approx(1.0025)
    assert m["yaw_v_rad"] == pytest.approx(math.pi - 0.05)  # through +-pi, not through 0
    assert truth_at(by_t, 1_000_000_000) is a and truth_at(by_t, 1_012_000_000) is None


def test_evaluate_counts_corrupted_frames_and_episodes():
    node = WarningNode(WarningPolicy(hold_s=0.0), WarningNodeConfig(period_s=0.02))
    frames = []
    for t in range(0, 3000 * MS, 10 * MS):
        a = None
        if t == 0:
            a = assessment(0)
        elif t == 1000 * MS:
            a = assessment(t, ttr=1.0, roll=-0.9)
        elif t == 1500 * MS:
            a = assessment(t)
        frames += node.handle(t, a)
    bad = frames[10]
    data = bytearray(bad.data)
    data[3] ^= 0x01
    frames[10] = type(bad)(timestamp=bad.timestamp, arbitration_id=bad.arbitration_id, is_extended_id=False,
                           dlc=8, data=bytes(data))
    events = [{"kind": "tip_up", "t_s": 1.8}, {"kind": "point_of_no_return", "t_s": 2.5, "side": "right"}]
    o = evaluate_warning_frames(frames, events)
    assert o.frames_rejected == 1  # the CRC catches the flipped bit
    assert o.warning_episodes == [(1.0, 1.48)]  # the last frame at level 2 (the all-clear is sent at 1.5 s)
    assert o.first_warning_t_s == 1.0 and o.lead_time_s == pytest.approx(1.5)
    assert o.lead_to_tip_up_s == pytest.approx(0.8) and o.lead_time_matched_side_s == pytest.approx(1.5)
    assert o.false_alarms == 0
    # the same frames in a run without a rollover: one false alarm
    assert evaluate_warning_frames(frames, []).false_alarms == 1
    # a rollover 10 s later: the episode ended more than 5 s before it, a false alarm too
    assert evaluate_warning_frames(frames, [{"kind": "point_of_no_return", "t_s": 12.0}]).false_alarms == 1
