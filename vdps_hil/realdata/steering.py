"""The steady-state steering response of a real drive: openpilot's learned quantities (steer
ratio, tire stiffness factor, steering angle offset) fitted to the bicycle model, with their
observability against a prior (``steer_response_fit``), and its inputs from the samples and the
pipeline's track (``steer_signals``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vdps_hil.bus.samples import Sample
from vdps_hil.realdata.runs import Track, series

__all__ = ["OPENPILOT_RAV4", "understeer_gradient", "SteerResponseFit", "steer_response_fit", "steer_signals"]


OPENPILOT_RAV4 = {"steer_ratio": 16.88, "tire_stiffness_factor": 0.5533, "mass_kg": 3650 * 0.45359237 + 136.0,
                  "wheelbase_m": 2.65, "center_to_front_m": 0.44 * 2.65,
                  "cornering_stiffness_front_nprad": 121599.4, "cornering_stiffness_rear_nprad": 151033.1}
"""openpilot's starting values for the RAV4 (selfdrive/car/toyota/interface.py: steerRatio 16.88,
tire_stiffness_factor 0.5533, mass 3650 lb + STD_CARGO_KG 136 kg, wheelbase 2.65 m,
centerToFront 0.44 L) and the axle cornering stiffnesses its scale_tire_stiffness gives them
(Civic base 192150 / 202500 N/rad at 1462 kg, CG at 0.4 L)."""


def understeer_gradient(mass_kg: float, l_f_m: float, l_r_m: float, c_f_nprad: float, c_r_nprad: float) -> float:
    """K_us = (m / L) (l_r / C_f - l_f / C_r) [rad / (m/s^2)] of the steady-state bicycle model."""
    L = l_f_m + l_r_m
    return mass_kg / L * (l_r_m / c_f_nprad - l_f_m / c_r_nprad)


@dataclass(frozen=True)
class SteerResponseFit:
    """Least-squares fit of the steady-state bicycle model to a drive (``steer_response_fit``):
    ``theta`` = (p1, p2, p3) with sigmas and covariance, the derived steer ratio, stiffness
    factor and angle offset with sigmas, the information gains and their explanation, and the
    numbers of windows and the speed range used."""

    theta: tuple[float, float, float]
    cov: np.ndarray
    steer_ratio: float
    steer_ratio_sigma: float
    stiffness_factor: float
    stiffness_factor_sigma: float
    angle_offset_deg: float
    angle_offset_sigma_deg: float
    yaw_rate_bias_degps: float
    gains: tuple[float, ...]
    gain_vectors: np.ndarray
    explanations: tuple
    n_windows: int
    speed_range_mps: tuple[float, float]
    steer_range_deg: tuple[float, float]
    residual_sigma: float
    combination: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    """(u_rms [m/s], q = s_R (L + K_us u_rms^2) [m], sigma_q [m]): the steady-state steering
    gain r / delta_sw = u / q at the drive's RMS speed, the combination the drive pins down."""

    def observable(self, gain_threshold: float = 1.0) -> dict[str, bool]:
        """Per quantity: its prior-relative direction is carried by identified directions only
        (|component in the unidentified directions|^2 < 0.5)."""
        weak = self.gain_vectors[:, np.asarray(self.gains) < gain_threshold]
        names = ("steer_ratio_x_wheelbase", "understeer_x_steer_ratio", "angle_offset")
        return {n: bool(np.sum(weak[i] ** 2) < 0.5) for i, n in enumerate(names)}


