"""The residual of eq 13 at one row for one model (vehicle + dynamics effects), the kernel of
:func:`~vdps_hil.workbench.residuals.compute_residuals` (:class:`RowModel`).

Per row (``meas``: the 22 measured values of ``RowStates.meas``; core: ``model.core.Model.f``
at the row's state, the reduced model, ``unsprung_dof=False``)::

    r_long,lat,vert = m (f_meas - (a_b - g_b))                   [N]     f = a - g at the CG
    r_roll,pitch,yaw = I (omega_dot_meas - omega_dot_model)      [N m]
    r_wheel_i = I_w (omega_dot_i,meas - omega_dot_i,model)       [N m]
    r_wheel_speed_i = v_l,i (1 + kappa_q,i) - r_i omega_i,meas   [m/s]

v_l,i: the wheel centre's velocity along the wheel's heading in the road plane, e_l = (d - (d.n)
n) / |...| with d = (cos delta, sin delta, 0), n the road normal; kappa_q,i = (T_i + T_eff,i -
I_w omega_dot_i,meas) / (r_i C_kappa,i), the slip the measured spin balance asks for (eq 15;
with a saturating tire law the slip at which that law gives the same force). When the
suspension is measured the normal loads come from the deflections (eq 14): the difference to
the rigid-tire pose dF_z,i acts along n at the contact point r_c,i = r_w,i - h_w n.
"""

from __future__ import annotations

import math
from array import array

import numpy as np

from vdps_hil import jit
from vdps_hil.model.chassis import anti_roll_forces_n, roll_centre_forces_n
from vdps_hil.model.core import Model
from vdps_hil.model.effects import EffectSet
from vdps_hil.model.params import Vehicle
from vdps_hil.model.stages import wheel_axes
from vdps_hil.units import GRAVITY_MPS2
from vdps_hil.workbench import row_kernel as rk

__all__ = ["LazyRowQuantities", "RowModel", "RowQuantities"]


class RowQuantities:
    """The named quantities of every row (``EquationResiduals.quantities``) packed: the names
    once, the values as one float64 array (8 bytes a value instead of a dict per row, about 20
    times less); ``q[j]`` and iteration give each row as a fresh dict, equal to the one
    appended (numpy float64 values come back as Python floats of the same bits). A row with
    other names than the first row's, or a value that is not a float, is kept as its dict.
    ``packed``: how many rows are packed."""

    def __init__(self):
        self._names: tuple | None = None
        self._vals = array("d")
        self._rows: list[int] = []  # offset into _vals per row, or -1 - index into _other
        self._other: list[dict] = []

    def append(self, q: dict) -> None:
        names = tuple(q)
        if self._names is None:
            self._names = names
        # a float or a float subclass (numpy's float64, what the residuals compute): packed; read
        # back as a float of the same value
        if names == self._names and all(issubclass(t, float) for t in set(map(type, q.values()))):
            self._rows.append(len(self._vals))
            self._vals.extend(q.values())
        else:
            self._rows.append(-1 - len(self._other))
            self._other.append(dict(q))

    def __len__(self) -> int:
        return len(self._rows)

    @property
    def packed(self) -> int:
        return sum(1 for o in self._rows if o >= 0)

    def __getitem__(self, j: int) -> dict:
        o = self._rows[j]
        if o < 0:
            return dict(self._other[-1 - o])
        return dict(zip(self._names, self._vals[o:o + len(self._names)]))

    def __iter__(self):
        for j in range(len(self._rows)):
            yield self[j]


class LazyRowQuantities:
    """A :class:`RowQuantities` made by ``make()`` when first read (the ranking's base fits never
    read the named quantities; the candidates' regressors do), read as the one it makes."""

    def __init__(self, make):
        self._make, self._q = make, None

    def _get(self) -> RowQuantities:
        if self._q is None:
            self._q, self._make = self._make(), None
        return self._q

    def __len__(self) -> int:
        return len(self._get())

    def __getitem__(self, j: int) -> dict:
        return self._get()[j]

    def __iter__(self):
        return iter(self._get())

    @property
    def packed(self) -> int:
        return self._get().packed


