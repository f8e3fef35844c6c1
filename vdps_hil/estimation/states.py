"""Named EKF states (paper eq 7) and the configurable filter layout.

The paper's state vector (eq 7)::

    x = [x_g, y_g, z_g, xdot_g, ydot_g, zdot_g, phi_g, theta_g, psi_g, phi_r, theta_r, psi_v]

=========  =====  ======  ===============================================================
index      name   unit    meaning (frames and signs: ``vdps_hil.conventions``)
=========  =====  ======  ===============================================================
0..2       X_G..  m       CG position in the global ENU frame {g}
3..5       XDOT_G m/s     CG velocity in {g}
6          PHI_G  rad     absolute roll (right side down positive)
7          THETA_G rad    absolute pitch (nose up positive, eq 1 as printed)
8          PSI_G  rad     absolute yaw (CCW from East)
9          PHI_R  rad     road bank (rotation about the road x axis, eq 2)
10         THETA_R rad    road grade (rotation about the global y axis, eq 2; < 0 downhill)
11         PSI_V  rad     vehicle yaw relative to the road frame (eq 3)
=========  =====  ======  ===============================================================

The *full* vector above is what every process and observation function in this package is
written for. The *filter* vector is a subset chosen by configuration (:class:`StateLayout`):

* ``psi_v`` is a filter state only in the paper-faithful variant of correction (a). With the
  road curve angle psi_r = 0, eq 4 fixes psi_v from the other five angles
  (C_r^v = C_g^v (C_g^r)^T), so the corrected filter *derives* it:
  psi_v = atan2(C_r^v[0,1], C_r^v[0,0]) (``kinematics.vehicle_angles_eq4``).
* Without suspension sensors nothing observes the road angles (section 3.2); the layout then
  fixes phi_r = theta_r = 0 and psi_v = psi_g.

``StateLayout.expand`` maps a filter vector to the full vector and returns
E = d x_full / d x_filter (12 x n) so that H_filter = H_full E and P_full = E P E^T.

Augmented states (not in eq 7; optional, for real sensors, ``AugStates``)::

    x_ext = [x_full (12), b_g (3), b_a (3), k_w]       (N_EXT = 19)

=========  =====================  ======  ======================================================
index      name                   unit    meaning
=========  =====================  ======  ======================================================
12..14     gyro_bias_{x,y,z}      rad/s   gyro bias: w_b = w_meas - b_g
15..17     accel_bias_{x,y,z}     m/s^2   accelerometer bias: f_b = f_meas - b_a
18         wheel_speed_scale      -       omega_i r_0 = (1 + k_w) v_i: rolling-radius error of
                                          the model file's r_0 (k_w = r_0 / r_true - 1)
=========  =====================  ======  ======================================================

A layout carries the bias axes the IMU has (an ESC cluster: b_g,z, b_a,x, b_a,y; a 6-axis IMU:
all six) when configured; ``expand(x, ext=True)`` gives the N_EXT vector and E (N_EXT x n);
without ``ext`` the first 12 rows only (what the eq-9 models and the observability report use).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

N_FULL = 12
N_EXT = 19


class States(enum.IntEnum):
    """Index of each state in the full vector of eq 7 (openpilot ``car_kf.States`` style)."""

    X_G = 0
    Y_G = 1
    Z_G = 2
    XDOT_G = 3
    YDOT_G = 4
    ZDOT_G = 5
    PHI_G = 6
    THETA_G = 7
    PSI_G = 8
    PHI_R = 9
    THETA_R = 10
    PSI_V = 11


class AugStates(enum.IntEnum):
    """Index of the augmented states in the extended vector (module docstring)."""

    BG_X = 12
    BG_Y = 13
    BG_Z = 14
    BA_X = 15
    BA_Y = 16
    BA_Z = 17
    WHEEL_SCALE = 18


GYRO_BIAS = slice(12, 15)
ACCEL_BIAS = slice(15, 18)

POSITION = slice(0, 3)
VELOCITY = slice(3, 6)
ATTITUDE = slice(6, 9)
ROAD = slice(9, 11)
ANGLES5 = slice(6, 11)  # phi_g, theta_g, psi_g, phi_r, theta_r: the five independent angles

STATE_NAMES: tuple[str, ...] = ("x_g_m", "y_g_m", "z_g_m", "xdot_g_mps", "ydot_g_mps", "zdot_g_mps",
                                "phi_g_rad", "theta_g_rad", "psi_g_rad", "phi_r_rad", "theta_r_rad",
                                "psi_v_rad")
"""Output names with units, index-aligned with :class:`States`."""

AUG_STATE_NAMES: tuple[str, ...] = ("gyro_bias_x_radps", "gyro_bias_y_radps", "gyro_bias_z_radps",
                                    "accel_bias_x_mps2", "accel_bias_y_mps2", "accel_bias_z_mps2",
                                    "wheel_speed_scale")
"""Names of the augmented states (``AugStates`` order, index - 12)."""

ALL_STATE_NAMES: tuple[str, ...] = STATE_NAMES + AUG_STATE_NAMES
"""Names of the extended vector (N_EXT)."""

YAW_STATES = (States.PSI_G, States.PSI_V)
"""States wrapped to [-pi, pi)."""


def wrap_angle(a: float) -> float:
    """Wrap to [-pi, pi) (scalar, cheap)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _as_slice(positions) -> slice | np.ndarray:
    """``positions`` as an index: a slice when they are consecutive (cheaper to assign through)."""
    p = [int(i) for i in positions]
    if p and p == list(range(p[0], p[0] + len(p))):
        return slice(p[0], p[0] + len(p))
    return np.array(p, dtype=int)


