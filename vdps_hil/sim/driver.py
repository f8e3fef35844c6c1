"""Driver model for closed-loop maneuvers: pure-pursuit path following and PI speed control.

Steering (pure pursuit with understeer feed-forward)::

    L_d     = max(lookahead_min_m, lookahead_time_s * v)          look-ahead distance [m]
    alpha   = angle to the path point L_d ahead of the nearest path point, seen from the CG
              in the vehicle's heading frame                         [rad]
    kappa   = 2 sin(alpha) / L_d                                     path curvature to follow [1/m]
    delta_m = atan(L kappa) + K_us v^2 kappa                          bicycle road-wheel angle [rad]
    delta_sw = steer_ratio * delta_m, limited to +-max_steer_wheel_rad and to
               max_steer_rate_radps (a human hand)                   [rad]

K_us is the vehicle's linear understeer gradient m_f/C_f - m_r/C_r [rad/(m/s^2)] (a driver who
knows the car), or ``understeer_gradient_radpmps2`` from the spec.

Speed (PI on the speed error, force demand distributed to wheels)::

    F   = m clamp(k_p e + k_i integral(e), -8, +4 m/s^2),  e = v_target(t) - v      [N]
          (the integral runs only while |e| < 2 m/s and the demand is not clamped: anti-windup)
    F >= 0: drive torque F r / n on the driven wheels (``drive`` = "fwd", "rwd" or "awd")
    F <  0: brake torques |F| r split front/rear by ``brake_front_share``

Paths (``[driver] path = {...}``, coordinates x along the initial heading, y to its left, from
the initial position; ``type``):

* ``straight``: a straight line.
* ``circle``: ``radius_m`` (> 0 turns left), entered tangentially after ``entry_m`` of straight.
* ``iso3888``: ISO 3888-1 double lane change centre line: ``entry_m`` of straight, then 15 m
  (section 1), 30 m transition, 25 m at ``offset_m`` (default 3.5 m to the left), 25 m
  transition, 15 m back on the original line, then straight. Transitions are half-cosines.
* ``points``: ``points = [[x, y], ...]`` polyline.

Spec keys (``[driver]``): path, speed (a signal, see ``sim.signals``; omitted: no speed control,
zero torque), lookahead_time_s (0.8), lookahead_min_m (5.0), speed_kp_per_s (1.0),
speed_ki_per_s2 (0.3), drive ("awd"), brake_front_share (0.6), max_steer_wheel_rad (8.0),
max_steer_rate_radps (15.0, about 860 deg/s), understeer_gradient_radpmps2 (from the vehicle),
update_period_s (0.01: the driver acts at 100 Hz and holds its outputs in between).
Without ``path`` the driver only controls speed (the steering channel comes from ``[inputs]``).
"""

from __future__ import annotations

import math
from bisect import bisect_left
from typing import Any, Mapping, Sequence

from vdps_hil.model.core import Env, Inputs
from vdps_hil.units import GRAVITY_MPS2

from .signals import ScenarioError, build_signal

_SPEC_KEYS = {"path", "speed", "lookahead_time_s", "lookahead_min_m", "speed_kp_per_s", "speed_ki_per_s2",
              "drive", "brake_front_share", "max_steer_wheel_rad", "max_steer_rate_radps",
              "understeer_gradient_radpmps2", "update_period_s"}
_PATH_KEYS = {"straight": {"length_m"}, "circle": {"radius_m", "entry_m"},
              "iso3888": {"entry_m", "offset_m", "exit_m"}, "points": {"points"}}


def _err(where: str, msg: str) -> ScenarioError:
    return ScenarioError(f"{where}: {msg}")


