"""The predictor's integration loops (the stiff wheel spin): the steps, the stop rules and
the ROS2 W-method, on the generic core (``Model.f``) and on the specialised reduced core
(:class:`vdps_hil.model.reduced.ReducedLinearCore`).

The stiffest mode of the reduced model is the wheel spin under slip,
``tau = I_w max(|v_l|, v_floor) / (r^2 C_kappa)`` (0.5 ms at the slip speed floor with the
sedan-model's x1.5 prior of C_kappa): explicit RK2 needs dt <= 2 tau ~ 1 ms, 5000 steps for 5 s.
The body modes (roll, pitch, heave with rigid tires: 1.5-2.5 Hz; yaw/sideslip) are slow.
Default integrator ``ros2``: the 2-stage Rosenbrock W-method of Verwer et al. (SIAM J. Sci.
Comput. 20(4), 1999), gamma = 1 + 1/sqrt(2), L-stable, second order for ANY matrix J::

    (I - gamma h J) k1 = f(x_n)
    (I - gamma h J) k2 = f(x_n + h k1) - 2 k1
    x_{n+1} = x_n + 3/2 h k1 + 1/2 h k2

with J nonzero only in the four wheel-spin rows (the body rows are zero, so the solve is one
division per wheel): the diagonal J_ii = d omega_dot_i / d omega_i by a forward difference of
the core's f (clipped to <= 0), and, with ``jacobian_coupling`` (default), the coupling to the
body velocity from the slip kinematics of the core (kappa = (r omega - v_l) / max(|v_l|, v_floor),
v_l = (v_x - omega_z y_i) cos delta_i + (v_y + omega_z x_i) sin delta_i)::

    d omega_dot_i / d v_l = -J_ii (1 + kappa_i) / r_i,   then chained to v_x, v_y, omega_z

J is refreshed every ``jacobian_every`` steps (a W-method stays second order with a stale or
approximate J). On the body states the scheme IS Heun's method (RK2) exactly; on the wheel
spins it is linearly implicit, so the step is set by the body dynamics. Without the coupling
the wheel spin lags an accelerating body by ~0.6 h d(v/r)/dt (order reduction of the stiff
component): 0.88 m after 5 s of the left turn at h = 10 ms; with it 2.7 mm. Measured against
explicit RK2 at 1 ms (``tools/bench_predictor.py``, true parameters, 5 s)::

    case                     h = 10 ms (default)          h = 20 ms
    left turn (Fig 8)        2.7 mm, 0.001 deg, 7 ms      5.6 mm, 0.005 deg, 3.7 ms
    T2 = T3 = 1000 N m       0.22 m, 0.21 deg             0.44 m, 0.42 deg
    fishhook-suv (to PONR)   4 mm, 0.59 deg, same PONR    6 mm, 0.98 deg, same PONR

(CPU time of one 5 s prediction in pure Python, best of 15; explicit RK2 at 1 ms takes 56 ms).
``rk2`` (Heun, explicit) is available for reference and needs h below the wheel-spin stability
limit.

Both loops sample the inputs at the start of each step and hold them over it (zero-order hold),
keep every ``output_every``-th step (and the last) and stop at the horizon, the predicted point
of no return (with ``stop_at_point_of_no_return``), |phi_v| > ``ROLL_LIMIT_RAD`` or a
non-finite state (:func:`keep_step`). Each returns ``(states, wheel loads, times, stop reason,
steps, f-evaluations)``.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.model.core import Env, Inputs, Model
from vdps_hil.model.reduced import ReducedLinearCore
from vdps_hil.model.rollover import TIP_UP_LOAD_FRACTION, RolloverMonitor
from vdps_hil.model.stages import steer_angles

from .config import PredictorConfig
from .initial_state import InputSource
from .integration_kernel import STOP_REASONS, reduced_loop

ROS2_GAMMA = 1.0 + 1.0 / math.sqrt(2.0)
"""gamma of Verwer's ROS2 (L-stable choice)."""
ROLL_LIMIT_RAD = math.radians(85.0)
"""The prediction stops beyond this road-relative roll (the model has no body-ground contact)."""


