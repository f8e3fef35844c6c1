"""Tests of vdps_hil.estimation.imu_monitor: the IMU checks (finite, time, plausible, spike with
re-anchoring, gap) on synthetic 1 kHz streams, and the outage input: the covariance of a real
MultiRateEKF grows with the outage as the module docstring's model says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vdps_hil.estimation.ekf import MultiRateEKF
from vdps_hil.estimation.imu_monitor import ImuChecks, ImuMonitor
from vdps_hil.estimation.states import States

G = (0.0, 0.0, 9.81)
MS = 1_000_000


def _stream(mon, n, w_of_k, t0_ms=0):
    """Feed n samples at 1 kHz (w from w_of_k(k)); the verdicts."""
    return [mon.check((t0_ms + k) * MS, G, w_of_k(k)) for k in range(n)]


def test_a_car_manoeuvre_passes_every_check():
    # yaw acceleration 15 rad/s^2 for 0.2 s (a violent steer: 3 rad/s of yaw rate) plus noise
    rng = np.random.default_rng(3)
    mon = ImuMonitor()
    ok = _stream(mon, 600, lambda k: (rng.normal(0, 0.0014), 0.0, 15.0 * min(k, 200) * 1e-3 + rng.normal(0, 0.0014)))
    assert all(ok)
    assert mon.counters["spike"] == 0 and mon.counters["outages"] == 0


@pytest.mark.parametrize("amp_degps, n_ms", [(200.0, 50), (200.0, 2), (150.0, 200), (200.0, 200), (20.0, 200),
                                             (100.0, 50)])
def test_gyro_spike_is_rejected_sample_by_sample(amp_degps, n_ms):
    """A spike on a yaw rate that moves (0.5 rad/s^2, a steady steer) and on noise: every spike
    sample rejected, every other one taken (issue 20: 2-200 ms, up to 200 deg/s; spikes above the
    jump floor, ``ImuChecks.rate_jump_radps`` = 0.15 rad/s = 8.6 deg/s, on a clean IMU)."""
    rng = np.random.default_rng(5)
    mon = ImuMonitor()
    amp = math.radians(amp_degps)
    ok = _stream(mon, 600, lambda k: (rng.normal(0, 0.0014), 0.0, 0.1 + 5e-4 * k + rng.normal(0, 0.0014)
                                      + (amp if 100 <= k < 100 + n_ms else 0.0)))
    assert not any(ok[100:100 + n_ms])
    assert all(ok[:100]) and all(ok[100 + n_ms:])
    assert mon.counters["spike"] == n_ms
    assert mon.fault_age_ns((100 + n_ms) * MS) <= 1 * MS  # the fault is recent when the spike ends


def test_small_spike_within_the_jump_allowance_is_taken():
    # 5 deg/s (0.087 rad/s < rate_jump_radps 0.15) is indistinguishable from motion: taken
    mon = ImuMonitor()
    ok = _stream(mon, 200, lambda k: (0.0, 0.0, math.radians(5.0) if 50 <= k < 100 else 0.0))
    assert all(ok)


def test_a_noisy_imu_raises_its_own_jump_and_keeps_every_sample():
    """A MEMS gyro as noisy as the real RTKLIB drive's (100 Hz, pitch-rate noise whose steps
    average ~0.09 rad/s, heavy-tailed: Student t with 3 degrees of freedom) is not rejected for
    its noise (the jump grows with the running mean step), and a 200 deg/s spike on it still is."""
    rng = np.random.default_rng(17)
    mon = ImuMonitor()
    noise = rng.standard_t(3, size=3000) * 0.045
    ok = [mon.check(k * 10 * MS, G, (0.0, noise[k], 0.0)) for k in range(3000)]
    assert all(ok) and mon.counters["spike"] == 0
    t = 3000 * 10 * MS
    assert not mon.check(t, G, (0.0, noise[0] + math.radians(200.0), 0.0))
    assert mon.counters["spike"] == 1


def test_a_persistent_step_is_reanchored_so_the_imu_is_not_locked_out():
    c = ImuChecks()
    mon = ImuMonitor(c)
    ok = _stream(mon, 1500, lambda k: (0.0, 0.0, 3.0 if k >= 100 else 0.0))
    rejected = 1500 - sum(ok)
    assert rejected == pytest.approx(c.reanchor_s * 1000, abs=2)
    assert all(ok[100 + int(c.reanchor_s * 1000) + 1:])
    assert mon.counters["reanchored"] == 1


@pytest.mark.parametrize("w, f", [((11.0, 0.0, 0.0), G), ((0.0, 0.0, 0.0), (0.0, 120.0, 9.81)),
                                  ((math.nan, 0.0, 0.0), G)])
def test_saturated_implausible_or_non_finite_samples_are_rejected(w, f):
    mon = ImuMonitor()
    assert mon.check(0, G, (0.0, 0.0, 0.0))
    assert not mon.check(MS, f, w)
    assert mon.counters["implausible"] + mon.counters["not_finite"] == 1


def test_time_stepping_back_is_rejected_but_stamp_jitter_is_taken():
    mon = ImuMonitor()
    assert mon.check(100 * MS, G, (0.0, 0.0, 0.0))
    assert mon.check(99 * MS, G, (0.0, 0.0, 0.0))  # 1 ms: serial time-stamp jitter
    assert not mon.check(50 * MS, G, (0.0, 0.0, 0.0))  # 50 ms back: a clock step
    assert mon.counters["time"] == 1


def test_gap_is_an_outage_that_spans_are_checked_against():
    mon = ImuMonitor()
    _stream(mon, 100, lambda k: (0.0, 0.0, 0.2))
    assert mon.covered(90 * MS, 99 * MS) and not mon.missing(99 * MS)
    assert mon.missing(500 * MS) and not mon.covered(99 * MS, 500 * MS)
    # the IMU returns at 2.1 s with another yaw rate (no reference after a gap: taken)
    assert mon.check(2100 * MS, G, (0.0, 0.0, 1.5))
    assert mon.counters["outages"] == 1 and mon.gap == (99 * MS, 2100 * MS)
    assert not mon.covered(1500 * MS, 2100 * MS)  # a predict over the gap
    assert mon.check(2101 * MS, G, (0.0, 0.0, 1.5))
    assert mon.covered(2100 * MS, 2101 * MS)
    assert mon.fault_age_ns(2101 * MS) == 1 * MS


def test_a_slow_imu_teaches_its_period_and_is_not_in_outage():
    """An IMU at 10 Hz (the CANedge's IMU frames): its intervals exceed the 20 ms timeout, so the
    period could never be learned from intervals within it and every sample was an outage. Three
    alike long intervals are its period: only the first two count as outages, and then samples
    100 ms apart cover the spans between them and the IMU is not missing 0.5 s after the last."""
    mon = ImuMonitor()
    rng = np.random.default_rng(5)
    t = [int((100 * k + rng.uniform(-5, 5)) * MS) for k in range(50)]  # 10 Hz with +-5 ms stamp jitter
    assert all(mon.check(tk, G, (0.0, 0.0, 0.1)) for tk in t)
    assert mon.counters["outages"] == 2 and mon.counters["period_relearned"] >= 1
    assert 0.9e9 <= mon.timeout_ns <= 1.1e9  # 10 learned periods
    assert mon.covered(t[-2], t[-1]) and not mon.missing(t[-1] + 500 * MS)
    assert mon.fault_age_ns(t[-1]) == t[-1] - t[2]  # the last fault: the second interval's end
    # a real outage of the slow IMU is still one
    assert mon.missing(t[-1] + 2000 * MS)
    assert mon.check(t[-1] + 3000 * MS, G, (0.0, 0.0, 0.1))
    assert mon.counters["outages"] == 3


def test_two_alike_gaps_of_a_fast_imu_stay_outages():
    """The slow-rate rule needs three alike long intervals in a row: a 1 kHz IMU that drops out
    twice for 300 ms with one sample between counts two outages and keeps its period."""
    mon = ImuMonitor()
    _stream(mon, 100, lambda k: (0.0, 0.0, 0.2))
    assert mon.check(400 * MS, G, (0.0, 0.0, 0.2)) and mon.check(700 * MS, G, (0.0, 0.0, 0.2))
    assert mon.counters["outages"] == 2 and mon.counters["period_relearned"] == 0
    _stream(mon, 100, lambda k: (0.0, 0.0, 0.2), t0_ms=701)
    assert mon.timeout_ns == 20 * MS  # max(timeout, 10 x 1 ms)
    assert mon.counters["outages"] == 2


def test_covariance_grows_with_the_outage_as_the_markov_input_error_says():
    """EKF at rest, IMU lost at 0: over T = 0.6 s (< tau = 1 s) the yaw variance must grow by
    sigma_wz^2 T^2 (the integral of q(t) = 2 sigma^2 t), within 10 %; and the horizontal velocity
    variance at least by sigma_f^2 T^2 (plus the tilt error's gravity leak)."""
    c = ImuChecks()
    mon = ImuMonitor(c)
    ekf = MultiRateEKF()
    n = ekf.layout.n
    ekf.initialize(0, np.zeros(n), np.eye(n) * 1e-6)
    mon.check(0, G, (0.0, 0.0, 0.0))
    P0 = ekf.full_state()[1]
    for k in range(1, 61):  # predicts every 10 ms from the last good sample, none arrives
        t1 = k * 10 * MS
        assert mon.apply_input(ekf, t1, G, (0.0, 0.0, 0.0), fresh=False) == (t1 > c.timeout_s * 1e9)
        ekf.predict_to(t1)
    P = ekf.full_state()[1]
    T = 0.6 - c.timeout_s  # the first 20 ms are covered (within the timeout)
    d_yaw = P[States.PSI_G, States.PSI_G] - P0[States.PSI_G, States.PSI_G]
    assert d_yaw == pytest.approx(c.outage_yaw_rate_sigma_radps ** 2 * 0.6 ** 2, rel=0.10)
    d_vx = P[States.XDOT_G, States.XDOT_G] - P0[States.XDOT_G, States.XDOT_G]
    assert d_vx >= 0.9 * c.outage_accel_sigma_mps2 ** 2 * T ** 2
    # the IMU is back: the configured input noise again
    mon.check(700 * MS, G, (0.0, 0.0, 0.0))
    mon.check(701 * MS, G, (0.0, 0.0, 0.0))
    assert mon.apply_input(ekf, 710 * MS, G, (0.0, 0.0, 0.0), fresh=True)  # still spans the gap
    ekf.predict_to(710 * MS)
    assert mon.apply_input(ekf, 720 * MS, G, (0.0, 0.0, 0.0), fresh=True) is False
    np.testing.assert_array_equal(ekf._q_in, ekf.config.input_psd())


def test_checks_refuse_bad_settings():
    with pytest.raises(ValueError, match="timeout_s"):
        ImuChecks(timeout_s=0.0)
    with pytest.raises(ValueError, match="max_rate_radps"):
        ImuChecks(max_rate_radps=math.inf)