def validate_driver_spec(spec: Mapping[str, Any], where: str) -> None:
    """Raise ScenarioError for unknown keys or bad values."""
    unknown = sorted(set(spec) - _SPEC_KEYS)
    if unknown:
        raise _err(where, f"unknown key {unknown[0]!r}")
    for k in _SPEC_KEYS - {"path", "speed", "drive"}:
        if k in spec:
            v = spec[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise _err(where, f"{k} must be a finite number")
    if spec.get("drive", "awd") not in ("fwd", "rwd", "awd"):
        raise _err(where, "drive must be fwd, rwd or awd")
    if "path" in spec:
        p = spec["path"]
        if not isinstance(p, Mapping) or not isinstance(p.get("type"), str) or p.get("type") not in _PATH_KEYS:
            raise _err(where, f"path.type must be one of {', '.join(_PATH_KEYS)}")
        bad = sorted(set(p) - _PATH_KEYS[p["type"]] - {"type"})
        if bad:
            raise _err(where, f"path: unknown key {bad[0]!r} for a {p['type']} path")
        if p["type"] == "circle" and not isinstance(p.get("radius_m"), (int, float)):
            raise _err(where, "path.radius_m is required for a circle")
        if p["type"] == "points":
            pts = p.get("points")
            if not isinstance(pts, list) or len(pts) < 2 or not all(isinstance(q, list) and len(q) == 2 for q in pts):
                raise _err(where, "path.points must be a list of >= 2 [x, y] pairs")
    if "speed" in spec:
        build_signal(spec["speed"], f"{where}.speed")


class ReferencePath:
    """A polyline path in ENU with arc length; nearest-point search from a hint index."""

    def __init__(self, xy: Sequence[tuple[float, float]]):
        if len(xy) < 2:
            raise ValueError("a path needs at least 2 points")
        self.x = [float(p[0]) for p in xy]
        self.y = [float(p[1]) for p in xy]
        s = [0.0]
        for k in range(1, len(xy)):
            s.append(s[-1] + math.hypot(self.x[k] - self.x[k - 1], self.y[k] - self.y[k - 1]))
        self.s = s
        self.length_m = s[-1]
        self._hint = -1

    def nearest(self, px: float, py: float, window: int = 40) -> float:
        """Arc length of the point on the path nearest to (px, py): a full search the first
        time, then a window around the last result (paths are followed in order)."""
        best, best_s, bk = math.inf, 0.0, 0
        if self._hint < 0:
            k0, k1 = 0, len(self.x) - 1
        else:
            k0 = max(0, self._hint - 5)
            k1 = min(len(self.x) - 1, self._hint + window)
        for k in range(k0, k1):
            ax, ay, bx, by = self.x[k], self.y[k], self.x[k + 1], self.y[k + 1]
            dx, dy = bx - ax, by - ay
            seg2 = dx * dx + dy * dy
            u = 0.0 if seg2 == 0.0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / seg2))
            qx, qy = ax + u * dx, ay + u * dy
            d2 = (px - qx) ** 2 + (py - qy) ** 2
            if d2 < best:
                best, best_s, bk = d2, self.s[k] + u * math.sqrt(seg2), k
        self._hint = bk
        return best_s

    def point_at(self, s: float) -> tuple[float, float]:
        if s <= 0.0:
            return self.x[0], self.y[0]
        if s >= self.length_m:
            # extend along the last segment
            dx, dy = self.x[-1] - self.x[-2], self.y[-1] - self.y[-2]
            n = math.hypot(dx, dy)
            e = s - self.length_m
            return self.x[-1] + e * dx / n, self.y[-1] + e * dy / n
        k = bisect_left(self.s, s) - 1
        k = max(0, min(k, len(self.s) - 2))
        u = (s - self.s[k]) / (self.s[k + 1] - self.s[k])
        return self.x[k] + u * (self.x[k + 1] - self.x[k]), self.y[k] + u * (self.y[k + 1] - self.y[k])


def path_local_points(spec: Mapping[str, Any], step_m: float = 0.5) -> list[tuple[float, float]]:
    """The path's points in its local frame (x along the initial heading, y left)."""
    kind = spec["type"]
    pts: list[tuple[float, float]] = []
    if kind == "straight":
        length = float(spec.get("length_m", 5000.0))
        n = max(2, int(length / 5.0))
        return [(length * k / (n - 1), 0.0) for k in range(n)]
    if kind == "circle":
        R = float(spec["radius_m"])
        entry = float(spec.get("entry_m", 0.0))
        if entry > 0:
            pts += [(x, 0.0) for x in _frange(-5.0, entry, step_m)]
        else:
            pts.append((-5.0, 0.0))
        # 20 laps of circle, centre at (entry, R)
        n = int(20 * 2 * math.pi * abs(R) / step_m)
        for k in range(n + 1):
            a = k * step_m / abs(R)
            pts.append((entry + abs(R) * math.sin(a), R - R * math.cos(a)))
        return pts
    if kind == "iso3888":
        entry = float(spec.get("entry_m", 50.0))
        off = float(spec.get("offset_m", 3.5))
        exit_ = float(spec.get("exit_m", 100.0))
        marks = [(-5.0, 0.0), (entry + 15.0, 0.0), (entry + 45.0, off), (entry + 70.0, off),
                 (entry + 95.0, 0.0), (entry + 110.0 + exit_, 0.0)]
        for (xa, ya), (xb, yb) in zip(marks, marks[1:]):
            for x in _frange(xa, xb, step_m):
                u = (x - xa) / (xb - xa)
                pts.append((x, ya + (yb - ya) * 0.5 * (1.0 - math.cos(math.pi * u))))
        pts.append(marks[-1])
        return pts
    return [(float(p[0]), float(p[1])) for p in spec["points"]]


def _frange(a: float, b: float, step: float):
    n = max(1, int(math.ceil((b - a) / step)))
    return [a + (b - a) * k / n for k in range(n)]


def make_path(spec: Mapping[str, Any], east_m: float, north_m: float, heading_rad: float) -> ReferencePath:
    """The path of a ``[driver] path`` table placed at the initial position and heading (ENU)."""
    ch, sh = math.cos(heading_rad), math.sin(heading_rad)
    return ReferencePath([(east_m + ch * x - sh * y, north_m + sh * x + ch * y) for x, y in path_local_points(spec)])


