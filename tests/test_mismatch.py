"""The model-mismatch test (identification.mismatch): residuals that are what the noise model
predicts pass; a missing term that follows the maneuver fails and is named by its row; the
long-run variance ratio inflates the sigmas only for correlated residuals (fixed seeds)."""

import math

import numpy as np

from vdps_hil.identification.config import StatusConfig
from vdps_hil.identification.mismatch import MismatchMonitor
from vdps_hil.identification.problems import Regressor
from vdps_hil.identification.rls import WeightedRLS

NOISE = 0.5  # row noise sd -> Q = 1 / NOISE
STRICT = StatusConfig(mismatch_variance_max=4.0, mismatch_whiteness_max=0.5)  # Q is the true noise here


def _drive(extra, seed=3, n=3000, cfg=STRICT):
    """Cornering-shaped problem (2 rows, 2 parameters) at 100 Hz: b = A x + noise + extra(t, row)."""
    rng = np.random.default_rng(seed)
    x_true = np.array([2.0, -1.0])
    q = (1.0 / NOISE, 1.0 / NOISE)
    rls = WeightedRLS(np.array([1.0, 1.0]), np.array([5.0, 5.0]), q)
    mon = MismatchMonitor("cornering", cfg, q)
    for k in range(n):
        t = k * 0.01
        a = rng.normal(0.0, 1.0, (2, 2)) + np.array([[math.sin(t), 0.0], [0.0, math.cos(0.7 * t)]])
        b = a @ x_true + rng.normal(0.0, NOISE, 2) + np.array([extra(t, 0), extra(t, 1)])
        reg = Regressor(a, b, np.array([True, True]))
        x0, c0 = rls.x, rls.covariance
        if rls.update(a, b, reg.rows):
            mon.observe(int(round(t * 1e9)), reg, x0, c0)
    return mon


def test_residuals_of_the_right_model_pass_and_keep_the_sigmas():
    mon = _drive(lambda t, i: 0.0)
    tests = mon.tests()
    assert not mon.mismatch and mon.failed_rows == ()
    for t in tests:
        assert t.n == 3000
        assert abs(t.variance - 1.0) < 0.15  # unit variance within its sampling error (n = 3000)
        assert abs(t.whiteness) < 0.3
    assert mon.variance_scale < 1.6


def test_a_missing_term_that_follows_the_maneuver_is_a_mismatch_of_its_row():
    # a slow 0.2 Hz term of 3 noise sd in the lateral row only (a saturating tire, say)
    mon = _drive(lambda t, i: 3.0 * NOISE * math.sin(2 * math.pi * 0.2 * t) if i == 1 else 0.0)
    assert mon.mismatch
    assert mon.failed_rows == ("lateral",)
    lat = {t.name: t for t in mon.tests()}["lateral"]
    assert lat.whiteness > 0.5
    assert mon.variance_scale > 5.0  # the correlated residual carries far less information


def test_shipped_thresholds_flag_a_missing_term_far_above_the_design_noise():
    # the shipped [status] (Q a design weight: variance up to 50 passes, whiteness off)
    small = _drive(lambda t, i: 3.0 * NOISE * math.sin(2 * math.pi * 0.2 * t) if i == 1 else 0.0, cfg=StatusConfig())
    assert not small.mismatch
    big = _drive(lambda t, i: 12.0 * NOISE * math.sin(2 * math.pi * 0.2 * t) if i == 1 else 0.0, cfg=StatusConfig())
    assert big.failed_rows == ("lateral",)


def test_too_few_rows_are_not_tested_and_the_test_can_be_switched_off():
    mon = _drive(lambda t, i: 10.0 * NOISE * math.sin(t), n=150)
    assert not mon.mismatch and mon.variance_scale == 1.0
    off = MismatchMonitor("cornering", StatusConfig(mismatch_test=False), (2.0, 2.0))
    assert not off.mismatch


