"""The ranking in the words of a vehicle-dynamics engineer.

One sentence per candidate from its fitted parameters (e.g. "tire saturation: above 4.1 deg slip
angle the lateral force falls below the linear tire (peak friction 0.98 +- 0.04); explains 87 %
of the lateral residual on held-out data"), the equivalence groups with the maneuver that would
separate them, and "not excited" when the drive cannot show an effect.
"""

from __future__ import annotations

import math

from vdps_hil.units import GRAVITY_MPS2

from .candidate_base import PARAM_ALIASES, PARAM_LABELS, param_unit
from .coverage import EFFECT_NEEDS
from .residuals import EQUATION_LABELS

__all__ = ["describe_entry", "describe_ranking", "separating_maneuver", "group_maneuver", "EFFECT_LABELS",
           "equation_phrase"]

EFFECT_LABELS = {
    "aero_drag": "aerodynamic drag", "rolling_resistance": "rolling resistance",
    "magic_formula_tire": "tire saturation", "load_dependent_cornering_stiffness": "load-dependent cornering stiffness",
    "low_pressure_tire": "under-inflated tire", "crosswind": "crosswind", "steering_compliance": "steering compliance",
    "imu_bias": "IMU bias", "imu_lever_arm": "IMU lever arm", "steering_offset": "steering-angle offset",
    **{v: PARAM_LABELS[k] for k, v in PARAM_ALIASES.items()},
}
_WHEEL = {1: "front left", 2: "front right", 3: "rear right", 4: "rear left"}
_GROUP_LABELS = {"innov_att": "GNSS attitude innovations", "innov_vel": "GNSS velocity innovations",
                 "innov_pos": "GNSS position innovations"}

_MANEUVERS = {
    frozenset({"steering_compliance", "cornering_stiffness_front"}):
        "a kinematics-and-compliance measurement of the steering, or a steady-state circle up to the tire limit "
        "(compliance steer keeps growing with the front force while the tire saturates)",
    frozenset({"magic_formula_tire", "load_dependent_cornering_stiffness"}):
        "a steady-state circle ramped to the limit (saturation caps the lateral force at mu F_z, load "
        "sensitivity only lowers the slope) or a straight-line brake-in-turn that shifts load without lateral slip",
    frozenset({"rolling_resistance", "imu_bias"}):
        "an out-and-back coast-down on the same road (a sensor bias turns with the car, rolling resistance does not)",
    frozenset({"rolling_resistance", "aero_drag"}):
        "a coast-down over a wide speed range (drag grows with v^2, rolling resistance hardly changes)",
    frozenset({"aero_drag", "imu_bias"}): "a coast-down over a wide speed range, driven in both directions",
    frozenset({"crosswind", "imu_bias"}): "the same stretch driven in both directions (the wind's side force "
                                          "changes sign, a sensor bias does not)",
    frozenset({"imu_lever_arm", "inertia_z"}): "a slalom at two speeds (the lever arm acts on the lateral "
                                               "acceleration, the yaw inertia on the yaw moment)",
    frozenset({"imu_bias", "mass"}): "accelerations and braking at different levels (a bias is constant, the "
                                     "mass scales with the acceleration)",
    frozenset({"steering_offset", "crosswind"}): "the same stretch driven in both directions (the wind's side "
                                                 "force changes sign, a sensor offset does not)",
    frozenset({"steering_offset", "imu_bias"}): "straight driving at two speeds (the offset's side force at the "
                                                "front axle also turns the car: a yaw moment a bias lacks)",
}


def separating_maneuver(a: str, b: str) -> str:
    """A maneuver that separates two candidates (known pairs; generic advice otherwise)."""
    m = _MANEUVERS.get(frozenset({a, b}))
    if m:
        return m
    return ("a drive that excites them differently: vary speed, lateral acceleration and direction of travel "
            "independently")


def group_maneuver(members) -> str:
    """The separating maneuver for a group: a known pair inside it, else generic advice."""
    ms = list(members)
    for i, a in enumerate(ms):
        for b in ms[i + 1:]:
            if frozenset({a, b}) in _MANEUVERS:
                return _MANEUVERS[frozenset({a, b})]
    return separating_maneuver(ms[0], ms[-1])