class Driver:
    """``driver(t, x) -> Inputs``: pure pursuit on ``path`` (None: steering 0) and PI speed
    control to ``speed(t)`` (None: zero torque). Call once per simulation step, in time order."""

    def __init__(self, model, env: Env, path: ReferencePath | None, speed=None, *, lookahead_time_s: float = 0.8,
                 lookahead_min_m: float = 5.0, speed_kp_per_s: float = 1.0, speed_ki_per_s2: float = 0.3,
                 drive: str = "awd", brake_front_share: float = 0.6, max_steer_wheel_rad: float = 8.0,
                 max_steer_rate_radps: float = 15.0, understeer_gradient_radpmps2: float | None = None,
                 update_period_s: float = 0.01):
        self.model = model
        self.path = path
        self.speed = speed
        veh = model.vehicle
        self.L = veh.geometry.wheelbase_m
        self.ratio = veh.geometry.steer_ratio
        if understeer_gradient_radpmps2 is None:
            sl = model.static_load_n
            p = veh.params
            understeer_gradient_radpmps2 = ((sl[0] + sl[1]) / GRAVITY_MPS2 / p.cornering_stiffness_front_nprad
                                            - (sl[2] + sl[3]) / GRAVITY_MPS2 / p.cornering_stiffness_rear_nprad)
        self.k_us = understeer_gradient_radpmps2
        self.t_la, self.la_min = lookahead_time_s, lookahead_min_m
        self.kp, self.ki = speed_kp_per_s, speed_ki_per_s2
        self.mass = veh.params.mass_kg
        self.r = model.rolling_radius_m
        self.driven = {"fwd": (0, 1), "rwd": (2, 3), "awd": (0, 1, 2, 3)}[drive]
        self.bf = brake_front_share
        self.max_sw, self.max_rate = max_steer_wheel_rad, max_steer_rate_radps
        self.period = update_period_s
        self._int = 0.0
        self._t = None
        self._sw = None
        self._u = None
        self.last_target_speed_mps = math.nan

    def steer(self, x) -> float:
        if self.path is None:
            return 0.0
        pe, pn, psi = x[0], x[1], x[5]
        v = max(1.0, math.hypot(x[6], x[7]))
        s = self.path.nearest(pe, pn)
        ld = max(self.la_min, self.t_la * v)
        tx, ty = self.path.point_at(s + ld)
        dx, dy = tx - pe, ty - pn
        c, sn = math.cos(psi), math.sin(psi)
        lx, ly = c * dx + sn * dy, -sn * dx + c * dy
        alpha = math.atan2(ly, lx)
        dist = math.hypot(lx, ly)
        kappa = 2.0 * math.sin(alpha) / max(dist, 1e-3)
        delta = math.atan(self.L * kappa) + self.k_us * v * v * kappa
        return self.ratio * delta

    def __call__(self, t: float, x) -> Inputs:
        if self._u is not None and t < self._t + self.period - 1e-9:
            return self._u
        dt = 0.0 if self._t is None else t - self._t
        self._t = t
        sw = max(-self.max_sw, min(self.max_sw, self.steer(x)))
        if self._sw is not None and dt > 0:
            lim = self.max_rate * dt
            sw = max(self._sw - lim, min(self._sw + lim, sw))
        self._sw = sw
        tq = [0.0, 0.0, 0.0, 0.0]
        br = [0.0, 0.0, 0.0, 0.0]
        if self.speed is not None:
            vt = self.speed(t)
            self.last_target_speed_mps = vt
            e = vt - x[6]
            a_p = self.kp * e
            if abs(e) < 2.0 and -8.0 < a_p + self.ki * self._int < 4.0:
                self._int += e * dt  # conditional integration (anti-windup)
            a_cmd = max(-8.0, min(4.0, a_p + self.ki * self._int))
            f = self.mass * a_cmd
            if f >= 0.0:
                for i in self.driven:
                    tq[i] = f * self.r[i] / len(self.driven)
            else:
                for i in range(4):
                    share = self.bf / 2.0 if i < 2 else (1.0 - self.bf) / 2.0
                    br[i] = -f * self.r[i] * share
        u = object.__new__(Inputs)
        object.__setattr__(u, "steer_wheel_angle_rad", sw)
        object.__setattr__(u, "wheel_torque_nm", tuple(tq))
        object.__setattr__(u, "brake_torque_nm", tuple(br))
        self._u = u
        return u


def make_driver(spec: Mapping[str, Any], model, env: Env, scenario, where: str = "[driver]") -> Driver:
    """A Driver from a scenario's [driver] table."""
    validate_driver_spec(spec, where)
    path = None
    if "path" in spec:
        path = make_path(spec["path"], scenario.initial_east_m, scenario.initial_north_m, scenario.initial_heading_rad)
    speed = build_signal(spec["speed"], f"{where}.speed") if "speed" in spec else None
    kw = {k: float(spec[k]) for k in ("lookahead_time_s", "lookahead_min_m", "speed_kp_per_s", "speed_ki_per_s2",
                                      "brake_front_share", "max_steer_wheel_rad", "max_steer_rate_radps",
                                      "understeer_gradient_radpmps2", "update_period_s") if k in spec}
    return Driver(model, env, path, speed, drive=spec.get("drive", "awd"), **kw)
