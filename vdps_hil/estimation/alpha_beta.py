"""Alpha-beta filters (paper eq 12) for rates and their derivatives.

Eq 12 with the state x_a = [x, x_dot] of one signal sampled every T_s::

    x_a(k+1) = A x_a(k) + K (z(k+1) - z_hat(k+1)),   A = [[1, T_s], [0, 1]],
    z_hat(k+1) = [1, 0] A x_a(k),                    K = [alpha, beta / T_s]^T

(identical to a g-h filter with g = alpha, h = beta; filterpy's ``GHFilter`` is the test oracle).

Gains from a bandwidth (what the configuration gives per signal), *critically damped*: both
closed-loop poles at z = theta = exp(-2 pi f_c T_s), i.e. at s = -2 pi f_c::

    alpha = 1 - theta^2,   beta = (1 - theta)^2

(the characteristic polynomial z^2 - (2 - alpha - beta) z + (1 - alpha) equals (z - theta)^2).

Gains from noise figures (*Kalata*): with the tracking index L = sigma_w T_s^2 / sigma_v
(sigma_w: white acceleration noise, piecewise constant over T_s; sigma_v: measurement noise) the
steady-state Kalman filter of the constant-velocity model has::

    alpha = -(L^2 + 8 L - (L + 4) sqrt(L^2 + 8 L)) / 8,   beta = (L^2 + 4 L - L sqrt(L^2 + 8 L)) / 4

(filterpy's ``KalmanFilter`` run to steady state is the test oracle).

Lag. The value channel is a type-2 loop: no steady-state lag for a ramp. The derivative channel
lags a linearly changing true derivative by::

    tau_d = T_s (alpha / beta - 1/2)          (~ 2 / (2 pi f_c) for the critically damped gains)

derived from the steady state with z = a t^2 / 2: the innovation settles at r = a T_s^2 / beta
and the derivative error at a T_s (1/2 - alpha / beta). ``derivative_lag_s`` reports it and
``frequency_response`` gives the full transfer functions.

==========  =====  ==============================================================
symbol      unit   meaning
==========  =====  ==============================================================
T_s         s      sampling period
f_c         Hz     bandwidth (closed-loop pole frequency) per signal
alpha/beta  -      gains of eq 12
tau_d       s      lag of the derivative estimate
==========  =====  ==============================================================
"""

from __future__ import annotations

import cmath
import math


def critically_damped_gains(bandwidth_hz: float, dt_s: float) -> tuple[float, float]:
    """(alpha, beta) with the double closed-loop pole at s = -2 pi f_c (module docstring)."""
    if not (bandwidth_hz > 0 and math.isfinite(bandwidth_hz)):
        raise ValueError(f"bandwidth must be a positive finite number of Hz, got {bandwidth_hz!r}")
    if not (dt_s > 0 and math.isfinite(dt_s)):
        raise ValueError(f"sampling period must be positive and finite, got {dt_s!r}")
    theta = math.exp(-2.0 * math.pi * bandwidth_hz * dt_s)
    return 1.0 - theta * theta, (1.0 - theta) ** 2


def kalata_gains(tracking_index: float) -> tuple[float, float]:
    """(alpha, beta) of the steady-state Kalman filter for the tracking index L (Kalata)."""
    lam = float(tracking_index)
    if not (lam > 0 and math.isfinite(lam)):
        raise ValueError(f"tracking index must be positive and finite, got {tracking_index!r}")
    r = math.sqrt(lam * lam + 8.0 * lam)
    alpha = -(lam * lam + 8.0 * lam - (lam + 4.0) * r) / 8.0
    beta = (lam * lam + 4.0 * lam - lam * r) / 4.0
    return alpha, beta


def tracking_index(accel_sigma: float, meas_sigma: float, dt_s: float) -> float:
    """L = sigma_w T_s^2 / sigma_v."""
    return accel_sigma * dt_s * dt_s / meas_sigma


def derivative_lag_s(alpha: float, beta: float, dt_s: float) -> float:
    """tau_d = T_s (alpha / beta - 1/2): lag of the derivative estimate (module docstring)."""
    return dt_s * (alpha / beta - 0.5)


