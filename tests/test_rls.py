"""Weighted and scaled RLS (eq 18-19): algebra, sign, scaling, forgetting, guards, sigma
calibration and the identifiability figure."""

import warnings

import numpy as np
import pytest

from vdps_hil.identification.rls import WeightedRLS

X_TRUE = np.array([550.0, 2400.0, 2700.0])
X0 = np.array([715.0, 1680.0, 3510.0])  # priors +-30 %


def _batch(x0, sigma0, q, rows):
    """Closed-form minimiser of sum ||Q (b - A x)||^2 + (x - x0)^T P0^-1 (x - x0)."""
    info = np.diag(1.0 / np.asarray(sigma0) ** 2)
    rhs = info @ x0
    for a, b in rows:
        qa, qb = q[:, None] * a, q * b
        info = info + qa.T @ qa
        rhs = rhs + qa.T @ qb
    return np.linalg.solve(info, rhs), info


def _rows(rng, n_rows, noise_sd=0.0, m=3, corr=0.0):
    """Random 3-column regressors with column correlation ``corr`` and b = A x + noise."""
    mix = np.array([[1.0, 0.0, 0.0], [corr, np.sqrt(1 - corr ** 2), 0.0], [corr, 0.0, np.sqrt(1 - corr ** 2)]])
    out = []
    for _ in range(n_rows):
        a = rng.normal(size=(m, 3)) @ mix.T * np.array([1.0, 0.3, 2.0])
        out.append((a, a @ X_TRUE + noise_sd * rng.normal(size=m)))
    return out


@pytest.mark.parametrize("form", ["covariance", "sqrt_information"])
def test_exact_regressors_recover_parameters_to_1e9(rng, form):
    # no noise, no forgetting, nontrivial Q and W; a very weak prior so the data decide
    q = np.array([0.3, 2.0, 0.05])
    w = np.array([1e3, 1e-2, 5.0])
    r = WeightedRLS(X0, 1e6 * X0, q, w, form=form)
    for a, b in _rows(rng, 200):
        assert r.update(a, b)
    assert np.max(np.abs(r.x / X_TRUE - 1.0)) < 1e-9


@pytest.mark.parametrize("form", ["covariance", "sqrt_information"])
def test_rls_equals_batch_weighted_least_squares_with_prior(rng, form):
    # noisy data and an informative prior: RLS must equal the closed-form minimiser (1e-9 rel)
    q = np.array([0.5, 1.0, 2.0])
    sigma0 = 0.3 * X0
    data = _rows(rng, 60, noise_sd=50.0, corr=0.6)
    r = WeightedRLS(X0, sigma0, q, form=form)
    for a, b in data:
        r.update(a, b)
    x_batch, info = _batch(X0, sigma0, q, data)
    assert np.allclose(r.x, x_batch, rtol=1e-9, atol=0)
    assert np.allclose(r.covariance, np.linalg.inv(info), rtol=1e-8, atol=0)


def test_the_two_forms_agree_with_forgetting(rng):
    data = _rows(rng, 300, noise_sd=20.0, corr=0.5)
    rc = WeightedRLS(X0, 0.5 * X0, [1.0, 0.5, 0.2], forgetting=0.97, form="covariance")
    rs = WeightedRLS(X0, 0.5 * X0, [1.0, 0.5, 0.2], forgetting=0.97, form="sqrt_information")
    for a, b in data:
        rc.update(a, b)
        rs.update(a, b)
    assert np.allclose(rc.x, rs.x, rtol=1e-9)
    assert np.allclose(rc.sigma, rs.sigma, rtol=1e-6)
    assert rc.residual_variance == pytest.approx(rs.residual_variance, rel=1e-6)


def test_eq19_as_printed_diverges_and_the_corrected_sign_converges():
    # scalar a = 1, exact data b = x_true; eq 19 literally: x+ = x - P+ a (b - a x)
    p, x_lit, x_fix = 4.0, 0.0, 0.0
    for _ in range(20):
        p = p - p * p / (1.0 + p)
        x_lit = x_lit - p * (1.0 - x_lit)
        x_fix = x_fix + p * (1.0 - x_fix)
    assert abs(x_fix - 1.0) < 0.06 and abs(x_lit - 1.0) > 1.0
    r = WeightedRLS([0.0], [2.0], [1.0], [1.0])
    for _ in range(20):
        r.update([[1.0]], [1.0])
    assert r.x[0] == pytest.approx(x_fix, rel=1e-12)


@pytest.mark.parametrize("form", ["covariance", "sqrt_information"])
def test_scaling_matrix_changes_nothing_but_numerics(rng, form):
    data = _rows(rng, 80, noise_sd=30.0, corr=0.4)
    results = []
    for w in (None, np.ones(3), np.array([1e-3, 1e4, 3.0])):
        r = WeightedRLS(X0, 0.4 * X0, [1.0, 0.1, 3.0], w, form=form)
        for a, b in data:
            r.update(a, b)
        results.append((r.x, r.sigma))
    for x, s in results[1:]:
        assert np.allclose(x, results[0][0], rtol=1e-9)
        assert np.allclose(s, results[0][1], rtol=1e-7)


