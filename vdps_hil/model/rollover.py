"""Rollover, defined once for the whole project.

* **Tip-up**: both tires of one side (the inside of the turn) carry less than 1 % of their
  static normal load for at least 0.2 s. The event time is the start of that interval; it is
  confirmed 0.2 s later.
* **Point of no return (PONR)**: the roll angle relative to the road |phi_v| exceeds the static
  tip angle atan(t_half / h_cg) while the roll rate is still increasing it (phi_v * phi_v_dot > 0).
  t_half is the mean half track, h_cg the CG height at design ride height (the rigid-vehicle
  static tip angle: the CG is then above the outer contact line).
* **Outcome** of a run (for maps): ``tip-up`` (a tip-up happened), ``spin-out`` (no tip-up, but the
  body sideslip |beta| = |atan2(v_y, |v_x|)| exceeded ``SPIN_OUT_SIDESLIP_RAD`` = 20 deg), else
  ``stable``.

:class:`RolloverMonitor` is fed truth samples (normal loads, road-relative roll and its rate)
and reports events; the simulator uses it and may stop at the PONR (no body-ground contact model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

TIP_UP_LOAD_FRACTION = 0.01
TIP_UP_MIN_DURATION_S = 0.2
SPIN_OUT_SIDESLIP_RAD = math.radians(20.0)


def static_tip_angle_rad(track_half_m: float, h_cg_m: float) -> float:
    """atan(t_half / h_cg) [rad]."""
    return math.atan2(track_half_m, h_cg_m)


@dataclass
class RolloverEvent:
    kind: str  # "tip_up" or "point_of_no_return"
    t_s: float  # when it happened (tip-up: start of the 0.2 s interval)
    side: str  # "left" or "right": the side that lifted / the side the body rolls away from
    detail: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"kind": self.kind, "t_s": self.t_s, "side": self.side, **self.detail}


class RolloverMonitor:
    """Tip-up and point-of-no-return detector (definitions in the module docstring).

    ``update(t_s, normal_loads_n, roll_rel_road_rad, roll_rate_rel_road_radps)`` returns the list
    of events newly detected at this sample."""

    def __init__(self, static_loads_n, track_half_m: float, h_cg_m: float):
        self.static_loads_n = tuple(float(s) for s in static_loads_n)
        self.tip_angle_rad = static_tip_angle_rad(track_half_m, h_cg_m)
        self._low_since = {"left": None, "right": None}
        self._thr = tuple(TIP_UP_LOAD_FRACTION * s for s in self.static_loads_n)
        self.tip_up: RolloverEvent | None = None
        self.point_of_no_return: RolloverEvent | None = None
        self.events: list[RolloverEvent] = []

    def update(self, t_s: float, normal_loads_n, roll_rel_road_rad: float,
               roll_rate_rel_road_radps: float) -> list[RolloverEvent]:
        fz = normal_loads_n
        thr = self._thr
        low_l = fz[0] < thr[0] and fz[3] < thr[3]
        low_r = fz[1] < thr[1] and fz[2] < thr[2]
        ls = self._low_since
        if (not (low_l or low_r) and ls["left"] is None and ls["right"] is None
                and (self.point_of_no_return is not None or abs(roll_rel_road_rad) <= self.tip_angle_rad)):
            return []  # nothing can change (the common case; called every step by the predictor)
        new: list[RolloverEvent] = []
        low = {"left": low_l, "right": low_r}
        for side in ("left", "right"):
            if low[side]:
                if self._low_since[side] is None:
                    self._low_since[side] = t_s
                elif (self.tip_up is None
                      and t_s - self._low_since[side] >= TIP_UP_MIN_DURATION_S - 1e-9):
                    ev = RolloverEvent("tip_up", self._low_since[side], side, {"confirmed_t_s": t_s})
                    self.tip_up = ev
                    new.append(ev)
            else:
                self._low_since[side] = None
        if (self.point_of_no_return is None and abs(roll_rel_road_rad) > self.tip_angle_rad
                and roll_rel_road_rad * roll_rate_rel_road_radps > 0.0):
            # roll right-side-down positive: positive roll lifts the left side
            side = "left" if roll_rel_road_rad > 0.0 else "right"
            ev = RolloverEvent("point_of_no_return", t_s, side,
                               {"roll_rel_road_rad": roll_rel_road_rad, "tip_angle_rad": self.tip_angle_rad})
            self.point_of_no_return = ev
            new.append(ev)
        self.events.extend(new)
        return new


def classify_outcome(tip_up: bool, max_abs_sideslip_rad: float) -> str:
    """'tip-up', 'spin-out' or 'stable' (definitions in the module docstring)."""
    if tip_up:
        return "tip-up"
    if max_abs_sideslip_rad > SPIN_OUT_SIDESLIP_RAD:
        return "spin-out"
    return "stable"


def with_static_stability_factor(vehicle, ssf: float):
    """The vehicle with its CG height set so that t_half / h_cg = ssf (everything else kept):
    the parametric axis of the outcome map."""
    import dataclasses
    g = vehicle.geometry
    t_half = 0.5 * (g.track_half_front_m + g.track_half_rear_m)
    return dataclasses.replace(vehicle, geometry=dataclasses.replace(g, h_cg_m=t_half / ssf))


@dataclass
class RolloverAssessment:
    """Outcome of one run: outcome class, event times [s] (NaN when absent), peaks."""

    outcome: str
    tip_up_t_s: float
    point_of_no_return_t_s: float
    max_abs_sideslip_rad: float
    max_abs_roll_rel_road_rad: float
    max_abs_ltr: float

    def to_json(self) -> dict:
        return dict(self.__dict__)


def assess(sim, t_from_s: float = 0.0) -> RolloverAssessment:
    """Classify a finished simulation (truth from ``t_from_s`` on)."""
    tr = [s for s in sim.truth if s["t_s"] >= t_from_s]
    beta = max((abs(s["sideslip_rad"]) for s in tr), default=0.0)
    roll = max((abs(s["roll_v_rad"]) for s in tr), default=0.0)
    ltr = max((abs(s["ltr"]) for s in tr), default=0.0)
    tu, pn = sim.rollover.tip_up, sim.rollover.point_of_no_return
    return RolloverAssessment(classify_outcome(tu is not None, beta), tu.t_s if tu else math.nan,
                              pn.t_s if pn else math.nan, beta, roll, ltr)