def equation_phrase(eq: str) -> str:
    if eq in _GROUP_LABELS:
        return _GROUP_LABELS[eq]
    return EQUATION_LABELS.get(eq, eq).replace(" force", "").replace(" moment", "") + " residual" \
        if eq in EQUATION_LABELS else eq


def _main_equation(e) -> tuple[str, float] | None:
    best = None
    for g, f in e.explained_by_equation.items():
        w = e.explained_gain_by_equation.get(g, 0.0) if hasattr(e, "explained_gain_by_equation") else f
        if f is not None and math.isfinite(f) and f > 0 and (best is None or w > best[2]):
            best = (g, f, w)
    return (best[0], best[1]) if best else None


def _explains(e) -> str:
    main = _main_equation(e)
    # a sensor effect is judged on its GNSS innovations (``ranking.sensor_fit``), where the
    # overall fraction is the balance rows' model error
    if main is None or not (e.explained_fraction > 0 or main[0].startswith("innov_")):
        return "explains nothing on held-out data"
    g, f = main
    return f"explains {100 * f:.0f} % of the {equation_phrase(g)} on held-out data"


def _pv(e, name):
    v = e.parameters.get(name)
    return (v[0], v[1]) if v else (math.nan, math.nan)


def describe_entry(rk, e) -> str:
    """One sentence for a ranked candidate or an identified parameter."""
    label = EFFECT_LABELS.get(e.effect, e.effect.replace("_", " "))
    if e.kind == "parameter":
        (p, (v, s)), = e.parameters.items()
        ref = e.reference.get(p, math.nan)
        unit, k = param_unit(p)
        if not e.excited:
            return f"{label}: not excited on this drive, held at the model file's {ref / k:.4g} {unit}"
        if not e.plausible:
            return _implausible_parameter(label, e, p, v, s, ref, unit, k)
        msg = _checked_parameter(label, e.identifier, v, s, ref, unit, k)
        if e.group:
            alts = [g for g in e.group if g != e.effect]
            msg += ("; the same change would be explained by " + ", ".join(EFFECT_LABELS.get(a, a) for a in alts)
                    + " -- cannot be told apart on this drive; " + group_maneuver(e.group)
                    + " would separate them")
        return msg
    if not e.excited:
        need = EFFECT_NEEDS.get(e.effect)
        return (f"{label}: not excited -- this drive cannot show it (z = {e.excitation_z:.1f} at its typical size)"
                + (f"; needs {need}" if need else ""))
    body = _effect_words(rk, e)
    msg = f"{label}: {body}; {_explains(e)}"
    if not e.plausible:
        msg += " -- rejected, the fit is physically implausible"
    if e.group:
        alts = [g for g in e.group if g != e.effect]
        msg += ("; cannot be told apart on this drive from " + ", ".join(EFFECT_LABELS.get(a, a) for a in alts)
                + " (" + group_maneuver(e.group) + " would separate them)")
    return msg


def _implausible_parameter(label, e, p, v, s, ref, unit, k) -> str:
    """An identified value outside its plausible range: never called identified; the value the
    model keeps (the nearest bound) is named."""
    lo, hi = e.plausible_range.get(p, (0.0, math.inf))
    used = e.model_value.get(p, math.nan)
    why = ("negative, " if v <= 0 else "") + ("below" if v < lo else "above") + " the plausible range"
    rng = f"{lo / k:.4g}-{hi / k:.4g} {unit}" if math.isfinite(hi) else f"> {lo / k:.4g} {unit}"
    return (f"{label}: NOT identified -- implausible fit {v / k:.4g} +- {s / k:.2g} {unit}, {why} {rng} (model "
            f"file {ref / k:.4g} {unit}), the model keeps {used / k:.4g} {unit}; this drive does not determine "
            "it, or the base model misses an effect that it absorbs")


def _checked_parameter(label, idf: dict, v, s, ref, unit, k) -> str:
    """A plausible fitted value in the words of the identifier's verdict (``ranking.rls_check``):
    "identified" only when the identifier identified it too and agrees (or did not run)."""
    fit = f"{v / k:.4g} +- {s / k:.2g} {unit}"
    model = f"model file {ref / k:.4g} {unit}"
    verdict = idf.get("verdict")
    if verdict is None:
        return f"{label}: identified {fit} ({model})"
    other = f"{idf['value'] / k:.4g} +- {idf['sigma'] / k:.2g} {unit}"
    if verdict == "agrees":
        return f"{label}: identified {fit} ({model}), the identifier agrees ({other})"
    if verdict == "disagrees":
        return (f"{label}: not confirmed -- fitted {fit}, the identifier {other} on the same drive "
                f"(z = {idf['z']:.1f}): one of the two models does not fit this drive ({model})")
    return (f"{label}: not confirmed -- fitted {fit}, the identifier says \"{idf['status']}\" on this "
            f"drive ({model})")