class _GenericWSolve:
    """W = I - gamma h J of the generic loop's ROS2 step, nonzero off the identity only in the
    four wheel-spin rows: J_kk by a forward difference of ``Model.f`` (clipped to <= 0) and,
    with ``jacobian_coupling``, the wheel rows' coupling to v_x, v_y, omega_z through the slip
    kinematics (module docstring)."""

    __slots__ = ("steer", "radii", "corner_xy", "vfloor", "w0", "w1", "gh", "coupling", "winv", "cvx", "cvy",
                 "cwz", "u_c", "cd", "sd")

    def __init__(self, model: Model, cfg: PredictorConfig):
        geo = model.vehicle.geometry
        self.steer = (geo.steer_ratio, geo.wheelbase_m, geo.track_half_front_m,
                      model.vehicle.chassis.ackermann_fraction)
        self.radii, self.corner_xy = model.rolling_radius_m, model.corner_xy
        self.vfloor = model.slip_speed_floor_mps
        ws = model.layout.wheel_spin
        self.w0, self.w1 = ws.start, ws.stop
        self.gh = ROS2_GAMMA * cfg.step_s  # gamma h
        self.coupling = cfg.jacobian_coupling
        self.winv = [1.0, 1.0, 1.0, 1.0]  # 1 / (1 - gamma h J_kk)
        self.cvx, self.cvy, self.cwz = [0.0] * 4, [0.0] * 4, [0.0] * 4  # gamma h d omega_dot_k / d (v_x, v_y, omega_z)
        self.u_c = None  # the inputs cd/sd were computed for
        self.cd = self.sd = (0.0,) * 4  # cos / sin of the road-wheel angles

    def refresh(self, f, x, u: Inputs, env: Env, f0, rec) -> None:
        """J at ``x`` (one more evaluation of ``f``); ``f0``, ``rec``: f(x) and its corner records."""
        w0, w1 = self.w0, self.w1
        xp = list(x)
        eps = []
        for i in range(w0, w1):
            e_ = 1e-4 * max(1.0, abs(x[i]))
            xp[i] += e_
            eps.append(e_)
        fp = f(xp, u, env)
        coupling, gh = self.coupling, self.gh
        if coupling and (u is not self.u_c):
            self.u_c = u
            ratio, wheelbase, t_f, e_a = self.steer  # the road-wheel angles of the core (Ackermann fraction)
            d1, d2 = steer_angles(u.steer_wheel_angle_rad / ratio, wheelbase, t_f, e_a)
            self.cd = (math.cos(d1), math.cos(d2), 1.0, 1.0)
            self.sd = (math.sin(d1), math.sin(d2), 0.0, 0.0)
        cd, sd = self.cd, self.sd
        above = abs(x[6]) > self.vfloor
        for k in range(4):
            jd = (fp[w0 + k] - f0[w0 + k]) / eps[k]
            if jd > 0.0 or jd != jd:
                jd = 0.0
            self.winv[k] = 1.0 / (1.0 - gh * jd)
            if coupling:
                # d omega_dot / d v_l = J_kk * (d kappa / d v_l) / (d kappa / d omega)
                fac = -jd * ((1.0 + rec[k][3]) if above else 1.0) / self.radii[k]
                xi, yi = self.corner_xy[k]
                self.cvx[k] = gh * fac * cd[k]
                self.cvy[k] = gh * fac * sd[k]
                self.cwz[k] = gh * fac * (xi * sd[k] - yi * cd[k])

    def solve(self, k: list) -> list:
        """W^-1 k on the wheel rows, in place (W = I on the body rows); returns ``k``."""
        w0, cvx, cvy, cwz, winv = self.w0, self.cvx, self.cvy, self.cwz, self.winv
        a6, a7, a11 = k[6], k[7], k[11]
        for j in range(4):
            k[w0 + j] = (k[w0 + j] + cvx[j] * a6 + cvy[j] * a7 + cwz[j] * a11) * winv[j]
        return k


