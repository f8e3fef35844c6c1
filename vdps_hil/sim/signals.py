"""Signals of a scenario file (``[inputs]`` channels, the driver's ``speed``): a function of the
simulation time from a TOML table, and :class:`ScenarioError`, the one-line error of scenario
files. A leaf module: :mod:`vdps_hil.sim.scenarios` and :mod:`vdps_hil.sim.driver` both use it.

Signals (tables; t is the simulation time [s])::

    {type = "const", value = V}
    {type = "sine", offset = O, amplitude = A, frequency_hz = F, phase_rad = 0, start_s = 0}
        O + A sin(2 pi F (t - start) + phase) for t >= start, O + A sin(phase) before
    {type = "sweep", offset = O, amplitude = A, f0_hz, f1_hz, start_s, duration_s}
        linear chirp O + A sin(2 pi (f0 tau + (f1 - f0) tau^2 / (2 T))), tau = t - start in [0, T], O outside
    {type = "points", points = [[t0, v0], [t1, v1], ...]}   piecewise linear, held beyond the ends
    {type = "step", t_s = T, before = 0, after = V}
  modifiers on any signal:
    hold_from_s = T         the value at T is held from T on
    then_s = T, then = {signal}    from T on the channel follows the other signal
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping


class ScenarioError(ValueError):
    """A scenario that cannot be used; the message is one line."""


def read_number(d: Mapping, key: str, where: str, default: float | None = None) -> float:
    if key not in d:
        if default is None:
            raise ScenarioError(f"{where}: missing key {key!r}")
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ScenarioError(f"{where}.{key}: expected a finite number, got {v!r}")
    return float(v)


_SIGNAL_KEYS = {
    "const": {"value"},
    "sine": {"offset", "amplitude", "frequency_hz", "phase_rad", "start_s"},
    "sweep": {"offset", "amplitude", "f0_hz", "f1_hz", "start_s", "duration_s"},
    "points": {"points"},
    "step": {"t_s", "before", "after"},
}
_MODIFIERS = {"type", "hold_from_s", "then_s", "then"}


def build_signal(spec: Any, where: str) -> Callable[[float], float]:
    """A function of time from a signal table (see the module docstring)."""
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        spec = {"type": "const", "value": spec}
    if not isinstance(spec, Mapping):
        raise ScenarioError(f"{where}: a signal must be a table or a number")
    kind = spec.get("type")
    if not isinstance(kind, str) or kind not in _SIGNAL_KEYS:
        raise ScenarioError(f"{where}: unknown signal type {kind!r} (known: {', '.join(_SIGNAL_KEYS)})")
    unknown = sorted(set(spec) - _SIGNAL_KEYS[kind] - _MODIFIERS)
    if unknown:
        raise ScenarioError(f"{where}: unknown key {unknown[0]!r} for a {kind} signal")
    if kind == "const":
        v = read_number(spec, "value", where)
        fn = lambda t, v=v: v  # noqa: E731
    elif kind == "sine":
        o, a = read_number(spec, "offset", where, 0.0), read_number(spec, "amplitude", where)
        w = 2.0 * math.pi * read_number(spec, "frequency_hz", where)
        ph, t0 = read_number(spec, "phase_rad", where, 0.0), read_number(spec, "start_s", where, 0.0)
        sin = math.sin

        def fn(t, o=o, a=a, w=w, ph=ph, t0=t0):
            return o + a * sin(w * (t - t0) + ph) if t >= t0 else o + a * sin(ph)
    elif kind == "sweep":
        o, a = read_number(spec, "offset", where, 0.0), read_number(spec, "amplitude", where)
        f0, f1 = read_number(spec, "f0_hz", where), read_number(spec, "f1_hz", where)
        t0, T = read_number(spec, "start_s", where, 0.0), read_number(spec, "duration_s", where)
        if T <= 0:
            raise ScenarioError(f"{where}.duration_s: must be positive")

        def fn(t, o=o, a=a, f0=f0, f1=f1, t0=t0, T=T):
            tau = t - t0
            if tau < 0.0 or tau > T:
                return o
            return o + a * math.sin(2.0 * math.pi * (f0 * tau + (f1 - f0) * tau * tau / (2.0 * T)))
    elif kind == "points":
        pts = spec.get("points")
        if (not isinstance(pts, list) or not pts
                or not all(isinstance(p, list) and len(p) == 2 for p in pts)):
            raise ScenarioError(f"{where}.points: expected a list of [t, value] pairs")
        ts = [read_number({"t": p[0]}, "t", where) for p in pts]
        vs = [read_number({"v": p[1]}, "v", where) for p in pts]
        if any(b < a for a, b in zip(ts, ts[1:])):
            raise ScenarioError(f"{where}.points: times must not decrease")

        def fn(t, ts=ts, vs=vs):
            if t <= ts[0]:
                return vs[0]
            if t >= ts[-1]:
                return vs[-1]
            # linear search is fine for the few points a schedule has
            for k in range(1, len(ts)):
                if t < ts[k]:
                    t_a, t_b = ts[k - 1], ts[k]
                    if t_b == t_a:
                        return vs[k]
                    return vs[k - 1] + (vs[k] - vs[k - 1]) * (t - t_a) / (t_b - t_a)
            return vs[-1]
    else:  # step
        ts_, b, a = read_number(spec, "t_s", where), read_number(spec, "before", where, 0.0), read_number(spec, "after", where)
        fn = lambda t, ts_=ts_, b=b, a=a: a if t >= ts_ else b  # noqa: E731
    if "then_s" in spec or "then" in spec:
        if "then_s" not in spec or "then" not in spec:
            raise ScenarioError(f"{where}: then_s and then go together")
        t_sw = read_number(spec, "then_s", where)
        other = build_signal(spec["then"], f"{where}.then")
        first = fn
        fn = lambda t, first=first, other=other, t_sw=t_sw: other(t) if t >= t_sw else first(t)  # noqa: E731
    if "hold_from_s" in spec:
        t_h = read_number(spec, "hold_from_s", where)
        inner = fn
        held = inner(t_h)
        fn = lambda t, inner=inner, t_h=t_h, held=held: held if t >= t_h else inner(t)  # noqa: E731
    return fn


__all__ = ["ScenarioError", "build_signal", "read_number"]
