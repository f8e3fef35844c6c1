"""Innovation monitor of the absolute aiding (GNSS position, velocity, attitude): the rule that
keeps the gate from locking the filter out of its own corrections, and the consistency that
makes an estimate fit to warn on.

Lock-out rule ("inflate and accept"; PX4's EKF2 resets the states a sensor observes once its
innovations have failed for a timeout, the same idea): the EKF gates an update whose NIS
exceeds the chi-square quantile (``ekf`` module docstring). When ``inflate_after_gated``
consecutive updates of one aiding kind are gated, the filter is inconsistent with that sensor,
not the sensor with the filter (one bad fix is gated, a run of them means the state is off).
Then the variances of the states the kind observes are raised by the innovation,

    sigma_i^2 <- P_ii + max_j nu_j^2        (positions: nu [m]; attitude: nu [rad];
                                              velocity: |nu_speed| + speed |nu_course| [m/s])

their cross-covariances dropped (``MultiRateEKF.reacquire``, the values kept), and the same
measurement is applied again: it now passes the gate and pulls the state back (counted
``inflations``). A consistent filter gates 3 updates in a row with probability (1e-4)^3.

Consistency (``consistent``): the estimate is consistent with the measurements while, for each
aiding kind that updated within ``stale_s``, the NIS of its last ``window`` updates
(accepted or gated; fewer at the start) sum to at most the chi-square ``nis_probability``
quantile of their summed degrees of freedom (a consistent filter: sum NIS ~ chi2(sum dof)). One
marginally gated fix among small ones passes; a run of large innovations, as after an IMU
outage or before an inflation has been worked off, does not. The warning is valid only then (``pipeline.node``); it
returns to valid when the innovations are accepted and small again.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from vdps_hil.estimation.chi2 import chi2_quantile
from vdps_hil.estimation.observations import ObsKind
from vdps_hil.estimation.states import States

__all__ = ["AIDING_KINDS", "AidingChecks", "AidingMonitor", "health"]

AIDING_KINDS = (ObsKind.GNSS_POS, ObsKind.GNSS_VEL, ObsKind.GNSS_ATT)

_OBSERVED = {ObsKind.GNSS_POS: (States.X_G, States.Y_G, States.Z_G),
             ObsKind.GNSS_VEL: (States.XDOT_G, States.YDOT_G),
             ObsKind.GNSS_ATT: (States.PHI_G, States.THETA_G, States.PSI_G)}
"""The full-vector states each aiding kind observes (and the inflation raises)."""


@dataclass(frozen=True)
class AidingChecks:
    """Settings of the aiding monitor (module docstring)."""

    inflate_after_gated: int = 3  # 0: never inflate
    window: int = 3
    stale_s: float = 1.0
    nis_probability: float = 0.999

    def __post_init__(self):
        for name in ("inflate_after_gated", "window"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (0 if name == "inflate_after_gated" else 1):
                raise ValueError(f"AidingChecks.{name} must be an integer >= {0 if name[0] == 'i' else 1}, got {v!r}")
        if not (isinstance(self.stale_s, (int, float)) and math.isfinite(self.stale_s) and self.stale_s > 0):
            raise ValueError(f"AidingChecks.stale_s must be a positive finite number, got {self.stale_s!r}")
        if not 0.0 < self.nis_probability < 1.0:
            raise ValueError(f"AidingChecks.nis_probability must be in (0, 1), got {self.nis_probability!r}")


class AidingMonitor:
    """Gated runs, inflation and consistency of the aiding kinds (module docstring)."""

    def __init__(self, checks: AidingChecks | None = None):
        self.checks = c = checks or AidingChecks()
        self._stale_ns = int(round(c.stale_s * 1e9))
        self._gated = dict.fromkeys(AIDING_KINDS, 0)
        self._recent = {k: deque(maxlen=c.window) for k in AIDING_KINDS}  # (NIS, dof)
        self._last_t = dict.fromkeys(AIDING_KINDS, None)
        self._limits: dict[int, float] = {}
        self.inflations = 0

    def observe(self, res) -> bool:
        """Record an update result of any kind; True when it is an aiding update gated for the
        ``inflate_after_gated``-th time in a row (the caller inflates and re-applies it)."""
        k = res.kind
        if k not in self._gated or res.status not in ("accepted", "gated"):
            return False
        self._last_t[k] = res.t_ns
        ok = res.status == "accepted"
        if res.dof and math.isfinite(res.nis):
            self._recent[k].append((res.nis, res.dof))
        if ok:
            self._gated[k] = 0
            return False
        self._gated[k] += 1
        n = self.checks.inflate_after_gated
        return bool(n) and self._gated[k] >= n

    def inflation(self, res, x_full, P_full) -> dict:
        """{full index: (value, sigma)} raising the observed states of ``res.kind`` by its
        innovation (module docstring); resets the kind's gated run (counted ``inflations``)."""
        k = res.kind
        nu = [abs(v) for v in res.innovation if math.isfinite(v)]
        if k == ObsKind.GNSS_VEL and len(nu) > 1:
            speed = math.hypot(float(x_full[States.XDOT_G]), float(x_full[States.YDOT_G]))
            a = nu[0] + speed * nu[1]
        else:
            a = max(nu, default=0.0)
        self._gated[k] = 0
        self.inflations += 1
        return {s: (float(x_full[s]), math.sqrt(float(P_full[s, s]) + a * a)) for s in _OBSERVED[k]}

    def reset(self) -> None:
        """Forget the windows (a new initialisation)."""
        for k in AIDING_KINDS:
            self._gated[k] = 0
            self._recent[k].clear()
            self._last_t[k] = None

    def consistent(self, t_ns: int) -> bool:
        """True while the recent aiding innovations are accepted and small (module docstring)."""
        for k in AIDING_KINDS:
            last = self._last_t[k]
            if last is None or t_ns - last > self._stale_ns:
                continue
            rec = self._recent[k]
            dof = sum(d for _, d in rec)
            if dof and sum(v for v, _ in rec) > self._nis_limit(dof):
                return False
        return True

    def _nis_limit(self, n: int) -> float:
        lim = self._limits.get(n)
        if lim is None:
            lim = self._limits[n] = chi2_quantile(self.checks.nis_probability, n)
        return lim


def health(imu_monitor, aiding_monitor: AidingMonitor, t_ns: int) -> str | None:
    """Why an estimate at ``t_ns`` is not fit to warn on, or None: "imu_missing" (no accepted
    IMU sample within the timeout), "imu_fault" (within ``ImuChecks.settle_s`` of an IMU
    fault: a gap closed, a sample rejected), "inconsistent" (the aiding innovations, above)."""
    if imu_monitor.missing(t_ns):
        return "imu_missing"
    if imu_monitor.fault_age_ns(t_ns) < imu_monitor.checks.settle_s * 1e9:
        return "imu_fault"
    return None if aiding_monitor.consistent(t_ns) else "inconsistent"