def _effect_words(rk, e) -> str:
    name = e.effect
    veh = rk.base_vehicle
    if name == "aero_drag":
        v, s = _pv(e, "cda_m2")
        f25 = 0.5 * 1.225 * v * 25.0 ** 2
        return f"C_d A = {v:.3g} +- {s:.2g} m^2 ({f25:.0f} N of drag at 25 m/s)"
    if name == "rolling_resistance":
        v, s = _pv(e, "coefficient")
        return f"f_r = {v:.4f} +- {s:.4f} ({v * veh.params.mass_kg * GRAVITY_MPS2:.0f} N on this car)"
    if name == "magic_formula_tire":
        mu, smu = _pv(e, "peak_friction")
        cc = e.parameters.get("cornering_coefficient_per_rad")
        a = _saturation_angle_deg(rk, mu, cc[0] if cc else math.nan)
        where = f"above {a:.1f} deg slip angle " if math.isfinite(a) else ""
        sat = e.parameters.get("saturation_scale")
        scale = (f"{sat[0]:.2f} +- {sat[1]:.2f} times the generic tire's saturation, i.e. " if sat else "")
        common = (f"; the four tires' slip stiffness taken as one cornering coefficient, {cc[0]:.1f} per rad of "
                  "static load, as the axles' identified stiffnesses fitted it worse" if cc else "")
        return (f"{where}the lateral force falls below the linear tire ({scale}peak friction mu = {mu:.2f} +- "
                f"{smu:.2f} with the Magic Formula shape at its generic prior{common})")
    if name == "load_dependent_cornering_stiffness":
        a, sa = _pv(e, "load_slope")
        b, sb = _pv(e, "load_degression")
        loss = 1.0 - (1.0 - b * 0.25)  # axle stiffness loss at d = +-0.5 load transfer
        return (f"cornering stiffness grows less than the load (slope {a:.2f} +- {sa:.2f}, degression {b:.2f} +- "
                f"{sb:.2f}): an axle loses {100 * loss:.0f} % of its stiffness at 50 % load transfer")
    if name == "low_pressure_tire":
        w, _ = _pv(e, "wheel")
        v, s = _pv(e, "radius_reduction")
        wl = _WHEEL.get(int(round(w)), str(w))
        return (f"the {wl} wheel (wheel {int(round(w))}) rolls on a {100 * v:.2f} +- {100 * s:.2f} % smaller radius "
                "(it spins faster than the others at the same speed)")
    if name == "crosswind":
        sp, ss = _pv(e, "wind_speed_mps")
        d, _ = _pv(e, "wind_to_rad")
        frm = (math.degrees(d) + 180.0) % 360.0
        return (f"a steady wind of {sp:.1f} +- {ss:.1f} m/s blowing toward {math.degrees(d) % 360:.0f} deg "
                f"(from {frm:.0f} deg, CCW from East) pushes the car sideways")
    if name == "steering_compliance":
        v, s = _pv(e, "compliance_radpn")
        w_f = veh.params.mass_kg * GRAVITY_MPS2 * veh.geometry.l_r_m / veh.geometry.wheelbase_m
        dk = math.degrees(w_f * v)
        return (f"the front wheels yield {math.degrees(v) * 1e3:.3f} +- {math.degrees(s) * 1e3:.3f} deg per kN of "
                f"front lateral force ({dk:.2f} deg/g more understeer)")
    if name == "steering_offset":
        v, s = _pv(e, "offset_rad")
        return (f"the steering-angle sensor reads {math.degrees(v):+.2f} +- {math.degrees(s):.2f} deg at the steering "
                f"wheel when the front wheels point straight ahead ({math.degrees(v / veh.geometry.steer_ratio):+.3f} "
                "deg at the road wheels)")
    if name == "imu_bias":
        parts = []
        for a in "xyz":
            v, s = _pv(e, f"accel_bias_{a}_mps2")
            parts.append(f"a_{a} {v:+.3f}+-{s:.3f}")
        for a in "xyz":
            v, s = _pv(e, f"gyro_bias_{a}_radps")
            parts.append(f"w_{a} {math.degrees(v):+.3f}+-{math.degrees(s):.3f}")
        return "sensor offsets (accelerometer m/s^2, gyro deg/s): " + ", ".join(parts)
    if name == "imu_lever_arm":
        xs = [_pv(e, f"lever_{a}_m") for a in "xyz"]
        return ("the IMU sits at (" + ", ".join(f"{v:+.2f}+-{s:.2f}" for v, s in xs)
                + ") m from the CG, so its accelerometers see the body's rotation")
    return _generic_words(e.parameters)


