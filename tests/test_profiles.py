import math

import pytest

from vdps_hil.sim.profiles import PROFILE_DIR, ProfileError, load_profile, parse_profile


def test_table1_exactly_as_printed():
    p = load_profile("table1")
    assert p.gnss.rate_hz == 5.0 and math.isclose(p.gnss.attitude_sigma_rad, math.radians(0.4))
    assert (p.gnss.pos_sigma_h_m, p.gnss.pos_sigma_v_m) == (1.0, 3.0)
    assert (p.suspension.rate_hz, p.suspension.sigma_m) == (1.0, 0.001)
    assert (p.imu.rate_hz, p.imu.accel_sigma_mps2) == (1000.0, 0.02)
    assert math.isclose(p.imu.gyro_sigma_radps, math.radians(0.08))
    assert p.tachometer.rate_hz == 1000.0 and math.isclose(p.tachometer.sigma_radps, math.radians(2.0))
    # realistic errors beyond white noise are all off in table1
    assert p.gnss.latency_s == 0 and p.gnss.gauss_markov_tau_s == 0
    assert p.imu.scale_factor_ppm == 0 and p.imu.misalignment_rad == 0 and not p.quantise_dbc
    # rates Table 1 omits are stated
    assert p.wheel_torque.rate_hz > 0 and p.steering.rate_hz > 0


def test_susp1k_differs_only_in_suspension_rate():
    a, b = load_profile("table1"), load_profile("table1-susp1k")
    assert b.suspension.rate_hz == 1000.0
    assert (a.gnss, a.imu, a.tachometer, a.wheel_torque, a.steering) == (b.gnss, b.imu, b.tachometer, b.wheel_torque, b.steering)


def test_zero_noise_keeps_rates():
    z = load_profile("table1-susp1k").zero_noise()
    assert z.imu.accel_sigma_mps2 == 0 and z.gnss.pos_sigma_h_m == 0 and z.suspension.rate_hz == 1000.0


@pytest.mark.parametrize("mutation,msg", [
    (lambda s: s.replace("rate_hz = 5.0", "rate_hz = 0"), "must be positive"),
    (lambda s: s.replace("sigma_m = 0.001", "sigma_m = -1"), "non-negative"),
    (lambda s: s.replace('"PASHR"', '"GSV"'), "attitude_sentence"),
    (lambda s: s.replace("[imu]", "[imu]\nbogus = 1"), "unknown key"),
    (lambda s: s + "\n[[", "malformed TOML"),
    # each was an internal error in vdps sim (a division by a zero period, an overflow, a ValueError)
    (lambda s: s.replace("rate_hz = 5.0", "rate_hz = 1e300"), r"outside \[0, 100000\]"),
    (lambda s: s.replace("baud = 115200", "baud = 0"), r"outside \[1, 1e\+08\]"),
    (lambda s: s.replace("sigma_m = 0.001", "sigma_m = 1e300"), r"outside \[0, 1e\+06\]"),
])
def test_bad_profiles(mutation, msg):
    with pytest.raises(ProfileError, match=msg):
        parse_profile(mutation((PROFILE_DIR / "table1.toml").read_text()), "x.toml")


def test_unknown_profile_lists_available():
    with pytest.raises(ProfileError, match="available: table1"):
        load_profile("nope")
