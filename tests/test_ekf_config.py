"""EKF configuration: sensor sets and real-car switches decide the measurement kinds and the state
layout; bad values refused."""

import pytest

from vdps_hil.estimation.ekf_config import EkfConfig, PaperFaithful, SensorSet
from vdps_hil.estimation.observations import ObsKind


@pytest.mark.parametrize("sensors,kinds,n", [
    (SensorSet(), {"gnss_pos", "gnss_vel", "gnss_att", "y1_sus", "y2_sus_rate"}, 11),
    (SensorSet(gnss="single_antenna"), {"gnss_pos", "gnss_vel", "y1_sus", "y2_sus_rate"}, 11),
    (SensorSet(imu="esc3", gnss="single_antenna", suspension=False), {"gnss_pos", "gnss_vel"}, 9),
    (SensorSet(gnss="none", suspension=False), set(), 9),
])
def test_sensor_sets_decide_kinds_and_layout(sensors, kinds, n):
    cfg = EkfConfig(sensors=sensors)
    assert {k.value for k in cfg.kinds()} == kinds
    assert cfg.layout().n == n
    q = cfg.input_psd()
    if sensors.imu == "esc3":  # substituted axes get the substitution noise
        assert q[2] == pytest.approx(2 * 0.5 ** 2 * 0.2) and q[3] == q[4] == pytest.approx(2 * 0.05 ** 2 * 0.2)
    else:
        assert q[0] == pytest.approx(0.02 ** 2 / 1000)


def test_config_rejects_bad_values():
    with pytest.raises(ValueError):
        EkfConfig(accel_noise_mps2=-1.0)
    with pytest.raises(ValueError):
        EkfConfig(gate_probability=1.5)
    with pytest.raises(ValueError):
        SensorSet(gnss="three_antenna")
    with pytest.raises(ValueError):
        PaperFaithful.only("e_something")


def test_real_car_switches_decide_kinds_and_layout():
    esc = SensorSet(imu="esc3", gnss="single_antenna", suspension=False)
    cfg = EkfConfig(sensors=esc, gyro_bias=True, accel_bias=True, wheel_speed=True, wheel_scale_state=True,
                    nonholonomic=True)
    assert {k.value for k in cfg.kinds()} == {"gnss_pos", "gnss_vel", "wheel_speed", "nhc"}
    assert cfg.gyro_bias_axes == (2,) and cfg.accel_bias_axes == (0, 1) and cfg.layout().n == 13
    six = EkfConfig(sensors=SensorSet(gnss="single_antenna", suspension=False, wheel_speeds=False),
                    gyro_bias=True, accel_bias=True, wheel_speed=True, wheel_scale_state=True)
    assert ObsKind.WHEEL_SPEED not in six.kinds()  # no wheel speeds fitted: no row, no scale state
    assert six.layout().n == 15 and not six.layout().wheel_scale
    assert EkfConfig(sensors=esc).with_real_car_rows() == cfg
    assert not EkfConfig(sensors=SensorSet(wheel_speeds=False)).with_real_car_rows().wheel_scale_state
    with pytest.raises(ValueError, match="nonholonomic"):
        EkfConfig(nonholonomic=1)
    with pytest.raises(ValueError, match="gyro_bias_sigma_radps"):
        EkfConfig(gyro_bias_sigma_radps=0.0)
