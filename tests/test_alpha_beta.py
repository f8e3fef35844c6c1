"""Alpha-beta filters of eq 12 against filterpy oracles (GHFilter, KalmanFilter to steady
state), agreement 1e-9; critically damped poles; the derivative lag formula against a
simulated ramp; the time-stamped variant (uniform sampling equals the fixed one, gaps, NaN)."""

import math

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.gh import GHFilter
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.estimation.alpha_beta import (AlphaBetaFilter, TimedAlphaBeta, bandwidth_3db_hz,
                                            critically_damped_gains, derivative_lag_s, frequency_response,
                                            kalata_gains, tracking_index)


def test_matches_filterpy_gh_filter(rng):
    dt = 1e-3
    a, b = critically_damped_gains(8.0, dt)
    ours = AlphaBetaFilter(a, b, dt, x0=0.3, v0=-0.1)
    gh = GHFilter(x=0.3, dx=-0.1, dt=dt, g=a, h=b)
    t = np.arange(3000) * dt
    z = np.sin(2 * math.pi * 1.3 * t) + rng.normal(0, 0.01, t.size)
    for zk in z:
        x, v = ours.update(zk)
        gx, gv = gh.update(zk)
        assert abs(x - gx) < 1e-9 and abs(v - gv) < 1e-9


@pytest.mark.parametrize("sigma_w,sigma_v,dt", [(5.0, 0.01, 1e-3), (50.0, 0.02, 1e-2), (0.5, 0.001, 1.0)])
def test_kalata_gains_equal_steady_state_kalman_and_outputs_agree(sigma_w, sigma_v, dt, rng):
    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.F = np.array([[1.0, dt], [0.0, 1.0]])
    kf.H = np.array([[1.0, 0.0]])
    kf.R *= sigma_v ** 2
    kf.Q = Q_discrete_white_noise(2, dt, sigma_w ** 2)  # piecewise constant white acceleration
    kf.P *= 100.0
    for _ in range(20000):
        kf.predict()
        kf.update(0.0)
    a, b = kalata_gains(tracking_index(sigma_w, sigma_v, dt))
    assert abs(kf.K[0, 0] - a) < 1e-9
    assert abs(kf.K[1, 0] * dt - b) < 1e-9
    # from the same state, the steady-state Kalman filter and eq 12 give the same outputs
    kf.x = np.array([[0.2], [0.1]])
    ours = AlphaBetaFilter(a, b, dt, x0=0.2, v0=0.1)
    for zk in rng.normal(0, 1.0, 500) * sigma_v + 0.2:
        kf.predict()
        kf.update(zk)
        x, v = ours.update(zk)
        assert abs(x - kf.x[0, 0]) < 1e-9 and abs(v - kf.x[1, 0]) < 1e-9 * max(1.0, abs(v))


@settings(max_examples=60, deadline=None)
@given(st.floats(0.05, 200.0), st.floats(1e-4, 0.1))
def test_critically_damped_double_pole(f_c, dt):
    a, b = critically_damped_gains(f_c, dt)
    theta = math.exp(-2 * math.pi * f_c * dt)
    assert 0.0 < a <= 1.0 and 0.0 < b <= 1.0
    # z^2 - (2 - a - b) z + (1 - a) == (z - theta)^2
    assert abs((2 - a - b) - 2 * theta) < 1e-12 and abs((1 - a) - theta ** 2) < 1e-12
    assert abs(frequency_response(a, b, dt, 0.0)[0] - 1.0) < 1e-9  # unity DC gain


def test_derivative_lag_formula_against_a_ramping_derivative():
    """z = a t^2 / 2: after settling the derivative estimate equals a (t - tau_d)."""
    dt, acc = 1e-3, 2.0
    f = AlphaBetaFilter.from_bandwidth(5.0, dt)
    for k in range(20000):
        _, v = f.update(0.5 * acc * (k * dt) ** 2)
    lag = (19999 * dt) - v / acc
    assert abs(lag - f.derivative_lag_s) < 1e-9
    assert abs(f.derivative_lag_s - 2 / (2 * math.pi * 5.0)) < 0.01  # ~ 2 / (2 pi f_c)
    assert f.derivative_lag_s == derivative_lag_s(f.alpha, f.beta, dt)


def test_bandwidth_3db_grows_with_the_configured_bandwidth():
    dt = 1e-3
    bws = [bandwidth_3db_hz(*critically_damped_gains(fc, dt), dt) for fc in (1.0, 5.0, 20.0)]
    assert bws[0] < bws[1] < bws[2]
    # a critically damped type-2 loop: -3 dB near 2.5 f_c for small f_c T
    assert 2.0 < bws[0] / 1.0 < 3.0


def test_timed_variant_equals_fixed_rate_and_handles_gaps_and_nan(rng):
    dt = 1e-3
    fixed = AlphaBetaFilter.from_bandwidth(5.0, dt)
    timed = TimedAlphaBeta(5.0, max_gap_s=0.5)
    z = np.cumsum(rng.normal(0, 0.01, 2000))
    for k, zk in enumerate(z):
        x, v = fixed.update(zk)
        assert timed.update(k * 1_000_000, zk)
        assert abs(timed.x - x) < 1e-12 and abs(timed.v - v) < 1e-9
    assert abs(timed.lag_s - fixed.derivative_lag_s) < 1e-12
    assert not timed.update(2001 * 1_000_000, math.nan) and timed.rejected == 1
    assert not timed.update(1000 * 1_000_000, 0.0) and timed.rejected == 2  # backwards in time
    assert timed.update(10 * 1_000_000_000, 5.0) and timed.restarts == 1 and timed.x == 5.0 and timed.v == 0.0


def test_bad_parameters_rejected():
    with pytest.raises(ValueError):
        critically_damped_gains(0.0, 1e-3)
    with pytest.raises(ValueError):
        critically_damped_gains(5.0, -1.0)
    with pytest.raises(ValueError):
        kalata_gains(-1.0)
    with pytest.raises(ValueError):
        AlphaBetaFilter(1.5, 0.1, 1e-3)


def test_bank_equals_individual_filters_and_skips_nan_per_signal(rng):
    from vdps_hil.estimation.alpha_beta import TimedAlphaBetaBank

    bank = TimedAlphaBetaBank(3, 4.0, max_gap_s=0.5)
    singles = [TimedAlphaBeta(4.0, max_gap_s=0.5) for _ in range(3)]
    z = rng.normal(size=(1500, 3)).cumsum(axis=0) * 0.01
    z[700, 1] = math.nan
    for k in range(z.shape[0]):
        t = k * 1_000_000 + int(rng.integers(0, 100))  # jittered timestamps
        used = bank.update(t, z[k].tolist())
        assert used == (2 if k == 700 else 3)
        for f, v in zip(singles, z[k]):
            f.update(t, float(v))
    for i, f in enumerate(singles):
        assert abs(bank.x[i] - f.x) < 1e-12 and abs(bank.v[i] - f.v) < 1e-9
    assert bank.rejected == [0, 1, 0] and abs(bank.lag_s - singles[0].lag_s) < 1e-4
