"""The GNSS/IMU innovations the measurement effects are judged on (:func:`compute_innovations`).

Innovations of the measurement effects (:class:`Innovations`): the IMU integrated open loop
(strapdown, ENU, from the estimator's state at the table's first row) against every GNSS
measurement -- attitude (roll, pitch, yaw), horizontal antenna velocity (speed and course) and
antenna position::

    C_dot = -[omega x] C,   v_dot = C^T f + g,   p_dot = v        (C = C_g^v, eq 1)
    e = z_GNSS - h(strapdown)

These are the estimator's own innovations, taken over the whole drive instead of one filter step,
so a slow sensor error accumulates instead of being absorbed by the next update. Nuisance: the
initial attitude, velocity and position (9 columns). An effect's column is the change of e when
its field regressors (``MeasurementEffect.regressors``) are taken out of the readings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from vdps_hil.model.effects.base import MeasurementEffect
from vdps_hil.units import GRAVITY_MPS2

from .dataset import DriveTable, dcm_gv_batch
from .residuals import imu_kinematics

__all__ = ["INNOVATION_CHANNELS", "INNOVATION_UNITS", "Innovations", "compute_innovations"]


INNOVATION_CHANNELS = ("att_roll", "att_pitch", "att_yaw", "vel_e", "vel_n", "pos_e", "pos_n", "pos_u")
INNOVATION_UNITS = {"att_roll": "rad", "att_pitch": "rad", "att_yaw": "rad", "vel_e": "m/s", "vel_n": "m/s",
                    "pos_e": "m", "pos_n": "m", "pos_u": "m"}


@dataclass
class Innovations:
    """GNSS against the open-loop strapdown (module docstring): one row per GNSS value.

    ``t_s`` (m,), ``channel`` (m,) index into ``INNOVATION_CHANNELS``, ``values`` (m,),
    ``sigma`` (m,), ``nuisance`` (m, 9) columns for the initial attitude (3, rotation about the
    ENU axes), velocity (3) and position (3)."""

    t_s: np.ndarray
    channel: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    nuisance: np.ndarray
    _ctx: dict = field(repr=False, default_factory=dict)

    def __len__(self) -> int:
        return len(self.t_s)

    def effect_columns(self, effect: MeasurementEffect, params: Sequence[str]) -> np.ndarray:
        """(m, len(params)): the innovations theta leaves when it is in the readings, per unit of
        each parameter: e = z - h(f + theta d) ~ e_0 - theta dh/dtheta (finite differences of the
        strapdown with the field regressors d taken out of the readings)."""
        ctx = self._ctx
        if not len(self.t_s) or not params:
            return np.zeros((len(self.t_s), len(params)))
        c = ctx["table"].columns
        n = len(ctx["t"])
        base_f, base_w = ctx["f"], ctx["w"]
        dfs = [np.zeros((n, 3)) for _ in params]
        dws = [np.zeros((n, 3)) for _ in params]
        for k in range(n):
            reg = effect.regressors(imu_kinematics(c, ctx["rows"][k]))
            for q, a in enumerate("xyz"):
                rf = reg.get(f"specific_force_mps2_{a}", {})
                rw = reg.get(f"angular_rate_radps_{a}", {})
                for j, p in enumerate(params):
                    dfs[j][k, q] = rf.get(p, 0.0)
                    dws[j][k, q] = rw.get(p, 0.0)
        # step sizes: the effect's default magnitude (or 1e-3 of a unit)
        spec = effect.param_specs()
        steps = [abs(spec[p].default) if spec[p].default else 1e-3 for p in params]
        fb = np.stack([base_f] + [base_f - h * d for h, d in zip(steps, dfs)])
        wb = np.stack([base_w] + [base_w - h * d for h, d in zip(steps, dws)])
        traj = _strapdown(ctx["t"], fb, wb, ctx["c0"], ctx["v0"], ctx["p0"])
        h_all = _observe(traj, ctx)
        # e = z - h(f + theta d): an effect theta in the readings leaves e ~ -theta dh/dtheta
        return np.column_stack([(h_all[1 + j] - h_all[0]) / steps[j] for j in range(len(params))])


def _strapdown(t, f, w, c0, v0, p0):
    """Open-loop integration for a batch (B, n, 3) of readings: (C (B,n,3,3), v (B,n,3),
    p (B,n,3)). C0 (B,3,3) or (3,3)."""
    b, n = f.shape[0], f.shape[1]
    C = np.empty((b, n, 3, 3))
    v = np.empty((b, n, 3))
    p = np.empty((b, n, 3))
    c = np.broadcast_to(c0, (b, 3, 3)).copy()
    vv = np.broadcast_to(v0, (b, 3)).copy()
    pp = np.broadcast_to(p0, (b, 3)).copy()
    g = np.array([0.0, 0.0, -GRAVITY_MPS2])
    C[:, 0], v[:, 0], p[:, 0] = c, vv, pp
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        wm = 0.5 * (w[:, k] + w[:, k + 1])
        fm = 0.5 * (f[:, k] + f[:, k + 1])
        # C_{k+1} = exp(-[w dt x]) C_k  (Rodrigues)
        th = wm * dt
        ang = np.linalg.norm(th, axis=1)
        s = np.where(ang > 1e-12, np.sin(ang) / np.maximum(ang, 1e-300), 1.0)
        cc = np.where(ang > 1e-12, (1.0 - np.cos(ang)) / np.maximum(ang * ang, 1e-300), 0.5)
        K = np.zeros((b, 3, 3))
        K[:, 0, 1], K[:, 0, 2] = -th[:, 2], th[:, 1]
        K[:, 1, 0], K[:, 1, 2] = th[:, 2], -th[:, 0]
        K[:, 2, 0], K[:, 2, 1] = -th[:, 1], th[:, 0]
        R = np.eye(3)[None] - s[:, None, None] * K + cc[:, None, None] * (K @ K)
        c_mid = c
        acc = np.einsum("bji,bj->bi", c_mid, fm) + g
        c = R @ c
        acc = 0.5 * (acc + np.einsum("bji,bj->bi", c, fm) + g)
        vn = vv + acc * dt
        pp = pp + 0.5 * (vv + vn) * dt
        vv = vn
        C[:, k + 1], v[:, k + 1], p[:, k + 1] = c, vv, pp
    return C, v, p


def _observe(traj, ctx) -> np.ndarray:
    """Predicted GNSS values (B, m) for the strapdown batch, in the order of the innovation rows."""
    C, v, p = traj
    b = C.shape[0]
    t = ctx["t"]
    rows = ctx["obs"]
    out = np.empty((b, len(rows)))
    lever = ctx["lever"]
    w = ctx["w"]
    for j, (ch, ts) in enumerate(rows):
        k = int(np.clip(np.searchsorted(t, ts) - 1, 0, len(t) - 2))
        a = (ts - t[k]) / (t[k + 1] - t[k])
        if ch < 3:
            e0 = _euler(C[:, k])
            e1 = _euler(C[:, k + 1])
            d = e1 - e0
            d[:, 2] = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
            out[:, j] = e0[:, ch] + a * d[:, ch]
        elif ch < 5:
            cm = C[:, k]
            va = v[:, k] * (1 - a) + v[:, k + 1] * a + np.einsum("bji,j->bi", cm, np.cross(w[k], lever))
            out[:, j] = va[:, ch - 3]
        else:
            cm = C[:, k]
            pa = p[:, k] * (1 - a) + p[:, k + 1] * a + np.einsum("bji,j->bi", cm, lever)
            out[:, j] = pa[:, ch - 5]
    return out


def _euler(c):
    """(phi, theta, psi) from C_g^v batches (B,3,3) (``frames.euler_ypr_from_dcm``)."""
    th = np.arcsin(np.clip(c[:, 0, 2], -1.0, 1.0))
    ph = np.arctan2(c[:, 1, 2], c[:, 2, 2])
    ps = np.arctan2(c[:, 0, 1], c[:, 0, 0])
    return np.stack([ph, th, ps], axis=1)


def _rot_about(axis: int, ang: float) -> np.ndarray:
    """Rotation of the ENU frame by ``ang`` about one of its axes, as C_g^v post-factor."""
    c, s = math.cos(ang), math.sin(ang)
    r = np.eye(3)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def compute_innovations(table: DriveTable, gnss_speed_sigma_mps: float = 0.1,
                        min_course_speed_mps: float = 3.0) -> Innovations:
    """GNSS against the open-loop strapdown (module docstring)."""
    c = table.columns
    empty = Innovations(np.zeros(0), np.zeros(0, int), np.zeros(0), np.zeros(0), np.zeros((0, 9)))
    rows = _strapdown_rows(table)
    if rows is None:
        return empty
    t = table.t_s[rows]
    f = np.column_stack([c[f"specific_force_b_mps2_{a}"][rows] for a in "xyz"])[None]
    w = np.column_stack([c[f"rate_b_radps_{a}"][rows] for a in "xyz"])[None]
    k0 = rows[0]
    c0 = dcm_gv_batch(np.array([c["roll_g_rad"][k0]]), np.array([c["pitch_g_rad"][k0]]),
                      np.array([c["yaw_g_rad"][k0]]))[0]
    v0 = np.array([c[f"vel_g_mps_{a}"][k0] for a in "enu"])
    p0 = np.array([c[f"pos_g_m_{a}"][k0] for a in "enu"])
    lever = np.asarray(table.vehicle.mounting.gnss_lever_arm_m, dtype=float)
    obs, vals, sig = _gnss_observations(table.gnss, t[0], t[-1], gnss_speed_sigma_mps, min_course_speed_mps)
    if not obs:
        return empty
    ctx = {"t": t, "f": f[0], "w": w[0], "c0": c0, "v0": v0, "p0": p0, "lever": lever, "obs": obs, "rows": rows,
           "table": table}
    # nominal + initial-attitude perturbations (rotation of the ENU frame about E, N, U)
    h = 1e-3
    c0s = np.stack([c0] + [c0 @ _rot_about(ax, h).T for ax in range(3)])
    traj = _strapdown(t, np.repeat(f, 4, axis=0), np.repeat(w, 4, axis=0), c0s, np.repeat(v0[None], 4, 0),
                      np.repeat(p0[None], 4, 0))
    hh = _observe(traj, ctx)  # (4, m): h(strapdown) nominal, then per initial-attitude perturbation
    ch = np.array([o[0] for o in obs])
    ts = np.array([o[1] for o in obs])
    values = np.array(vals) - hh[0]
    att = ch < 3
    values[att & (ch == 2)] = (values[att & (ch == 2)] + np.pi) % (2 * np.pi) - np.pi
    return Innovations(ts, ch, values, np.array(sig), _nuisance_columns(hh, h, ch, ts, t[0]), ctx)


def _strapdown_rows(table: DriveTable) -> np.ndarray | None:
    """The table rows the strapdown integrates: the longest contiguous run of rows with every IMU
    and estimator signal it needs (None: fewer than 20 usable rows)."""
    c = table.columns
    names = [f"specific_force_b_mps2_{a}" for a in "xyz"] + [f"rate_b_radps_{a}" for a in "xyz"] + list(
        ("roll_g_rad", "pitch_g_rad", "yaw_g_rad", "vel_g_mps_e", "vel_g_mps_n", "vel_g_mps_u",
         "pos_g_m_e", "pos_g_m_n", "pos_g_m_u"))
    ok = np.ones(len(table), bool)
    for n in names:
        ok &= np.isfinite(c[n])
    rows = np.flatnonzero(ok)
    if len(rows) < 20:
        return None
    # one contiguous span (the longest run of usable rows)
    breaks = np.flatnonzero(np.diff(rows) > 1)
    starts = np.r_[0, breaks + 1]
    ends = np.r_[breaks, len(rows) - 1]
    j = int(np.argmax(ends - starts))
    return rows[starts[j]:ends[j] + 1]


def _gnss_observations(g: dict, lo: float, hi: float, gnss_speed_sigma_mps: float,
                       min_course_speed_mps: float) -> tuple[list, list, list]:
    """The GNSS values inside [lo, hi] as innovation rows: ([(channel, t_s)], values, sigmas);
    attitude, then horizontal velocity (east, north from speed and course, above
    ``min_course_speed_mps``), then position; a missing sigma gets a default."""
    obs, vals, sig = [], [], []
    if "att" in g:
        a = g["att"]
        for ch, key in enumerate(("roll", "pitch", "yaw")):
            for ts, z, s in zip(a["t_s"], a[f"{key}_rad"], a[f"{key}_sigma_rad"]):
                if lo <= ts <= hi and math.isfinite(z):
                    obs.append((ch, ts))
                    vals.append(z)
                    sig.append(s if (math.isfinite(s) and s > 0) else math.radians(0.4))
    if "vel" in g:
        a = g["vel"]
        for ts, sp, co in zip(a["t_s"], a["speed_mps"], a["course_rad"]):
            if lo <= ts <= hi and math.isfinite(sp + co) and sp >= min_course_speed_mps:
                for ch, z in ((3, sp * math.cos(co)), (4, sp * math.sin(co))):
                    obs.append((ch, ts))
                    vals.append(z)
                    sig.append(gnss_speed_sigma_mps)
    if "pos" in g:
        a = g["pos"]
        for ts, e, nn, u, sh, sv in zip(a["t_s"], a["e_m"], a["n_m"], a["u_m"], a["sigma_h_m"], a["sigma_v_m"]):
            if lo <= ts <= hi and math.isfinite(e + nn + u):
                sh = sh if (math.isfinite(sh) and sh > 0) else 1.0
                sv = sv if (math.isfinite(sv) and sv > 0) else 3.0
                for ch, z, s in ((5, e, sh), (6, nn, sh), (7, u, sv)):
                    obs.append((ch, ts))
                    vals.append(z)
                    sig.append(s)
    return obs, vals, sig


def _nuisance_columns(hh: np.ndarray, h: float, ch: np.ndarray, ts: np.ndarray, t0: float) -> np.ndarray:
    """(m, 9): d e / d(initial attitude about E, N, U) by the finite differences ``hh`` (step h,
    yaw wrapped), d e / d(initial velocity) (1 on the velocity rows, dt on the position rows) and
    d e / d(initial position) (1 on the position rows)."""
    nuis = np.zeros((len(ch), 9))
    for ax in range(3):
        d = hh[1 + ax] - hh[0]
        d[ch == 2] = (d[ch == 2] + np.pi) % (2 * np.pi) - np.pi
        nuis[:, ax] = d / h
    dt = ts - t0
    for q in range(3):
        nuis[:, 3 + q] = np.where(ch == 3 + q, 1.0, 0.0) + np.where(ch == 5 + q, dt, 0.0)
        nuis[:, 6 + q] = np.where(ch == 5 + q, 1.0, 0.0)
    return nuis