def _generic_words(parameters) -> str:
    """``name = v +- s`` per parameter; a parameter whose sigma is not below its size is said to
    be undetermined, and two or more such say that only a combination of them is (a collinear
    pair such as an axle's front and rear anti-roll stiffness: on CommonRoad's set-3 circle
    1.71e+04 +- 7.2e+08 each, printed as if identified)."""
    loose = [k for k, (v, s) in parameters.items() if not abs(v) > s]
    parts = [f"{k} = {v:.4g} +- {s:.2g}" + (" (not determined on this drive)" if k in loose and len(loose) == 1 else "")
             for k, (v, s) in parameters.items()]
    text = ", ".join(parts) if parts else "fitted"
    if len(loose) >= 2:
        text += (f" ({' and '.join(loose)} cannot be told apart on this drive: each sigma exceeds its value, only a "
                 "combination of them is determined)")
    return text


def _saturation_angle_deg(rk, mu: float, coefficient_per_rad: float = math.nan, drop: float = 0.05) -> float:
    """Slip angle where the Magic Formula lateral force of a front tire at its static load falls
    ``drop`` below the linear tire (shape factors at the generic prior); its slip stiffness is
    half the front axle's, or ``coefficient_per_rad`` times its load when given (the saturation
    candidate's ``"common"`` normalisation)."""
    from vdps_hil.model.effects import MagicFormulaTire

    if not (mu > 0 and math.isfinite(mu)):
        return math.nan
    spec = {p.name: p.default for p in MagicFormulaTire.PARAMS}
    c, e = spec["shape_lateral"], spec["curvature_lateral"]
    lo, hi = 1e-4, 1.2
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if MagicFormulaTire.shape(mid, c, e) / mid > 1.0 - drop:
            lo = mid
        else:
            hi = mid
    veh = rk.base_vehicle
    fz = veh.params.mass_kg * GRAVITY_MPS2 * veh.geometry.l_r_m / veh.geometry.wheelbase_m / 2.0
    ca = coefficient_per_rad * fz if math.isfinite(coefficient_per_rad) else veh.params.cornering_stiffness_front_nprad / 2.0
    return math.degrees(lo * mu * fz / ca)


def describe_ranking(rk) -> list[str]:
    """Headline lines: the recommendation (or none), the equivalence groups."""
    out = []
    if rk.recommendation:
        e = rk.entry(rk.recommendation)
        out.append("missing: " + describe_entry(rk, e))
        for extra in rk.selected[1:]:
            out.append("also missing: " + describe_entry(rk, rk.entry(extra)))
    else:
        out.append("no missing effect found: no candidate explains enough of the held-out residual with plausible "
                   "values")
    for g in rk.groups:
        mem = g["members"]
        if rk.recommendation and rk.recommendation in mem:
            rec = rk.recommendation
            if mem[0] != rec and mem[0] not in rk.equivalent_to:
                # another candidate's fit is reproduced by the recommended effect, not the other
                # way round: the recommendation is the better explanation, the other one is not
                # ruled out
                lead = EFFECT_LABELS.get(mem[0], mem[0])
                out.append(f"also consistent with this drive: {lead} (what it would explain, "
                           f"{EFFECT_LABELS.get(rec, rec)} explains too, and significantly more; "
                           f"{group_maneuver(mem)} would separate them)")
            continue
        lead = mem[0]
        alts = mem[1:]
        out.append(f"cannot be told apart on this drive: {EFFECT_LABELS.get(lead, lead)} and "
                   + ", ".join(EFFECT_LABELS.get(a, a) for a in alts) + " (" + group_maneuver(mem)
                   + " would separate them)")
    return out
