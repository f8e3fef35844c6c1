"""Pipeline settings: the real-car switches are off for the paper's Table-1 set."""

from vdps_hil.estimation.pipeline_config import PipelineConfig


def test_real_car_switches_are_off_for_the_paper_set():
    cfg = PipelineConfig()
    e = cfg.ekf
    assert not (e.gyro_bias or e.accel_bias or e.wheel_speed or e.wheel_scale_state or e.nonholonomic)
    assert cfg.reacquire_after_gated == 0
    assert not e.layout().augmented and e.layout().n == 11
    assert {k.value for k in e.kinds()} == {"gnss_pos", "gnss_vel", "gnss_att", "y1_sus", "y2_sus_rate"}