def propagate_generic(model: Model, cfg: PredictorConfig, x: list, env: Env, held: Inputs | None,
                      src: InputSource | None, monitor: RolloverMonitor):
    """The integration loop on ``model.f`` (any effect set and variant): ROS2 with the
    wheel-spin Jacobian by forward difference (:class:`_GenericWSolve`), or explicit Heun.
    ``held``: the held inputs, else ``src(t_rel_s)`` is sampled every step."""
    f = model.f
    h = cfg.step_s
    n_steps, out_every, jac_every = cfg.n_steps, cfg.output_every, cfg.jacobian_every
    ros2, stop_ponr = cfg.integrator == "ros2", cfg.stop_at_point_of_no_return
    w = _GenericWSolve(model, cfg)
    # ROS2: x_n+1 = x_n + 3/2 h k1 + 1/2 h k2;  Heun (rk2): x_n+1 = x_n + h/2 (f(x_n) + f(x_n + h f(x_n)))
    h_k1, h_k2, h_heun = 1.5 * h, 0.5 * h, 0.5 * h
    xs: list[list[float]] = []
    fzs: list[tuple] = []
    ts: list[float] = []
    stop = "horizon"
    n = n_eval = 0
    u = held
    while True:
        t_rel = n * h
        if held is None:
            u = src(t_rel)
        out = {"_want_air": False}
        f0 = f(x, u, env, out)
        n_eval += 1
        rec = out["_rec"]
        record = n % out_every == 0 or n == n_steps
        # road-relative roll for the rollover monitor (n_b = C_r^v e_z)
        nx, ny, nz = out["_normal_b"]
        fz = (rec[0][2], rec[1][2], rec[2][2], rec[3][2])
        ended = keep_step(xs, fzs, ts, monitor, stop_ponr, record, t_rel, x, fz, math.atan2(ny, nz), nx)
        if ended is not None:
            stop = ended
            break
        if n >= n_steps:
            break
        if ros2:
            if n % jac_every == 0:
                w.refresh(f, x, u, env, f0, rec)
                n_eval += 1
            k1 = w.solve(list(f0))
            f1 = f([a + h * b for a, b in zip(x, k1)], u, env)
            n_eval += 1
            k2 = w.solve([c - 2.0 * b for b, c in zip(k1, f1)])
            x = [a + h_k1 * b + h_k2 * c for a, b, c in zip(x, k1, k2)]
        else:
            f1 = f([a + h * b for a, b in zip(x, f0)], u, env)
            n_eval += 1
            x = [a + h_heun * (b + c) for a, b, c in zip(x, f0, f1)]
        n += 1
        if not math.isfinite(x[6] + x[9] + x[12] + x[3] + x[4]):
            stop = "non_finite"
            break
    return xs, fzs, ts, stop, n, n_eval