def test_weighting_changes_the_solution(rng):
    data = _rows(rng, 50, noise_sd=200.0)
    xs = []
    for q in ([1.0, 1.0, 1.0], [1.0, 0.01, 1.0]):
        r = WeightedRLS(X0, 0.4 * X0, q)
        for a, b in data:
            r.update(a, b)
        xs.append(r.x)
    assert not np.allclose(xs[0], xs[1], rtol=1e-6)


def test_forgetting_factor_tracks_a_step_change(rng):
    # the parameters step by +20 % at sample 300; lambda = 0.97 (memory ~ 33 samples) follows
    # to 1 %, lambda = 1 stays > 5 % away (it averages the two segments)
    x_after = 1.2 * X_TRUE
    rf = WeightedRLS(X0, 0.5 * X0, [1.0, 1.0, 1.0], forgetting=0.97)
    r1 = WeightedRLS(X0, 0.5 * X0, [1.0, 1.0, 1.0])
    for k in range(600):
        a = rng.normal(size=(3, 3))
        b = a @ (X_TRUE if k < 300 else x_after) + rng.normal(size=3)
        rf.update(a, b)
        r1.update(a, b)
        if k == 299:
            assert np.max(np.abs(rf.x / X_TRUE - 1)) < 0.01
    assert np.max(np.abs(rf.x / x_after - 1)) < 0.01
    assert np.max(np.abs(r1.x / x_after - 1)) > 0.05


def test_anti_windup_bounds_p_in_unexcited_directions():
    # lambda = 0.9 and only parameter 0 excited: without the bound P_11 would grow 0.9^-k
    r = WeightedRLS([1.0, 1.0], [1.0, 1.0], [1.0], [1.0, 1.0], forgetting=0.9)
    for _ in range(500):
        r.update([[1.0, 0.0]], [2.0])
    assert r.x[0] == pytest.approx(2.0, rel=1e-6)
    assert np.max(np.linalg.eigvalsh(r.covariance_scaled)) <= 1.0 + 1e-12
    assert r.x[1] == 1.0


def test_gating_and_zero_regressors_never_divide_by_zero():
    r = WeightedRLS(X0, 0.5 * X0, [1.0, 1.0, 1.0])
    with np.errstate(all="raise"), warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not r.update(np.ones((3, 3)), np.ones(3), rows=[False, False, False])
        # an all-zero regressor (zero slip, zero steer): S = I, the gain is zero, x unchanged
        assert r.update(np.zeros((3, 3)), np.zeros(3))
        _ = r.sigma, r.identifiability
    assert np.array_equal(r.x, X0)
    assert r.counters.not_excited == 1


def test_nan_rows_are_left_out_and_counted(rng):
    r = WeightedRLS(X0, 0.5 * X0, [1.0, 1.0, 1.0])
    a = rng.normal(size=(3, 3))
    b = a @ X_TRUE
    a[1, 2] = np.nan
    b[2] = np.inf
    assert r.update(a, b)  # row 0 is still used
    assert r.counters.nan_rows == 2 and r.counters.rows_used == 1
    assert np.all(np.isfinite(r.x)) and np.all(np.isfinite(r.covariance))
    assert not r.update(np.full((3, 3), np.nan), np.zeros(3))
    assert r.counters.not_excited == 1 and r.counters.nan_rows == 5


def test_bounds_clamp_and_reject():
    lower, upper = 0.3 * X0, 3.0 * X0
    bad = np.eye(3)
    b = 10.0 * X0  # demands x = 10 x prior, outside the bounds
    rc = WeightedRLS(X0, 1e3 * X0, [1.0] * 3, lower=lower, upper=upper, bounds_mode="clamp")
    assert rc.update(bad, b)
    assert np.allclose(rc.x, upper) and rc.counters.clamped == 1
    rr = WeightedRLS(X0, 1e3 * X0, [1.0] * 3, lower=lower, upper=upper, bounds_mode="reject")
    p_before = rr.covariance
    assert not rr.update(bad, b)
    assert np.array_equal(rr.x, X0) and np.array_equal(rr.covariance, p_before)
    assert rr.counters.rejected == 1 and rr.counters.updates == 0


def test_reset_returns_to_the_prior(rng):
    r = WeightedRLS(X0, 0.5 * X0, [1.0] * 3)
    for a, b in _rows(rng, 10):
        r.update(a, b)
    r.reset()
    assert np.array_equal(r.x, X0) and r.identifiability == 0.0
    assert r.counters.updates == 0 and r.counters.resets == 1
    assert np.allclose(r.sigma, 0.5 * X0)  # prior sigma, unit residual variance


