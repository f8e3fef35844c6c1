"""vdps_hil.realdata.rtklib without the real data: the publisher's mounting conversion and the GPST
time scales."""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.model.frames import dcm_gv
from vdps_hil.model.params import load_vehicle
from vdps_hil.realdata.rtklib import gpst_minus_utc_s, gpst_to_unix, groves_ctm, publisher_mounting_rpy, unix_to_gpst


def test_publisher_mounting_matches_the_vehicle_file_and_groves():
    veh = load_vehicle("rtklib-car-model", "model")
    rpy = publisher_mounting_rpy((180.0, 0.0, 180.0), (0.0, -6.79, 5.35))
    assert np.allclose(rpy, veh.mounting.imu_rotation_rpy_rad, atol=1e-9)
    e = np.radians([180.0, -6.79, 185.35])
    f_imu = np.array([1.15, 0.30, 9.86])  # the drive's standstill mean [m/s^2]
    f_frd = groves_ctm(*e) @ f_imu  # the publisher's own transform
    f_flu = dcm_gv(*rpy).T @ f_imu  # what the pipeline does with the model file
    assert np.allclose(f_flu, f_frd * np.array([1.0, -1.0, -1.0]), atol=1e-12)
    assert abs(f_flu[0]) < 0.05 and f_flu[2] > 9.8  # level forward axis once the misalignment is applied
    assert np.allclose(publisher_mounting_rpy((180.0, 0.0, 180.0)), (0.0, 0.0, -math.pi), atol=1e-12)
    assert veh.mounting.imu_lever_arm_m == (0.0, 0.0, 0.65) and veh.mounting.gnss_lever_arm_m == (0.0, 0.05, 0.65)


def test_time_scales():
    assert gpst_minus_utc_s(1.75e9) == 18 and gpst_minus_utc_s(1.2e9) == 14
    assert gpst_to_unix(unix_to_gpst(1.75e9)) == 1.75e9
