"""Wheel lift-off detection and the GNSS antenna's lever-arm rates (``estimation.lift_off``)."""

import math

import pytest

from vdps_hil.estimation.lift_off import LiftOffDetector, lever_arm_rates
from vdps_hil.model.params import load_vehicle

SUV = load_vehicle("suv-model", "model")


def _droop_m(corner: int) -> float:
    """The deflection [m] at which the corner's spring is at its free length (no load left
    but the unsprung weight, which the lifted wheel hangs on)."""
    return -SUV.axle(corner).static_compression_m - 0.01


def test_a_car_at_design_ride_height_has_every_wheel_loaded():
    det = LiftOffDetector(SUV, 0.1)
    assert not det.unloaded((0.0,) * 4, (0.0,) * 4)
    assert not det.unloaded((0.02, -0.02, -0.02, 0.02), (0.0,) * 4)  # a 2 cm roll: loads shift, none lifts
    assert det.unloaded_samples == 0 and not det.active


@pytest.mark.parametrize("corner", range(4))
def test_a_wheel_hanging_at_full_droop_is_unloaded_and_counted(corner):
    det = LiftOffDetector(SUV, 0.1)
    h = [0.0] * 4
    h[corner] = _droop_m(corner)
    assert det.unloaded(h, (0.0,) * 4)
    assert det.active and det.unloaded_samples == 1


def test_the_check_is_off_at_fraction_0_and_a_non_finite_rate_counts_as_0():
    h = [_droop_m(0), 0.0, 0.0, 0.0]
    assert not LiftOffDetector(SUV, 0.0).unloaded(h, (0.0,) * 4)
    det = LiftOffDetector(SUV, 0.1)
    assert det.unloaded(h, (math.nan,) * 4)
    assert not det.unloaded((math.nan,) * 4, (0.0,) * 4)  # a missing deflection says nothing


@pytest.mark.parametrize("bad", [-0.1, 1.0, math.nan, "0.1"])
def test_an_absurd_fraction_is_refused(bad):
    with pytest.raises(ValueError, match="lift-off load fraction"):
        LiftOffDetector(SUV, bad)


def test_lever_arm_rates_come_from_the_gyro_the_suspension_or_nowhere():
    geo = SUV.geometry
    gyro = (0.1, 0.2, 0.3)
    assert lever_arm_rates(gyro, (0.0,) * 4, geo, imu_missing=False, lifted=True) == [0.1, 0.2, 0.3]
    assert lever_arm_rates(gyro, (0.0,) * 4, geo, imu_missing=True, lifted=True) is None
    # right side compressing at 0.1 m/s: roll right-side-down positive, nose neither up nor down
    w = lever_arm_rates(gyro, (-0.1, 0.1, 0.1, -0.1), geo, imu_missing=True, lifted=False)
    t = 2.0 * geo.track_half_front_m + 2.0 * geo.track_half_rear_m
    assert w[0] == pytest.approx(0.4 / t, rel=1e-12) and w[1] == 0.0 and w[2] == 0.3


def test_without_suspension_rates_the_held_gyro_rates_stay():
    """A car without suspension sensors (the alpha-beta rates NaN) keeps the held gyro's roll and
    pitch rates for the lever arm during an outage, as before the suspension substitute."""
    w = lever_arm_rates((0.1, 0.2, 0.3), (math.nan,) * 4, SUV.geometry, imu_missing=True, lifted=False)
    assert w == [0.1, 0.2, 0.3]
