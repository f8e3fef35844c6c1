"""What a drive can show: missing signal groups named with what they prevent, why rows are
unusable, and a drive too short to judge."""

from __future__ import annotations

import numpy as np

from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import coverage as C
from vdps_hil.workbench.dataset import DriveTable
from vdps_hil.workbench.residuals import NEEDED_COLUMNS


def _table(n=500, speed=20.0, drop=()):
    t = np.arange(n) * 0.02
    cols = {k: np.zeros(n) for k in NEEDED_COLUMNS}
    cols.update({f"susp_deflection_m_{i}": np.zeros(n) for i in range(1, 5)})
    cols["vel_g_mps_e"] = np.full(n, speed) if np.isscalar(speed) else np.asarray(speed, float)
    for k in drop:
        cols[k] = np.full(n, np.nan)
    return DriveTable(0, t, cols, {}, {}, {}, {}, load_vehicle("sedan-model"))


def test_a_missing_signal_group_is_named_with_what_it_prevents():
    torques = [f"wheel_torque_nm_{i}" for i in range(1, 5)]
    lines = C.missing_signals(_table(drop=torques))
    assert len(lines) == 1 and "wheel torques" in lines[0] and "aerodynamic drag" in lines[0]
    assert C.missing_signals(_table()) == []


def test_a_sensor_the_set_left_out_is_named():
    """``load_drive`` records what the sensor set's kind map left out (``sensorsets.KindMap``) in
    ``table.sensors["not_used"]``; the diagnosis says it beside the missing signals."""
    tab = _table()
    tab.sensors = {"source": "rav4-can-ublox", "kind_map": {"esc_imu": "imu"}, "not_used": {"imu/imu": 6256}}
    assert C.missing_signals(tab) == ["not used: imu/imu (6256 samples): the sensor set feeds imu from esc_imu"]
    tab.sensors = {"source": "inferred from the recording", "kind_map": {}}
    assert C.missing_signals(tab) == []


def test_unusable_rows_say_why():
    assert "never moves faster than 5 m/s" in C.unusable_reason(_table(speed=1.0))
    msg = C.unusable_reason(_table(drop=["steer_wheel_angle_rad"]))
    assert "steer_wheel_angle_rad" in msg and "0 of 500, at least 50 needed" in msg
    # every row usable and still too few (a 2 s drive read "49 of 49 ...: only 49 rows are moving")
    msg = C.unusable_reason(_table(n=49))
    assert "49 of 49, at least 50 needed" in msg and "the drive is too short, 49 rows of 0.02 s (1.0 s)" in msg


def test_a_drive_that_stops_early_is_too_short_to_judge():
    speed = np.r_[np.full(200, 15.0), np.zeros(1800)]  # 4 s moving, then standing for 36 s
    tab = _table(n=2000, speed=speed)
    used = np.flatnonzero(speed >= 5.0)
    msgs = C.coverage_messages(tab, used)
    assert any("too little drive to judge: only 4.0 s of the 40.0 s" in m for m in msgs)
    assert not any("too little" in m for m in C.coverage_messages(_table(n=2000), np.arange(2000)))


def test_an_effect_left_out_is_said_with_why_and_how_to_fit_it_anyway():
    from vdps_hil.workbench.coverage import not_ranked_lines

    assert not_ranked_lines({}) == []
    (line,) = not_ranked_lines({"steering_offset": "the heading spans 12 deg, less than the half turn"})
    assert line == ("not ranked on this drive: steering_offset (the heading spans 12 deg, less than the half turn): "
                    "vdps diagnose --add steering_offset fits it")