def test_tests_read_between_observations_follow_every_new_residual():
    # tests() is computed once per change of the residuals: read after every observation it must
    # equal the tests of a monitor read only at the end (a stale cache would keep old counts)
    rng = np.random.default_rng(11)
    q = (1.0 / NOISE, 1.0 / NOISE)
    a_mon, b_mon = MismatchMonitor("cornering", STRICT, q), MismatchMonitor("cornering", STRICT, q)
    x, c = np.array([1.0, 1.0]), np.eye(2)
    seen = []
    for k in range(400):
        a = rng.normal(0.0, 1.0, (2, 2))
        reg = Regressor(a, a @ x + rng.normal(0.0, NOISE + k / 100.0, 2), np.array([True, k % 3 != 0]))
        for mon in (a_mon, b_mon):
            mon.observe(k * 10_000_000, reg, x, c)
        seen.append(a_mon.tests()[1].n)
        a_mon.variance_scale, a_mon.failed_rows
    assert a_mon.tests() == b_mon.tests()
    assert seen[-1] == 266 and seen[:3] == [0, 1, 2]  # row 1 used when k % 3 != 0
    a_mon.reset()
    assert a_mon.tests()[0].n == 0


def test_integrated_autocorrelation_time_counts_the_effective_samples():
    """``_Row.tau_int`` (Sokal's window over the lagged sums kept in a ring): ~1 for white
    residuals, ~20 for a 20-sample moving average of white noise (N / N_eff of its mean), the
    lagged sums equal to the direct ones; None below 4 MAX_LAG residuals."""
    import numpy as np

    from vdps_hil.identification.mismatch import MAX_LAG, _Row
    rng = np.random.default_rng(11)
    white, ma = _Row(), _Row()
    x = rng.normal(size=4000)
    y = np.convolve(rng.normal(size=4019), np.ones(20) / 20.0, mode="valid")
    for a, b in zip(x, y):
        white.add(0, float(a))
        ma.add(0, float(b))
    direct = np.array([x[k:] @ x[:-k] for k in range(1, MAX_LAG + 1)])
    assert np.allclose(white.lag_sums[1:], direct, rtol=1e-12, atol=1e-9)
    assert 0.8 < white.tau_int() < 1.3
    assert 15.0 < ma.tau_int() < 25.0
    short = _Row()
    for a in x[:4 * MAX_LAG - 1]:
        short.add(0, float(a))
    assert short.tau_int() is None


def test_bin_tests_read_the_growing_buffers_exactly_as_the_bin_lists():
    """The whiteness and long-run tests read the bin means from buffers that grow by doubling (an
    hour of 0.5 s bins is 7200 of them, read at every status): at every step they equal, bit for
    bit, the same formulas on the means and counts kept as plain lists (open bin last), through
    several doublings and with bins of unequal counts; None below 4 bins."""
    import numpy as np

    from vdps_hil.identification.mismatch import _Row
    rng = np.random.default_rng(23)
    row, means, counts = _Row(), [], []
    k_bin, acc, n_in = 0, 0.0, 0
    checked = 0
    for step in range(3000):
        if rng.random() < 0.3:  # a new bin starts with this residual
            if n_in:
                means.append(acc / n_in)
                counts.append(n_in)
            k_bin, acc, n_in = k_bin + 1, 0.0, 0
        r = float(rng.normal(0.3, 1.0))
        row.add(k_bin, r)
        acc += r
        n_in += 1
        m = np.asarray(means + [acc / n_in], dtype=float)
        c = np.asarray(counts + [n_in], dtype=float)
        if len(m) < 4:
            assert row.whiteness() is None and row.long_run() is None
            continue
        a = m - float(np.mean(m))
        white = float(a[1:] @ a[:-1]) / float(a @ a)
        rbar = row.s1 / row.n
        var = (row.s2 - row.n * rbar * rbar) / (row.n - 1)
        long_run = float(np.sum(c * (m - rbar) ** 2) / (len(m) - 1)) / var
        assert row.whiteness() == white and row.long_run() == long_run
        checked += 1
    assert checked > 2900 and len(row.means) >= 1024  # the buffers doubled several times
