"""Tests of vdps_hil.prediction.metrics on hand-made trajectories (exact numbers)."""

import math

import numpy as np
import pytest

from vdps_hil.model.frames import dcm_global_to_road
from vdps_hil.prediction.metrics import (CHANNELS, PAPER_INACCURACY_PCT, PoseTrajectory, compare_trajectories,
                                         format_metrics, prediction_metrics, road_frame_channels)

N = 11
T = np.linspace(0.0, 1.0, N)
D = math.radians(1.0)


def straight_east(speed=10.0):
    pos = np.stack([speed * T, np.zeros(N), np.zeros(N)], axis=1)
    return pos, np.zeros((N, 3))


def test_identical_trajectories_have_zero_error():
    pos, eul = straight_east()
    m = prediction_metrics(pos, eul, pos, eul, t_s=T)
    assert m["position_err_m"] == 0.0 and m["position_rms_m"] == 0.0
    assert m["yaw_err_deg"] == 0.0 and m["roll_rms_deg"] == 0.0
    assert m["inaccuracy_pct"] == 0.0 and set(m["inaccuracy_channels_pct"]) == set(CHANNELS)
    assert m["span_s"] == 1.0 and m["n_samples"] == N


def test_constant_offset_east_north():
    pos, eul = straight_east()
    m = prediction_metrics(pos + [3.0, 4.0, 0.0], eul, pos, eul)
    assert m["position_err_m"] == pytest.approx(5.0, abs=1e-12)
    assert m["position_rms_m"] == pytest.approx(5.0, abs=1e-12)
    assert m["along_err_m"] == pytest.approx(3.0) and m["cross_err_m"] == pytest.approx(4.0)
    # paper-style: xa range 10 m -> 3/10; ya range 0 -> floor 1 m -> 4/1; others 0
    assert m["inaccuracy_channels_pct"]["xa"] == pytest.approx(30.0)
    assert m["inaccuracy_channels_pct"]["ya"] == pytest.approx(400.0)
    assert m["inaccuracy_pct"] == pytest.approx((30.0 + 400.0) / 6.0)


def test_aux_frame_follows_the_heading_at_t0():
    # heading north (psi_v = 90 deg): a northward error is along-track, an eastward one cross-track (right: -y)
    pos = np.stack([np.zeros(N), 10.0 * T, np.zeros(N)], axis=1)
    eul = np.zeros((N, 3))
    eul[:, 2] = math.pi / 2
    m = prediction_metrics(pos + [0.0, 2.0, 0.0], eul, pos, eul)
    assert m["along_err_m"] == pytest.approx(2.0) and m["cross_err_m"] == pytest.approx(0.0, abs=1e-12)
    m = prediction_metrics(pos + [1.5, 0.0, 0.0], eul, pos, eul)
    assert m["cross_err_m"] == pytest.approx(-1.5) and m["along_err_m"] == pytest.approx(0.0, abs=1e-12)


def test_road_frame_on_a_banked_graded_road():
    bank, grade = math.radians(2.0), math.radians(-2.0)
    normal = dcm_global_to_road(bank, grade)[2]  # road normal in ENU (row 3 of C_g^r)
    pos, eul = straight_east()
    m = prediction_metrics(pos + 0.3 * normal, eul, pos, eul, road_bank_rad=bank, road_grade_rad=grade)
    assert m["normal_err_m"] == pytest.approx(0.3, abs=1e-12)
    assert abs(m["along_err_m"]) < 1e-12 and abs(m["cross_err_m"]) < 1e-12
    ch = road_frame_channels(pos, eul, pos[0], 0.0, bank, grade)
    assert ch["xa"][-1] == pytest.approx(10.0 * math.cos(grade))  # East projected on the graded road
    # a level 10 m eastward displacement seen from the road plane (C_g^r = R(x, bank) R(y, grade))
    assert ch["ya"][-1] == pytest.approx(-10.0 * math.sin(bank) * math.sin(grade), rel=1e-12)
    assert ch["za"][-1] == pytest.approx(-10.0 * math.cos(bank) * math.sin(grade), rel=1e-12)


