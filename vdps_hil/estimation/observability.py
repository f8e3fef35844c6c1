"""Numerical observability of the linearised filter over a window.

For the updates k = 1..K in a window starting at t_0, with Phi(t_k, t_0) the product of the
predict transitions and H_k, R_k the update's Jacobian and noise, the whitened, scaled
observability matrix is::

    O = [ R_1^-1/2 H_1 Phi(t_1, t_0) ; ... ; R_K^-1/2 H_K Phi(t_K, t_0) ] D

with D = diag(state scales) (default: 1 m, 1 m/s, 0.01 rad), so that every column is expressed
in a typical uncertainty of its state and every row in its measurement noise. With the singular
values s_1 >= ... >= s_n of O, the numerical rank is the number of s_i > rtol s_1 (``rtol``
default 1e-6). The right singular vectors of the remaining s_i span the unobservable
directions; a state is reported *unobservable* when its squared component in that null space
(its "participation", 0..1) exceeds ``participation_threshold`` (default 0.5). The null-space
basis itself (rows, scaled coordinates) is kept in ``ObservabilityReport.null_space`` so the
reasons can be derived from it (``observability_explain.explain_null_space``).

``ObservabilityWindow`` collects the blocks from an EKF's hooks; ``ObservabilityWindows`` cuts a
drive into consecutive windows of the pipeline's ``observability_window_s`` with one report each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vdps_hil.estimation.states import StateLayout

DEFAULT_RTOL = 1e-6
DEFAULT_PARTICIPATION = 0.5


def default_scales(layout: StateLayout) -> np.ndarray:
    """1 m for positions, 1 m/s for velocities, 0.01 rad for angles (filter layout); augmented
    states: 1e-3 rad/s gyro bias, 0.01 m/s^2 accelerometer bias, 0.01 wheel-speed scale."""
    full = np.array([1.0] * 3 + [1.0] * 3 + [0.01] * 6 + [1e-3] * 3 + [0.01] * 3 + [0.01])
    return full[layout.full_index]


@dataclass(frozen=True)
class ObservabilityReport:
    """Numerical rank of O (module docstring) and the unobservable states by name."""

    rank: int
    n_states: int
    singular_values: tuple[float, ...]
    unobservable: tuple[str, ...]
    participation: dict
    rows: int
    rtol: float
    null_space: tuple = ()  # orthonormal basis of the unobservable directions (rows, scaled coordinates)

    @property
    def full_rank(self) -> bool:
        return self.rank == self.n_states

    def to_json(self) -> dict:
        return {"rank": self.rank, "n_states": self.n_states, "rows": self.rows, "rtol": self.rtol,
                "singular_values": list(self.singular_values), "unobservable": list(self.unobservable),
                "participation": dict(self.participation)}


def observability_rank(blocks, state_names, scales=None, rtol: float = DEFAULT_RTOL,
                       participation_threshold: float = DEFAULT_PARTICIPATION) -> ObservabilityReport:
    """Rank and unobservable states of the stacked blocks R_k^-1/2 H_k Phi(t_k, t_0) (each m_k x n).

    ``scales`` multiplies the columns (state scales, D above)."""
    names = tuple(state_names)
    n = len(names)
    rows = [np.atleast_2d(np.asarray(b, dtype=float)) for b in blocks]
    for b in rows:
        if b.shape[1] != n:
            raise ValueError(f"observability block has {b.shape[1]} columns, expected {n}")
    if not rows:
        return ObservabilityReport(0, n, tuple([0.0] * n), names, {nm: 1.0 for nm in names}, 0, rtol,
                                   tuple(tuple(float(v) for v in row) for row in np.eye(n)))
    o = np.vstack(rows)
    if scales is not None:
        o = o * np.asarray(scales, dtype=float)[None, :]
    _, s, vt = np.linalg.svd(o, full_matrices=o.shape[0] < n)  # economy size unless fewer rows than states
    s_full = np.zeros(n)
    s_full[: s.size] = s
    smax = s_full[0] if s_full.size else 0.0
    rank = int(np.sum(s_full > rtol * smax)) if smax > 0 else 0
    null = vt[rank:]
    part = (null ** 2).sum(axis=0) if null.size else np.zeros(n)
    unobs = tuple(nm for nm, p in zip(names, part) if p > participation_threshold)
    return ObservabilityReport(rank, n, tuple(float(v) for v in s_full), unobs,
                               {nm: float(p) for nm, p in zip(names, part)}, o.shape[0], rtol,
                               tuple(tuple(float(v) for v in row) for row in null))


class ObservabilityWindow:
    """Collects Phi and (H, R) from an EKF (``attach``) and reports per window.

    ``on_predict(Phi)`` accumulates Phi(t, t_0); ``on_update(H, R)`` appends
    R^-1/2 H Phi(t, t_0). ``report()`` evaluates the window; ``restart()`` begins a new one."""

    def __init__(self, state_names, scales=None, rtol: float = DEFAULT_RTOL,
                 participation_threshold: float = DEFAULT_PARTICIPATION):
        self.names = tuple(state_names)
        n = len(self.names)
        self.scales = np.ones(n) if scales is None else np.asarray(scales, dtype=float)
        if self.scales.shape != (n,):
            raise ValueError(f"scales must have shape ({n},), got {self.scales.shape}")
        self.rtol = rtol
        self.threshold = participation_threshold
        self._phi = np.eye(n)
        self._blocks: list[np.ndarray] = []
        self._whiteners: dict[tuple, np.ndarray] = {}  # R (shape, dtype, bytes) -> chol(R^-1)

    @classmethod
    def for_layout(cls, layout: StateLayout, **kw) -> "ObservabilityWindow":
        """Names and default scales of an EKF layout."""
        return cls(layout.names, kw.pop("scales", default_scales(layout)), **kw)

    def attach(self, ekf) -> "ObservabilityWindow":
        ekf.on_predict = self.on_predict
        ekf.on_update = self.on_update
        return self

    def restart(self) -> None:
        self._phi = np.eye(len(self.names))
        self._blocks = []

    def on_predict(self, phi: np.ndarray) -> None:
        self._phi = phi @ self._phi

    def on_update(self, H: np.ndarray, R: np.ndarray) -> None:
        key = (R.shape, R.dtype.str, R.tobytes())  # most updates repeat a few noise matrices: whiten once each
        w = self._whiteners.get(key)
        if w is None:
            if len(self._whiteners) > 64:
                self._whiteners.clear()
            # w w^T = R^-1 -> w^T H is whitened
            w = self._whiteners[key] = np.linalg.cholesky(np.linalg.inv(R))
        self._blocks.append(w.T @ H @ self._phi)

    @property
    def rows(self) -> int:
        return sum(b.shape[0] for b in self._blocks)

    def report(self) -> ObservabilityReport:
        return observability_rank(self._blocks, self.names, self.scales, self.rtol, self.threshold)


class ObservabilityWindows:
    """Consecutive windows of ``window_ns`` over an EKF's predicts and updates (the pipeline's
    ``observability_window_s``): ``tick(t)`` after each predict starts the first window or, once
    ``window_ns`` have passed, closes the window with its report and starts the next;
    ``restart()`` drops the window in progress (after a filter reset), ``forget_start()``
    makes the next tick start a new one (after an initialisation)."""

    def __init__(self, layout: StateLayout, window_ns: int, ekf):
        self._window = ObservabilityWindow.for_layout(layout).attach(ekf)
        self._window_ns = window_ns
        self._t0: int | None = None
        self._reports: list[tuple[int, int, ObservabilityReport]] = []

    @property
    def reports(self) -> tuple[tuple[int, int, ObservabilityReport], ...]:
        """(t_start_ns, t_end_ns, report) per completed window."""
        return tuple(self._reports)

    def now(self) -> ObservabilityReport:
        """Report of the window in progress."""
        return self._window.report()

    def tick(self, t: int) -> None:
        if self._t0 is None:
            self._t0 = t
            self._window.restart()
        elif t - self._t0 >= self._window_ns:
            self._reports.append((self._t0, t, self._window.report()))
            self._t0 = t
            self._window.restart()

    def restart(self) -> None:
        self._window.restart()
        self._t0 = None

    def forget_start(self) -> None:
        self._t0 = None