def frequency_response(alpha: float, beta: float, dt_s: float, freq_hz: float) -> tuple[complex, complex]:
    """(H_x, H_d) at ``freq_hz``: value estimate / input, and derivative estimate / true
    derivative (j w times the input), from the closed loop x(k+1) = (I - K c) A x(k) + K z(k+1)."""
    w = 2.0 * math.pi * freq_hz
    zf = cmath.exp(1j * w * dt_s)
    # M = (I - K c) A with K = [alpha, beta/T], c = [1, 0], A = [[1, T], [0, 1]]
    g = beta / dt_s
    m11, m12 = 1.0 - alpha, (1.0 - alpha) * dt_s
    m21, m22 = -g, 1.0 - g * dt_s
    # (zI - M)^-1 K zf
    a11, a12, a21, a22 = zf - m11, -m12, -m21, zf - m22
    det = a11 * a22 - a12 * a21
    x = (a22 * alpha - a12 * g) / det * zf
    v = (-a21 * alpha + a11 * g) / det * zf
    jw = 1j * w if w != 0 else 1e-300j
    return x, v / jw


def bandwidth_3db_hz(alpha: float, beta: float, dt_s: float) -> float:
    """Frequency where |H_x| first falls to 1/sqrt(2) (bisection on (0, Nyquist))."""
    target = 1.0 / math.sqrt(2.0)
    f_nyq = 0.5 / dt_s
    grid = [f_nyq * k / 2000.0 for k in range(1, 2001)]
    prev = 1e-9
    for f in grid:
        if abs(frequency_response(alpha, beta, dt_s, f)[0]) < target:
            lo, hi = prev, f
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if abs(frequency_response(alpha, beta, dt_s, mid)[0]) < target:
                    hi = mid
                else:
                    lo = mid
            return 0.5 * (lo + hi)
        prev = f
    return f_nyq


class AlphaBetaFilter:
    """Eq 12 with a fixed sampling period. The first ``update`` initialises x = z, x_dot = v0
    unless ``x0`` is given."""

    __slots__ = ("alpha", "beta", "dt_s", "x", "v", "initialized")

    def __init__(self, alpha: float, beta: float, dt_s: float, x0: float | None = None, v0: float = 0.0):
        if not (0.0 < alpha <= 1.0 and 0.0 < beta <= 2.0):
            raise ValueError(f"alpha must be in (0, 1] and beta in (0, 2], got {alpha!r}, {beta!r}")
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise ValueError(f"sampling period must be positive and finite, got {dt_s!r}")
        self.alpha, self.beta, self.dt_s = float(alpha), float(beta), float(dt_s)
        self.initialized = x0 is not None
        self.x = float(x0) if x0 is not None else 0.0
        self.v = float(v0)

    @classmethod
    def from_bandwidth(cls, bandwidth_hz: float, dt_s: float, **kw) -> "AlphaBetaFilter":
        return cls(*critically_damped_gains(bandwidth_hz, dt_s), dt_s, **kw)

    def update(self, z: float) -> tuple[float, float]:
        """One step of eq 12 with measurement z; returns (x, x_dot)."""
        if not self.initialized:
            self.x, self.initialized = float(z), True
            return self.x, self.v
        xp = self.x + self.dt_s * self.v
        r = z - xp
        self.x = xp + self.alpha * r
        self.v = self.v + (self.beta / self.dt_s) * r
        return self.x, self.v

    @property
    def derivative_lag_s(self) -> float:
        return derivative_lag_s(self.alpha, self.beta, self.dt_s)

    def frequency_response(self, freq_hz: float) -> tuple[complex, complex]:
        return frequency_response(self.alpha, self.beta, self.dt_s, freq_hz)

    def bandwidth_3db_hz(self) -> float:
        return bandwidth_3db_hz(self.alpha, self.beta, self.dt_s)