def test_angle_errors_and_yaw_wrap():
    pos, eul = straight_east()
    true = eul.copy()
    true[:, 2] = math.radians(179.0)
    pred = true.copy()
    pred[:, 2] = math.radians(-179.0)  # 2 deg further CCW across the +-180 cut
    pred[:, 0] = math.radians(0.5)  # roll error 0.5 deg
    m = prediction_metrics(pos, pred, pos, true)
    assert m["yaw_err_deg"] == pytest.approx(2.0, abs=1e-9)
    assert m["yaw_rms_deg"] == pytest.approx(2.0, abs=1e-9)
    assert m["roll_err_deg"] == pytest.approx(0.5) and m["pitch_err_deg"] == 0.0
    # ranges: psi constant -> floor 1 deg -> 200 %; roll 0.5/1 -> 50 %
    assert m["inaccuracy_channels_pct"]["psi_v"] == pytest.approx(200.0, abs=1e-6)
    assert m["inaccuracy_channels_pct"]["phi_v"] == pytest.approx(50.0)


def test_paper_style_inaccuracy_exact():
    """x_a moves 10 m (error 1 m -> 10 %), psi_v turns 20 deg (error 2 deg -> 10 %), theta_v
    moves 0.5 deg (error 0.1 deg, floor 1 deg -> 10 %): mean over six channels = 5 %."""
    pos, eul = straight_east()
    true_eul = eul.copy()
    true_eul[:, 2] = np.radians(20.0) * T
    true_eul[:, 1] = np.radians(0.5) * T
    pred_eul = true_eul + [0.0, math.radians(0.1), math.radians(2.0)]
    m = prediction_metrics(pos + [1.0, 0.0, 0.0], pred_eul, pos, true_eul)
    ch = m["inaccuracy_channels_pct"]
    assert ch["xa"] == pytest.approx(10.0) and ch["ya"] == pytest.approx(0.0, abs=1e-12)
    assert ch["psi_v"] == pytest.approx(10.0) and ch["theta_v"] == pytest.approx(10.0)
    assert m["inaccuracy_pct"] == pytest.approx(5.0)
    # the along error is measured in the aux frame of the TRUE pose at t0 (heading 0 here)
    assert m["along_err_m"] == pytest.approx(1.0)


def test_rms_over_the_span():
    pos, eul = straight_east()
    err = np.zeros((N, 3))
    err[:, 1] = np.linspace(0.0, 1.0, N)  # cross error grows 0..1 m
    m = prediction_metrics(pos + err, eul, pos, eul)
    assert m["position_err_m"] == pytest.approx(1.0)
    assert m["position_rms_m"] == pytest.approx(math.sqrt(np.mean(np.linspace(0, 1, N) ** 2)))


def test_compare_trajectories_interpolates_and_clips_to_the_common_span():
    t_true = np.arange(0.0, 2.0001, 0.01) + 3.0
    true = PoseTrajectory(t_true, np.stack([10.0 * (t_true - 3.0), 0 * t_true, 0 * t_true], axis=1),
                          np.zeros((t_true.size, 3)))
    t_pred = np.arange(0.0, 5.0001, 0.02) + 3.0  # longer than the truth
    pred = PoseTrajectory(t_pred, np.stack([10.0 * (t_pred - 3.0) + 0.5, 0 * t_pred, 0 * t_pred], axis=1),
                          np.zeros((t_pred.size, 3)))
    m = compare_trajectories(pred, true)
    assert m["t_end_s"] == pytest.approx(5.0) and m["n_samples"] == 101
    assert m["position_err_m"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="different times"):
        compare_trajectories(PoseTrajectory(t_pred + 0.1, pred.pos_g_m, pred.euler_v_rad), true)


def test_bad_shapes_are_refused():
    pos, eul = straight_east()
    with pytest.raises(ValueError):
        prediction_metrics(pos[:5], eul, pos, eul)
    with pytest.raises(ValueError):
        PoseTrajectory(T, pos[:, :2], eul)


def test_format_shows_the_paper_value():
    pos, eul = straight_east()
    m = prediction_metrics(pos + [1.0, 0.0, 0.0], eul, pos, eul, t_s=T)
    text = format_metrics("left turn", m, "left_turn")
    assert "paper: 0.51 %" in text and "inaccuracy" in text
    assert PAPER_INACCURACY_PCT == {"left_turn": 0.51, "rollover": 27.3}