@dataclass(frozen=True)
class StateLayout:
    """Which full-vector states the filter carries.

    ``road_estimated``: phi_r, theta_r are filter states (else fixed at 0).
    ``psi_v_state``: psi_v is a filter state with eq 6's zero rate (paper-faithful (a)); else it
    is derived from eq 4. ``psi_v_state`` requires ``road_estimated``.
    """

    road_estimated: bool = True
    psi_v_state: bool = False
    gyro_bias_axes: tuple[int, ...] = ()  # body axes (0 x, 1 y, 2 z) with a gyro bias state
    accel_bias_axes: tuple[int, ...] = ()  # body axes with an accelerometer bias state
    wheel_scale: bool = False  # wheel-speed scale state k_w

    def __post_init__(self):
        if self.psi_v_state and not self.road_estimated:
            raise ValueError("psi_v can only be a filter state when the road angles are estimated")
        for name in ("gyro_bias_axes", "accel_bias_axes"):
            ax = tuple(getattr(self, name))
            if len(set(ax)) != len(ax) or any(a not in (0, 1, 2) for a in ax) or list(ax) != sorted(ax):
                raise ValueError(f"StateLayout.{name} must be increasing distinct axes of 0, 1, 2, got {ax!r}")
            object.__setattr__(self, name, ax)
        idx = list(range(9))
        if self.road_estimated:
            idx += [States.PHI_R, States.THETA_R]
        if self.psi_v_state:
            idx.append(States.PSI_V)
        n_kin = len(idx)
        idx += [AugStates.BG_X + a for a in self.gyro_bias_axes]
        idx += [AugStates.BA_X + a for a in self.accel_bias_axes]
        if self.wheel_scale:
            idx.append(AugStates.WHEEL_SCALE)
        object.__setattr__(self, "_idx", np.array(idx, dtype=int))
        object.__setattr__(self, "_n_kin", n_kin)
        object.__setattr__(self, "_pos", {int(s): i for i, s in enumerate(idx)})
        # d x_full / d x_filter of the carried eq-7 states (12 x n selection; the output path copies it)
        sel = np.zeros((N_FULL, len(idx)))
        sel[np.array(idx[:n_kin], dtype=int), np.arange(n_kin)] = 1.0
        object.__setattr__(self, "_sel_full", sel)
        object.__setattr__(self, "_idx_kin", _as_slice(idx[:n_kin]))
        # filter positions of the angles psi_v of eq 4 depends on (E's psi_v row)
        psi_cols = [] if self.psi_v_state else [self._pos[6 + k] for k in range(5 if self.road_estimated else 3)]
        object.__setattr__(self, "_psi_v_cols", (_as_slice(psi_cols), len(psi_cols)))

    @property
    def n(self) -> int:
        return len(self._idx)

    @property
    def n_kinematic(self) -> int:
        """Number of eq-7 states in the filter vector (they come first)."""
        return self._n_kin

    @property
    def augmented(self) -> bool:
        """True when the layout carries bias or wheel-scale states."""
        return self.n > self._n_kin

    @property
    def full_index(self) -> np.ndarray:
        """Extended-vector index of each filter state (< 12: eq 7; read-only copy)."""
        return self._idx.copy()

    @property
    def states(self) -> tuple:
        return tuple(States(int(i)) if i < N_FULL else AugStates(int(i)) for i in self._idx)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(ALL_STATE_NAMES[int(i)] for i in self._idx)

    @property
    def is_full(self) -> bool:
        return self.n == N_FULL

    def index(self, state) -> int | None:
        """Position of ``state`` in the filter vector, or None if it is derived/fixed."""
        return self._pos.get(int(state))

    def check_x(self, x) -> np.ndarray:
        a = np.asarray(x, dtype=float)
        if a.ndim != 1 or a.shape[0] != self.n:
            raise ValueError(f"state vector must be 1-D of length {self.n} ({', '.join(self.names)}), "
                             f"got shape {a.shape}")
        return a

    def check_p(self, p) -> np.ndarray:
        a = np.asarray(p, dtype=float)
        if a.shape != (self.n, self.n):
            raise ValueError(f"covariance must be 2-D of shape ({self.n}, {self.n}), got shape {a.shape}")
        return a

    def from_full(self, x_full) -> np.ndarray:
        """Pick the filter states out of a full 12-vector (augmented states 0) or an extended
        N_EXT-vector."""
        a = np.asarray(x_full, dtype=float)
        if a.shape == (N_FULL,) and self.augmented:
            a = np.concatenate([a, np.zeros(N_EXT - N_FULL)])
        elif a.shape != (N_FULL,) and a.shape != (N_EXT,):
            raise ValueError(f"full state must have shape ({N_FULL},) or ({N_EXT},), got {a.shape}")
        return a[self._idx].copy()

    def expand(self, x, with_jacobian: bool = True, ext: bool = False):
        """Filter vector -> (full 12-vector, E = d x_full / d x_filter or None); with ``ext`` the
        extended N_EXT-vector and E (N_EXT x n) (augmented states not carried are 0).

        Derived psi_v (eq 4) gets its gradient with respect to the five angles in E's last row;
        fixed road angles are zero with zero rows."""
        from vdps_hil.estimation.kinematics import vehicle_angles_eq4  # local: avoid a cycle

        if with_jacobian and not ext and not self.psi_v_state:  # the EKF's update path: the same (x, E)
            return self.expand_with_vehicle_angles(x)[:2]
        m = N_EXT if ext else N_FULL
        xf = np.zeros(N_EXT)
        xf[self._idx] = x
        e = None
        if with_jacobian:
            e = np.zeros((N_EXT, self.n))
            e[self._idx, np.arange(self.n)] = 1.0
        if not self.psi_v_state:
            if with_jacobian:
                ang, jac = vehicle_angles_eq4(xf[ANGLES5], with_jacobian=True)
                # jac is 3 x 5 over (phi_g, theta_g, psi_g, phi_r, theta_r); keep the columns
                # of the angles that are filter states
                for k in range(5 if self.road_estimated else 3):
                    e[States.PSI_V, self._pos[6 + k]] = jac[2, k]
            else:
                ang = vehicle_angles_eq4(xf[ANGLES5], with_jacobian=False)
            xf[States.PSI_V] = ang[2]
        if m == N_EXT:
            return xf, e
        return xf[:N_FULL].copy(), (None if e is None else e[:N_FULL].copy())

    def expand_with_vehicle_angles(self, x):
        """(x_full, E, (phi_v, theta_v, psi_v), d angles / d x_full[6:11]) in one evaluation of
        eq 4 (the pipeline's output path)."""
        from vdps_hil.estimation.kinematics import vehicle_angles_eq4

        xf = np.zeros(N_FULL)
        xf[self._idx_kin] = x[:self._n_kin]
        e = self._sel_full.copy()
        ang, jac = vehicle_angles_eq4(xf[ANGLES5], with_jacobian=True)
        if not self.psi_v_state:
            cols, k = self._psi_v_cols
            e[States.PSI_V, cols] = jac[2, :k]
            xf[States.PSI_V] = ang[2]
        return xf, e, ang, jac

    def full_covariance(self, x, p) -> tuple[np.ndarray, np.ndarray]:
        """(x_full, P_full = E P E^T) of the 12 states of eq 7; fixed states get zero variance."""
        xf, e = self.expand(x)
        return xf, e @ p @ e.T

    def augmented_values(self, x, p=None) -> dict[str, tuple[float, float]]:
        """{name: (value, sigma)} of the augmented states the layout carries (sigma NaN without
        ``p``)."""
        out = {}
        for i in range(self._n_kin, self.n):
            s = float("nan") if p is None else float(np.sqrt(max(0.0, p[i, i])))
            out[ALL_STATE_NAMES[int(self._idx[i])]] = (float(x[i]), s)
        return out

    @classmethod
    def paper(cls) -> "StateLayout":
        """All 12 states of eq 7 (paper-faithful correction (a))."""
        return cls(road_estimated=True, psi_v_state=True)