def propagate_reduced(core: ReducedLinearCore, cfg: PredictorConfig, x: list, env: Env, held: Inputs | None,
                      src: InputSource | None, monitor: RolloverMonitor):
    """The loop of :func:`propagate_generic` on :class:`ReducedLinearCore`: the same steps, stop
    rules and ROS2 W-method, with the wheel-spin Jacobian in closed form instead of a forward
    difference and the W-solve written out for the four wheel rows, compiled as one call
    (:func:`vdps_hil.prediction.integration_kernel.reduced_loop`; tested equal to the generic
    loop in ``tests/test_predictor.py``). Input-driven: ``src`` is sampled at every step time
    n h of the horizon before the loop starts. The rollover monitor is fed the kept steps after
    the loop (:func:`feed_monitor`)."""
    h = cfg.step_s
    n_steps = cfg.n_steps
    if held is not None:
        uc = [core.inputs(held)]
    else:
        uc = [core.inputs(src(n * h)) for n in range(n_steps + 1)]
    u_csd = np.stack([u[0] for u in uc])
    u_tq = np.stack([u[1] for u in uc])
    u_br = np.stack([u[2] for u in uc])
    m = n_steps // cfg.output_every + 3
    X, FZ, T, PHI, RATE = np.empty((m, 16)), np.empty((m, 4)), np.empty(m), np.empty(m), np.empty(m)
    n_out, n_fed, n, n_eval, stop = reduced_loop(
        np.asarray(x, dtype=float), u_csd, u_tq, u_br, np.asarray(env.normal_g, dtype=float), core.K, core.C, h,
        n_steps, cfg.output_every, cfg.jacobian_every, cfg.integrator == "ros2", cfg.jacobian_coupling,
        cfg.stop_at_point_of_no_return, monitor.tip_angle_rad, ROLL_LIMIT_RAD, ROS2_GAMMA, X, FZ, T, PHI, RATE)
    feed_monitor(monitor, T[:n_fed], FZ[:n_fed], PHI[:n_fed], RATE[:n_fed])
    return X[:n_out], FZ[:n_out], T[:n_out], STOP_REASONS[stop], n, n_eval


def feed_monitor(monitor: RolloverMonitor, t_s: np.ndarray, fz: np.ndarray, roll: np.ndarray,
                 roll_rate: np.ndarray) -> None:
    """``monitor.update`` at every sample where it can change something: where an inside pair of
    wheels is below the tip-up load, the sample after one, or where |phi_v| is not within the
    static tip angle (at every other sample ``update`` returns at once with its state unchanged,
    so the events are those of feeding every sample)."""
    thr = [TIP_UP_LOAD_FRACTION * s for s in monitor.static_loads_n]
    low = ((fz[:, 0] < thr[0]) & (fz[:, 3] < thr[3])) | ((fz[:, 1] < thr[1]) & (fz[:, 2] < thr[2]))
    feed = low | ~(np.abs(roll) <= monitor.tip_angle_rad)
    feed[1:] |= low[:-1]
    for k in np.flatnonzero(feed).tolist():
        monitor.update(float(t_s[k]), tuple(fz[k].tolist()), float(roll[k]), float(roll_rate[k]))


def keep_step(xs: list, fzs: list, ts: list, monitor: "RolloverMonitor", stop_ponr: bool, record: bool,
               t_rel: float, x: list, fz, phi_v: float, nx: float) -> str | None:
    """One integration step's bookkeeping, the same in both loops: a
    recorded step keeps (state, wheel loads, time) and feeds the rollover monitor the
    road-relative roll ``phi_v`` and its rate (Euler-rate relation with theta_v = asin(n_x)).
    Returns why the prediction stops here -- ``"point_of_no_return"`` (the monitor found it and
    ``stop_ponr``), ``"roll_limit"`` (|phi_v| past ``ROLL_LIMIT_RAD``; that step is kept even
    when not a recorded one) -- or None."""
    if record:
        xs.append(x)
        fzs.append(fz)
        ts.append(t_rel)
        tt = math.tan(math.asin(max(-1.0, min(1.0, nx))))
        monitor.update(t_rel, fz, phi_v, x[9] - tt * math.sin(phi_v) * x[10] - tt * math.cos(phi_v) * x[11])
        if stop_ponr and monitor.point_of_no_return is not None:
            return "point_of_no_return"
    if abs(phi_v) > ROLL_LIMIT_RAD:
        if not record:
            xs.append(x), fzs.append(fz), ts.append(t_rel)
        return "roll_limit"
    return None


__all__ = ["ROLL_LIMIT_RAD", "ROS2_GAMMA", "feed_monitor", "keep_step", "propagate_generic", "propagate_reduced"]