def steer_response_fit(t_s, speed_mps, steer_wheel_rad, yaw_rate_radps, course_rate_radps, *, wheelbase_m: float,
                       understeer0: float, prior_steer_ratio: float, window_s: float = 1.0,
                       min_speed_mps: float = 5.0, prior_rel_sigma=(0.25, 0.5), prior_offset_sigma_deg: float = 2.0
                       ) -> SteerResponseFit:
    """openpilot's learned quantities (steer ratio s_R, stiffness factor x, steering angle offset
    delta_0) from the steady-state bicycle model, linear in three parameters::

        r = u (delta_sw - delta_0) / (s_R (L + K_us u^2)),   K_us = K_0 / x
        u delta_sw = p1 r + p2 r u^2 + p3 u,   p1 = s_R L,  p2 = s_R K_0 / x,  p3 = delta_0

    ==========  ==========  ===================================================================
    symbol      unit        meaning
    ==========  ==========  ===================================================================
    r           rad/s       yaw rate: the ESC yaw rate minus its bias b_r, b_r = mean over the
                            windows of (r_ESC - course rate of the EKF velocity) (GNSS-based);
                            its variance var(b_r) = var(differences) / N enters the covariance
                            as J_b var(b_r) J_b^T, J_b = d theta / d b_r (central difference)
    u           m/s         speed (EKF); delta_sw [rad] the steering wheel angle (CAN)
    L, K_0      m, rad/(m/s^2)  wheelbase; understeer gradient at x = 1 (model priors)
    ==========  ==========  ===================================================================

    Signals are averaged over ``window_s`` windows (quasi-steady state, nearly independent
    errors); least squares gives theta and Cov = s^2 (A^T A)^-1 + J_b var(b_r) J_b^T (s^2:
    residual variance). The information I = Cov^-1 is compared with a prior (p1, p2 relative sigmas
    ``prior_rel_sigma`` about s_R L and s_R K_0, p3 sigma ``prior_offset_sigma_deg``) as in
    ``observability_report``: gains = eig(S I S), S = diag(prior sigmas); a direction with gain
    < 1 is not identified by the drive (it does not halve the prior variance). s_R = p1 / L,
    x = p1 K_0 / (L p2), delta_0 = p3 (sigmas by first-order propagation)."""
    t = np.asarray(t_s, dtype=float)
    u, sw, r_m, cr = (np.asarray(v, dtype=float) for v in (speed_mps, steer_wheel_rad, yaw_rate_radps,
                                                           course_rate_radps))
    ok = np.isfinite(u + sw + r_m + cr) & (u >= min_speed_mps)
    W = _window_means(t, ok, window_s, (u, r_m, sw, cr))  # columns: u, r_ESC, delta_sw, course rate
    n = W.shape[0]
    d = W[:, 1] - W[:, 3]  # yaw rate minus course rate per window
    bias = float(d.mean())
    var_bias = float(d.var(ddof=1) / n)

    def solve(b):
        rr = W[:, 1] - b
        a_ = np.column_stack([rr, rr * W[:, 0] ** 2, W[:, 0]])
        y_ = W[:, 0] * W[:, 2]
        th, *_ = np.linalg.lstsq(a_, y_, rcond=None)
        return a_, y_, th

    A, y, theta = solve(bias)
    res = y - A @ theta
    s2 = float(res @ res / max(n - 3, 1))
    db = 1e-4
    j_b = (solve(bias + db)[2] - solve(bias - db)[2]) / (2 * db)  # d theta / d bias
    cov = np.linalg.pinv(A.T @ A / s2) + np.outer(j_b, j_b) * var_bias
    info = _without_design_null_space(np.linalg.pinv(cov), A)
    p1, p2, p3 = theta
    sr = p1 / wheelbase_m
    x = p1 * understeer0 / (wheelbase_m * p2) if p2 != 0 else math.inf
    j_x = np.array([understeer0 / (wheelbase_m * p2), -p1 * understeer0 / (wheelbase_m * p2 * p2), 0.0])
    prior = np.array([prior_steer_ratio * wheelbase_m * prior_rel_sigma[0],
                      prior_steer_ratio * understeer0 * prior_rel_sigma[1], math.radians(prior_offset_sigma_deg)])
    gains, vecs, expl = _gains_and_explanations(A, info, prior)
    u2 = float(np.mean(A[:, 2] ** 2))
    jq = np.array([1.0, u2, 0.0])
    comb = (math.sqrt(u2), float(p1 + p2 * u2), float(math.sqrt(max(jq @ cov @ jq, 0.0))))
    return SteerResponseFit(tuple(float(v) for v in theta), cov, float(sr), float(math.sqrt(cov[0, 0]) / wheelbase_m),
                            float(x), float(math.sqrt(max(j_x @ cov @ j_x, 0.0))), float(math.degrees(p3)),
                            float(math.degrees(math.sqrt(cov[2, 2]))), float(math.degrees(bias)),
                            tuple(float(v) for v in gains), vecs, tuple(expl), n,
                            (float(W[:, 0].min()), float(W[:, 0].max())),
                            (float(np.degrees(sw[ok].min())), float(np.degrees(sw[ok].max()))), float(math.sqrt(s2)),
                            comb)


