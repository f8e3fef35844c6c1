"""What ``vdps diagnose --add`` can claim about each parameter of an effect it fitted.

The identifier never calls a value on or near its bound identified (issue 17,
``identification.status``); the ``--add`` fit clips an added effect's parameters into their
physical range (``ParamSpec`` lower/upper, ``Candidate.clip_phi``) and used to report a clipped
value with the sigma of an interior point, e.g. a Magic Formula peak friction of 1.6 +- 0.003 on
CommonRoad's set 1 circle ramp (its upper bound; the truth's p_dy1 is 1.05, the ranking's
screening fit 1.03). Each parameter now carries one status, in the JSON, the text and the HTML:

``fitted``
    moved by the fit, with a sigma, away from its bounds;
``at bound``
    within ``BOUND_MARGIN`` of its range's width from a bound (the identifier's
    ``bound_margin``, 2 %): not identified -- the drive does not determine it, or the base model
    misses something it absorbs. The "after" figures were computed with this value, so it is
    still shown, as what the model used, never as a result;
``held``
    not fitted (no sigma): the effect's generic prior, kept (the Magic Formula's shape and
    curvature factors, which the ``--add`` fit does not move);
``at start``
    a parameter the fit was to move but no step of it kept (``add._descend``): still its start,
    the generic prior, so neither a fitted value nor a sigma (on our own circle ramp with the Magic
    Formula hidden the friction stayed at exactly 1.0 and was printed "fitted 1 +- 0.003").
"""

from __future__ import annotations

import math

from vdps_hil.identification.config import StatusConfig
from vdps_hil.model.effects.base import Effect

from .candidate_base import BASE_PARAMS, PARAM_LABELS, param_unit

__all__ = ["BOUND_MARGIN", "parameter_entries", "added_entries", "at_bound", "not_fitted", "added_parameter_lines",
           "IDENTIFIED_KEY"]

BOUND_MARGIN = StatusConfig().bound_margin
"""A fitted value within this fraction of its range's width from a bound is "at bound"."""
IDENTIFIED_KEY = "identified"
"""The key of ``AddResult.parameters`` that holds the ten parameters before and after (not an effect)."""


def _status(value: float, sigma, lower: float, upper: float) -> tuple[str, str | None]:
    """(status, side): side "lower"/"upper" for a value at a bound (module docstring)."""
    if sigma is None:
        return "held", None
    if math.isfinite(lower) and math.isfinite(upper) and upper > lower:
        m = BOUND_MARGIN * (upper - lower)
        if value <= lower + m:
            return "at bound", "lower"
        if value >= upper - m:
            return "at bound", "upper"
    return "fitted", None


def parameter_entries(effect: Effect, sigmas: dict, at_start: bool = False) -> dict[str, dict]:
    """Parameter -> {value, sigma, status, bound, lower, upper, unit} of one added ``effect``;
    ``sigmas``: the fit's sigmas of the parameters it fitted (the others are held); ``at_start``:
    no step of the fit moved them (``FittedModel.at_start``)."""
    specs = {p.name: p for p in getattr(effect, "PARAMS", ())}
    out = {}
    for k, v in effect.params.items():
        s = sigmas.get(k)
        spec = specs.get(k)
        lo, hi = (spec.lower, spec.upper) if spec is not None else (-math.inf, math.inf)
        status, side = _status(float(v), s, lo, hi)
        if at_start and status == "fitted":
            status = "at start"
        out[k] = {"value": v, "sigma": s if status == "fitted" else None, "status": status, "bound": side,
                  "lower": lo if math.isfinite(lo) else None, "upper": hi if math.isfinite(hi) else None,
                  "unit": spec.unit if spec is not None else ""}
    return out


def added_entries(parameters: dict):
    """(effect, {parameter: entry}) of each added effect in ``AddResult.parameters`` (not the ten
    parameters' before/after under :data:`IDENTIFIED_KEY`)."""
    return ((e, ps) for e, ps in parameters.items() if e != IDENTIFIED_KEY)


def _with_status(parameters: dict, *statuses: str) -> list[tuple[str, str]]:
    return [(e, k) for e, ps in added_entries(parameters) for k, d in ps.items() if d.get("status") in statuses]


def at_bound(parameters: dict) -> list[tuple[str, str]]:
    """(effect, parameter) of every added parameter at a bound (``AddResult.parameters``)."""
    return _with_status(parameters, "at bound")


def not_fitted(parameters: dict) -> list[tuple[str, str]]:
    """(effect, parameter) of every added parameter the fit did not determine: at a bound or
    still at its start (``AddResult.parameters``)."""
    return _with_status(parameters, "at bound", "at start")


def _unit(unit: str) -> str:
    return "" if unit in ("1", "") else " " + unit


def _fmt_range(d: dict) -> str:
    lo, hi = d.get("lower"), d.get("upper")
    return f"{lo:.4g}-{hi:.4g}" if lo is not None and hi is not None else "its range"


def added_parameter_lines(parameters: dict, labels: dict | None = None) -> list[str]:
    """The text lines of the added effects' parameters and of the ten parameters they moved;
    ``labels``: effect -> label."""
    labels = labels or {}
    out = []
    for e, ps in added_entries(parameters):
        out.append(f"added {labels.get(e, e)} ({e}):")
        held = []
        for k, d in ps.items():
            u = _unit(d.get("unit", ""))
            v = d["value"]
            if d["status"] == "held":
                held.append(f"{k} {v:.4g}{u}")
            elif d["status"] == "at bound":
                out.append(f"  {k}: AT BOUND -- {v:.4g}{u}, the {d['bound']} bound of {_fmt_range(d)}: not "
                           "identified (the drive does not determine it or shows none of it, or the model misses "
                           "an effect that pulls it there); the 'after' figures use this value")
            elif d["status"] == "at start":
                out.append(f"  {k}: AT START -- {v:.4g}{u}, the generic prior: no step of the fit lowered its "
                           "objective, so not a fitted value (the base model may hold an error that this value "
                           "would have to make up for); the 'after' figures use this value")
            else:
                s = d.get("sigma")
                out.append(f"  {k}: fitted {v:.4g}" + (f" +- {s:.2g}" if s is not None else "") + u)
        if held:
            out.append("  held at the generic prior: " + ", ".join(held))
    moved = []
    for k, d in parameters.get(IDENTIFIED_KEY, {}).items():
        b, a = d.get("before"), d.get("after")
        if k in BASE_PARAMS and b and a is not None and abs(a - b) > 0.01 * abs(b):
            unit, scale = param_unit(k)
            moved.append(f"{PARAM_LABELS.get(k, k)} {b / scale:.4g} -> {a / scale:.4g} {unit} ({100 * (a - b) / b:+.0f} %)")
    if moved:
        out.append("re-identified with them (changes above 1 %): " + ", ".join(moved))
    return out