def test_wrong_shapes_and_parameters_are_refused():
    r = WeightedRLS(X0, 0.5 * X0, [1.0] * 3)
    with pytest.raises(ValueError):
        r.update(np.ones((2, 3)), np.ones(2))
    with pytest.raises(ValueError):
        WeightedRLS(X0, 0.5 * X0, [1.0] * 3, forgetting=1.5)
    with pytest.raises(ValueError):
        WeightedRLS(X0, [1.0, 0.0, 1.0], [1.0] * 3)
    with pytest.raises(ValueError):
        WeightedRLS(X0, 0.5 * X0, [1.0] * 3, w=[1.0, 1.0])


def test_identifiability_is_min_eigenvalue_of_weighted_information(rng):
    data = _rows(rng, 40)
    for q in (0.625, 0.125):  # Table 3's first two weightings
        r = WeightedRLS(X0, 0.5 * X0, [q] * 3, np.ones(3))
        for a, b in data:
            r.update(a, b)
        _, info = _batch(X0, np.full(3, np.inf), np.full(3, q), data)
        assert r.identifiability == pytest.approx(np.linalg.eigvalsh(info)[0], rel=1e-10)
    # uniform Q = q I scales it by q^2
    r1 = WeightedRLS(X0, 0.5 * X0, [1.0] * 3)
    r2 = WeightedRLS(X0, 0.5 * X0, [0.2] * 3)
    for a, b in data:
        r1.update(a, b)
        r2.update(a, b)
    assert r2.identifiability == pytest.approx(0.04 * r1.identifiability, rel=1e-10)


def test_consider_covariance_uses_the_least_squares_sensitivity(rng):
    # b depends on a consider parameter theta: b = A x + d theta. J = dx/dtheta by finite difference.
    data = [(a, b, rng.normal(size=3)) for a, b in _rows(rng, 50, noise_sd=10.0)]
    def run(theta):
        r = WeightedRLS(X0, 0.5 * X0, [0.5, 1.0, 2.0], forgetting=0.98)
        for a, b, d in data:
            r.update(a, b + d * theta, db_dtheta=d[:, None])
        return r
    r0, r1 = run(0.0), run(1.0)
    j = r1.x - r0.x  # exact: x is linear in theta
    assert np.allclose(r0.consider_covariance([[4.0]]), 4.0 * np.outer(j, j), rtol=1e-8, atol=1e-12)
    assert np.array_equal(WeightedRLS(X0, X0, [1.0] * 3).consider_covariance([[1.0]]), np.zeros((3, 3)))


# ------------------------------------------------------------------ sigma calibration (MC)
N_SEEDS = 40
COVERAGE_BAND = (0.85, 1.0)  # 95 % expected; 40 seeds -> binomial sd 3.4 %


def _coverage(noise: str, autocorr: bool, n_steps: int = 400) -> np.ndarray:
    """Fraction of seeds with |x - x_true| <= 2 sigma, per parameter, over N_SEEDS seeds, for
    correlated regressor columns (corr 0.8) and white or AR(1) (rho 0.8) equation noise."""
    hits = np.zeros(3)
    for seed in range(N_SEEDS):
        rng = np.random.default_rng(1000 + seed)
        r = WeightedRLS(X0, 0.5 * X0, [0.1] * 3, sigma_autocorr=autocorr)
        phase = rng.uniform(0, 2 * np.pi, size=(3, 3))
        e = np.zeros(3)
        for k in range(n_steps):
            if noise == "white":
                a = rng.normal(size=(3, 3))
                e = 40.0 * rng.normal(size=3)
            else:  # slowly varying regressors (0.25 Hz at 100 Hz), coloured noise
                a = np.sin(2 * np.pi * 0.25 * k / 100.0 * np.array([1.0, 1.3, 1.7]) + phase) \
                    + 0.1 * rng.normal(size=(3, 3))
                e = 0.8 * e + 40.0 * np.sqrt(1 - 0.64) * rng.normal(size=3)
            a[:, 1] = 0.8 * a[:, 0] + 0.6 * a[:, 1]  # correlated columns
            r.update(a, a @ X_TRUE + e)
        hits += np.abs(r.x - X_TRUE) <= 2.0 * r.sigma
    return hits / N_SEEDS


def test_sigma_is_calibrated_for_correlated_regressors_and_white_noise():
    cov = _coverage("white", autocorr=True)
    assert np.all(cov >= COVERAGE_BAND[0]) and np.all(cov <= COVERAGE_BAND[1]), cov


def test_sigma_is_calibrated_for_coloured_noise_only_with_the_autocorrelation_correction():
    cov = _coverage("ar1", autocorr=True)
    assert np.all(cov >= COVERAGE_BAND[0]) and np.all(cov <= COVERAGE_BAND[1]), cov
    cov_plain = _coverage("ar1", autocorr=False)
    assert np.min(cov_plain) < COVERAGE_BAND[0], cov_plain  # the uncorrected sigma is too small