def _window_means(t: np.ndarray, ok: np.ndarray, window_s: float, signals) -> np.ndarray:
    """(windows, len(signals)): each signal's mean over the ``ok`` samples of consecutive
    ``window_s`` windows from the first to the last ``ok`` sample (windows with >= 3 samples)."""
    edges = np.arange(t[ok][0], t[ok][-1] + 1e-9, window_s)
    win = []
    for a, b in zip(edges[:-1], edges[1:]):
        m = ok & (t >= a) & (t < b)
        if m.sum() >= 3:
            win.append(tuple(x[m].mean() for x in signals))
    return np.array(win)


def _without_design_null_space(info: np.ndarray, A: np.ndarray, rel_tol: float = 1e-9) -> np.ndarray:
    """``info`` with the exact null space of the design ``A`` removed: P info P, P = I - V V^T,
    V the parameter directions v with A v = 0 (singular values of the column-normalised A below
    ``rel_tol`` times the largest). A noise-free drive (residual variance at rounding level)
    otherwise turns rounding noise in those directions into information."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0.0] = 1.0
    _, sv, vt = np.linalg.svd(A / scale, full_matrices=False)
    null = vt[sv < rel_tol * sv[0]] / scale  # back to parameter coordinates: A (v_n / S) = 0
    if not null.size:
        return info
    q, _ = np.linalg.qr(null.T)
    p = np.eye(A.shape[1]) - q @ q.T
    return p @ info @ p


def _gains_and_explanations(A: np.ndarray, info: np.ndarray, prior: np.ndarray) -> tuple:
    """(gains, gain vectors, explanations) of ``steer_response_fit``: gains = eig(S I S) with
    S = diag(prior sigmas); the directions with gain < 1 explained, and the exact null space of
    the design matrix A augmented by a constant road bank term (-s_R K_us g sin(phi) u: the
    same column as the offset)."""
    from vdps_hil.estimation.observability_explain import explain_null_space

    g = prior[:, None] * info * prior[None, :]
    gains, vecs = np.linalg.eigh(0.5 * (g + g.T))
    names = ("steer_ratio_x_wheelbase", "understeer_x_steer_ratio", "angle_offset")
    weak = vecs[:, gains < 1.0].T
    expl = list(explain_null_space(weak, names, "is barely seen in the data")) if weak.size else []
    # a constant road bank phi enters as -s_R K_us g sin(phi) u: the same column as the offset
    aug = np.column_stack([A, A[:, 2]])
    _, sv, vt = np.linalg.svd(aug / np.linalg.norm(aug, axis=0), full_matrices=False)
    null = vt[sv < 1e-9 * sv[0]]
    expl += explain_null_space(null, (*names, "road_bank_term"))
    return gains, vecs, expl


def steer_signals(samples: Sequence[Sample], track: Track, *, yaw_kind: str = "imu"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The inputs of ``steer_response_fit`` at the track's times: (t, speed (EKF), steering
    wheel angle (CAN, interpolated), yaw rate (``yaw_kind`` z rate, interpolated), course rate
    d/dt atan2(v_N, v_E) of the EKF velocity)."""
    ts, sw = series(samples, "steer", ("steer_wheel_angle_rad",))
    ty, wz = series(samples, yaw_kind, ("angular_rate_radps_z",))
    t = track.t_s
    v = track.vel_mps
    speed = np.hypot(v[:, 0], v[:, 1])
    course = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
    cr = np.gradient(course, t) if t.size > 1 else np.zeros_like(t)
    return t, speed, np.interp(t, ts, sw[:, 0]), np.interp(t, ty, wz[:, 0]), cr