class TimedAlphaBeta:
    """Eq 12 on time-stamped samples: T_s is the actual interval, the critically damped gains
    are re-derived from ``bandwidth_hz`` when it changes (cached per ns interval). A gap longer
    than ``max_gap_s`` restarts the filter at the new sample; non-finite samples are skipped and
    counted (``rejected``)."""

    __slots__ = ("bandwidth_hz", "max_gap_ns", "x", "v", "t_ns", "rejected", "restarts", "_gains", "_dt_s")

    def __init__(self, bandwidth_hz: float, max_gap_s: float = 0.5):
        critically_damped_gains(bandwidth_hz, 1e-3)  # validates
        self.bandwidth_hz = float(bandwidth_hz)
        self.max_gap_ns = int(round(max_gap_s * 1e9))
        self.x = math.nan
        self.v = math.nan
        self.t_ns: int | None = None
        self.rejected = 0
        self.restarts = 0
        self._gains: dict[int, tuple[float, float, float]] = {}
        self._dt_s = math.nan

    def update(self, t_ns: int, z: float) -> bool:
        """Feed sample z at t_ns; False if it was rejected (non-finite or not after the last)."""
        if not math.isfinite(z):
            self.rejected += 1
            return False
        t0 = self.t_ns
        if t0 is None or t_ns - t0 > self.max_gap_ns:
            if t0 is not None:
                self.restarts += 1
            self.x, self.v, self.t_ns = z, 0.0, t_ns
            return True
        d = t_ns - t0
        if d <= 0:
            self.rejected += 1
            return False
        g = self._gains.get(d)
        if g is None:
            dt = d * 1e-9
            a, b = critically_damped_gains(self.bandwidth_hz, dt)
            g = (a, b / dt, dt)
            if len(self._gains) < 256:
                self._gains[d] = g
        a, bt, dt = g
        xp = self.x + dt * self.v
        r = z - xp
        self.x = xp + a * r
        self.v += bt * r
        self.t_ns = t_ns
        self._dt_s = dt
        return True

    @property
    def lag_s(self) -> float:
        """Derivative lag at the last sampling period (NaN before two samples)."""
        if not math.isfinite(self._dt_s):
            return math.nan
        a, b = critically_damped_gains(self.bandwidth_hz, self._dt_s)
        return derivative_lag_s(a, b, self._dt_s)


class TimedAlphaBetaBank:
    """``n`` signals sampled together (gyro axes, four wheels, four corners): each is a
    ``TimedAlphaBeta`` with its own state and time, sharing the bandwidth and the gain cache
    (one call per sample instead of n). ``rejected[i]`` counts skipped non-finite values."""

    __slots__ = ("bandwidth_hz", "max_gap_ns", "x", "v", "t", "rejected", "restarts", "_gains", "_lag_s", "_all")

    def __init__(self, n: int, bandwidth_hz: float, max_gap_s: float = 0.5):
        critically_damped_gains(bandwidth_hz, 1e-3)  # validates
        self.bandwidth_hz = float(bandwidth_hz)
        self.max_gap_ns = int(round(max_gap_s * 1e9))
        self.x = [math.nan] * n
        self.v = [math.nan] * n
        self.t: list[int | None] = [None] * n
        self.rejected = [0] * n
        self.restarts = 0
        self._gains: dict[int, tuple[float, float, float, float]] = {}  # ns interval -> (alpha, beta/T, T, lag)
        self._lag_s = math.nan
        self._all = range(n)

    def update(self, t_ns: int, values, indices=None) -> int:
        """Feed one value per signal (NaN: skipped for that signal); returns how many were used.
        ``indices``: the signals ``values`` belong to when a sample carries only some of them
        (the others are left alone, not counted as rejected)."""
        used = 0
        xs, vs, ts, gains, max_gap = self.x, self.v, self.t, self._gains, self.max_gap_ns
        g = None  # the gains of the last filter step, if any
        d_last = None  # the interval of g: the signals of a bank are mostly sampled together
        for i, z in zip(self._all if indices is None else indices, values):
            if z - z != 0.0:  # NaN or +-inf
                self.rejected[i] += 1
                continue
            t0 = ts[i]
            if t0 is None or t_ns - t0 > max_gap:
                if t0 is not None:
                    self.restarts += 1
                xs[i], vs[i], ts[i] = z, 0.0, t_ns
                used += 1
                continue
            d = t_ns - t0
            if d <= 0:
                self.rejected[i] += 1
                continue
            if d != d_last:
                g = gains.get(d)
                if g is None:
                    g = self._new_gains(d)
                d_last = d
            a, bt, dt, _ = g
            v = vs[i]
            xp = xs[i] + dt * v
            r = z - xp
            xs[i] = xp + a * r
            vs[i] = v + bt * r
            ts[i] = t_ns
            used += 1
        if g is not None:
            self._lag_s = g[3]
        return used

    def _new_gains(self, d_ns: int) -> tuple[float, float, float, float]:
        """(alpha, beta / T, T, lag) of the interval ``d_ns``, kept in the cache while it has room."""
        dt = d_ns * 1e-9
        a, b = critically_damped_gains(self.bandwidth_hz, dt)
        g = (a, b / dt, dt, derivative_lag_s(a, b, dt))
        if len(self._gains) < 256:
            self._gains[d_ns] = g
        return g

    @property
    def lag_s(self) -> float:
        """Derivative lag at the sampling period of the last filter step (NaN before one)."""
        return self._lag_s
