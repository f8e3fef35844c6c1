"""``pipeline.configure.system_config``: how a recording's first seconds configure the node (the
sensor set inferred or named; the real-car rows when nothing measures the heading). The filter's
behaviour with the inferred set on a real drive is in ``test_real_rav4.py``."""

from __future__ import annotations

import pytest

from vdps_hil.model.params import load_vehicle
from vdps_hil.pipeline.configure import SystemConfigError, system_config

VEH = load_vehicle("sedan-model", "model")
SIX = {f"specific_force_mps2_{a}" for a in "xyz"} | {f"angular_rate_radps_{a}" for a in "xyz"}
WHEELS = {f"wheel_speed_radps_{i}" for i in range(1, 5)}
SUSP = {f"susp_deflection_m_{i}" for i in range(1, 5)}
POS = {"gnss_lat_deg", "gnss_lon_deg", "gnss_alt_m"}
ATT = {"gnss_roll_rad", "gnss_pitch_rad", "gnss_yaw_rad"}
RATES = {"imu": 1000.0, "gnss_pos": 5.0, "wheel_speed": 1000.0, "suspension": 1000.0}


def _rows(ekf) -> tuple:
    return ekf.gyro_bias, ekf.accel_bias, ekf.nonholonomic, ekf.uses_wheel_speed, ekf.wheel_scale_state


def test_table1_fields_keep_the_filter_as_printed():
    """Three antennas (GNSS attitude measured): eq 7 as printed, no real-car rows."""
    fields = {"imu": SIX, "gnss_pos": POS, "gnss_att": ATT, "wheel_speed": WHEELS, "suspension": SUSP}
    cfg, kind_map, nodes, desc = system_config(RATES, fields, VEH)
    assert desc["source"] == "inferred from the recording" and desc["gnss"] == "multi_antenna"
    assert _rows(cfg.pipeline.ekf) == (False, False, False, False, False)
    assert kind_map == {} and list(nodes) == []


@pytest.mark.parametrize("imu,fields,wheels", [
    ("6axis", {"imu": SIX, "gnss_pos": POS, "wheel_speed": WHEELS}, True),
    ("esc3", {"esc_imu": {"specific_force_mps2_x", "specific_force_mps2_y", "angular_rate_radps_z"},
              "gnss_pos": POS, "wheel_speed": WHEELS}, True),
    ("6axis", {"imu": SIX, "gnss_pos": POS}, False),
])
def test_without_gnss_attitude_the_inferred_set_runs_the_real_car_rows(imu, fields, wheels):
    """A single antenna measures no heading: bias states and the non-holonomic constraint always,
    the wheel-speed row and its scale state when the car has tachometers."""
    cfg, kind_map, _, desc = system_config(RATES, fields, VEH)
    assert (desc["imu"], desc["gnss"], desc["wheel_speeds"]) == (imu, "single_antenna", wheels)
    assert _rows(cfg.pipeline.ekf) == (True, True, True, wheels, wheels)
    assert kind_map == ({"esc_imu": "imu"} if imu == "esc3" else {})
    axes = cfg.pipeline.ekf.gyro_bias_axes
    assert axes == ((2,) if imu == "esc3" else (0, 1, 2))


def test_a_named_sensor_set_is_taken_as_written():
    """The named set decides its own rows (rav4-can-ublox switches them on in its file)."""
    fields = {"imu": SIX, "gnss_pos": POS, "gnss_att": ATT, "wheel_speed": WHEELS, "suspension": SUSP}
    cfg, _, _, desc = system_config(RATES, fields, VEH, sensorset="table1")
    assert desc["source"] == "table1" and _rows(cfg.pipeline.ekf) == (False, False, False, False, False)
    cfg, kind_map, _, desc = system_config(RATES, fields, VEH, sensorset="rav4-can-ublox")
    assert desc["source"] == "rav4-can-ublox" and kind_map == {"esc_imu": "imu"}
    assert _rows(cfg.pipeline.ekf) == (True, True, True, True, True)


def test_no_imu_is_a_one_line_error():
    with pytest.raises(SystemConfigError, match="no IMU"):
        system_config(RATES, {"gnss_pos": POS}, VEH)


def test_an_altitude_in_a_frame_of_its_own_is_named_for_the_join():
    """A recording with a ``gnss_alt`` kind (the CANedge's GNSS) is described as joining it
    (``sensor_set.gnss_altitude``), which switches on ``KindMap``'s altitude join."""
    fields = {"imu": SIX, "gnss_pos": {"gnss_lat_deg", "gnss_lon_deg"}, "gnss_alt": {"gnss_alt_m"}, "gnss_att": ATT}
    _, _, _, desc = system_config(RATES, fields, VEH)
    assert desc["gnss_altitude"] == "joined from gnss_alt"
    _, _, _, desc = system_config(RATES, {"imu": SIX, "gnss_pos": POS, "gnss_att": ATT}, VEH)
    assert "gnss_altitude" not in desc