class RowModel:
    """Residual vector of one row for one model (vehicle + dynamics effects)."""

    def __init__(self, vehicle: Vehicle, effects: EffectSet):
        self.model = Model(vehicle, EffectSet(effects.dynamics), unsprung_dof=False)
        p = vehicle.params
        self.m = p.mass_kg
        self.inertia = (p.inertia_x_kgm2, p.inertia_y_kgm2, p.inertia_z_kgm2)
        self.iw = vehicle.tire.wheel_inertia_kgm2
        self.c_kappa = p.tracking_stiffness_n
        self.corners = vehicle.geometry.corner_xy_m()
        self.axles = [vehicle.axle(i) for i in range(4)]
        self._spring = [(a.spring_c1_npm, a.spring_c2_per_m, a.spring_c3_m, a.static_compression_m, a.damper_nspm,
                         a.unsprung_mass_kg * GRAVITY_MPS2) for a in self.axles]
        geo, ch = vehicle.geometry, vehicle.chassis
        self._tracks = (2.0 * geo.track_half_front_m, 2.0 * geo.track_half_rear_m)
        kf, kr = self.model.anti_roll_stiffness_nmprad  # the file's bars plus ``anti_roll_stiffness`` effects
        self._arb = (kf, kr) if (kf != 0.0 or kr != 0.0) else None
        self._roll_centre = ((ch.roll_centre_height_front_m, ch.roll_centre_height_rear_m)
                             if ch.has_roll_centres else None)
        self.last_ws = [0.0] * 8
        self.last_slip_cols = None
        self._zw = self.model.wheel_centre_z_m
        # r_u = sum_i m_u,i r_w,i / m_tot: the core's unsprung masses ride with the body and react
        # to its acceleration a = F / m_tot + g (``stages.body_accelerations``: M += sum r_w,i x
        # m_u,i (g - a)), so a force F at r_c turns the body by (r_c - r_u) x F
        mu = [a.unsprung_mass_kg for a in self.axles]
        self.unsprung_arm_m = tuple(sum(m * c[k] for m, c in zip(mu, self.corners)) / self.m for k in (0, 1)) + (
            sum(mu) * self._zw / self.m,)
        ux, uy, uz = self.unsprung_arm_m
        self._corners_u = [(x - ux, y - uy) for x, y in self.corners]  # the corners and wheel centre
        self._zw_u = self._zw - uz  # relative to r_u, as the load and force columns take them
        tire = self.model.effects.tire
        self._tire = None if tire is None or tire.name == "linear_tire" else tire
        self._fz0 = self.model.static_load_n
        self._calpha = self.model.c_alpha

    def packed(self) -> tuple | None:
        """The arrays of :func:`~vdps_hil.workbench.row_kernel.residual_rows` (K, C, E, P,
        CORN, SPR) for this model, or None when its core is not compiled (then only
        :meth:`residual` evaluates it)."""
        if self.model.kernel_arrays is None or not jit.ENABLED:
            return None
        P = np.zeros(rk.N_P)
        P[0:5] = (self.m, *self.inertia, self.iw)
        P[rk.P_CK:rk.P_CK + 4] = self.c_kappa
        P[rk.P_ZW] = self._zw
        if self._arb is not None:
            P[rk.P_ARB:rk.P_KR + 1] = (1.0, *self._arb)
        P[rk.P_TF], P[rk.P_TR] = self._tracks
        if self._roll_centre is not None:
            P[rk.P_RC:rk.P_HR + 1] = (1.0, *self._roll_centre)
        P[rk.P_NEWTON] = 0.0 if self._tire is None else 1.0
        P[rk.P_FZ0:rk.P_FZ0 + 4] = self._fz0
        P[rk.P_CA:rk.P_CA + 4] = self._calpha
        P[rk.P_RU:rk.P_RU + 3] = self.unsprung_arm_m
        return (*self.model.kernel_arrays, P, np.array(self.corners, dtype=float), np.array(self._spring, dtype=float))

    def residual(self, x, u, env, meas, want_named: bool = False, want_slip: bool = False):
        """(r (14,) list, named quantities or None) at one row; ``meas`` a sequence of 22
        measured values (``RowStates.meas``)."""
        m = self.model
        raw: dict = {"_want_air": want_named}
        xd = m.f(x, u, env, raw)
        ax, ay, az = raw["_acc_b"]
        gx, gy, gz = raw["_g_b"]
        mass = self.m
        ix, iy, iz = self.inertia
        r = [mass * (meas[0] - (ax - gx)), mass * (meas[1] - (ay - gy)), mass * (meas[2] - (az - gz)),
             ix * (meas[3] - xd[9]), iy * (meas[4] - xd[10]), iz * (meas[5] - xd[11]),
             0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        vx, vy = x[6], x[7]
        wz = x[11]
        rec = raw["_rec"]
        if len(meas) > 14 and meas[14] == meas[14] and meas[18] == meas[18]:
            self._measured_loads(r, rec, raw["_normal_b"], meas)
        iw = self.iw
        ws = self.last_ws
        cos, sin, sqrt = math.cos, math.sin, math.sqrt
        nx, ny, nz = raw["_normal_b"]
        wx, wy = x[9], x[10]
        vz = x[8]
        zw = self._zw
        for i in range(4):
            rc = rec[i]
            tq, teff, delta, ri = rc[7], rc[8], rc[9], rc[10]
            r[6 + i] = iw * (meas[6 + i] - xd[12 + i])
            xi, yi = self.corners[i]
            # wheel-centre velocity along the wheel's heading in the road plane (as the core)
            cd, sd = cos(delta), sin(delta)
            hn = cd * nx + sd * ny
            lx, ly, lz = cd - hn * nx, sd - hn * ny, -hn * nz
            inv = 1.0 / sqrt(lx * lx + ly * ly + lz * lz)
            vwx = vx + wy * zw - wz * yi
            vwy = vy + wz * xi - wx * zw
            vwz = vz + wx * yi - wy * xi
            vl = (vwx * lx + vwy * ly + vwz * lz) * inv
            kq = (tq + teff - iw * meas[6 + i]) / (ri * self.c_kappa[i])
            if self._tire is not None:
                kq = self._slip_for_force(i, rc, kq * self.c_kappa[i], kq)
            r[10 + i] = vl * (1.0 + kq) - ri * meas[10 + i]
            ws[i] = vl
            ws[4 + i] = kq
        named = m._named(x, xd, raw, env) if want_named else None
        if want_slip:
            self.last_slip_cols = self._slip_columns(rec, raw["_normal_b"])
        return r, named

    def _measured_loads(self, r, rec, n_b, meas) -> None:
        """Normal loads from the measured deflections and rates (eq 14, as eq 20 and 23 use them)
        instead of the rigid-tire pose: the difference dF_z,i acts along the road normal n at the
        contact point r_c,i = r_w,i - h_w n. The chassis parts the core adds to the pose's load
        are added to the measured one as well: the anti-roll bars' F_arb,i from the measured
        deflections and the roll centres' J_i (``model.chassis``; in the reduced model both are
        part of the corner's normal load, so replacing that load by the springs' alone dropped
        them)."""
        nx, ny, nz = n_b
        farb = None
        if self._arb is not None:
            farb = anti_roll_forces_n(self._arb[0], self._arb[1], self._tracks[0], self._tracks[1], meas[14:18])
        jac = self._roll_centre_forces(rec, n_b) if self._roll_centre is not None else None
        for i in range(4):
            fz = rk.measured_normal_load(*self._spring[i], meas[14 + i], meas[18 + i],
                                         0.0 if farb is None else farb[i])
            if jac is not None:
                fz += jac[i]
            xi, yi = self._corners_u[i]
            rk.normal_load_change(r, fz - rec[i][2], rec[i][11], xi, yi, self._zw_u, nx, ny, nz)

    def _roll_centre_forces(self, rec, n_b) -> tuple[float, float, float, float]:
        """J_i (``chassis.roll_centre_forces_n``) from the axles' lateral tire forces in body y
        (F_a e_l + F_b e_t of the corners' records), as the core computes them."""
        fy = [0.0, 0.0]
        for i in range(4):
            lx, ly, lz, tx, ty, tz = wheel_axes(rec[i][9], n_b)
            fy[0 if i < 2 else 1] += rec[i][0] * ly + rec[i][1] * ty
        return roll_centre_forces_n(self._roll_centre[0], self._roll_centre[1], self._tracks[0], self._tracks[1],
                                    fy[0], fy[1])

    def _slip_for_force(self, i: int, rc, fa_target: float, k0: float) -> float:
        """The slip ratio at which the model's tire law gives the longitudinal force the spin
        balance measured (Newton from the linear tire's value, at the corner's slip angle and
        load; combined slip lowers the longitudinal stiffness of a saturating tire)."""
        tf = self._tire.tire_forces
        fz, alp = rc[2], rc[4]
        ck, ca, fz0 = self.c_kappa[i], self._calpha[i], self._fz0[i]
        k = k0
        for _ in range(3):
            f0 = tf(fz, fz0, k, alp, ck, ca)[0]
            h = 1e-5
            df = (tf(fz, fz0, k + h, alp, ck, ca)[0] - f0) / h
            if not df > 0.05 * ck:
                break
            k = k + (fa_target - f0) / df
        return k

    def _slip_columns(self, rec, n_b) -> np.ndarray:
        """(14, 8): d(residual)/d(F_a,i) (columns 0-3) -- a longitudinal tire force along the
        wheel's heading in the road plane e_l at the contact point (force e_l, moment (r_c - r_u) x
        e_l with the unsprung masses' arm r_u, wheel spin -r_i) -- and d(residual)/d(F_b,i)
        (columns 4-7, along e_t = n x e_l, times the slip angle: the cornering-stiffness columns of
        the linear tire)."""
        nx, ny, nz = n_b
        out = np.zeros((14, 8))
        for i in range(4):
            xi, yi = self._corners_u[i]
            rk.corner_force_columns(out, i, rec[i][9], rec[i][10], rec[i][11], rec[i][4], xi, yi, self._zw_u,
                                    nx, ny, nz)
        return out
