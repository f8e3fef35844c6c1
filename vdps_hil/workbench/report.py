"""The diagnosis as one self-contained HTML page (``--report DIR`` -> ``DIR/report.html``).

Everything is inside the file: the figures (``report_figures``) as SVG ``data:`` URIs (vector:
zoom the page to read them), inline CSS, no script, no external URL. Sections: summary in
vehicle-dynamics words; measured against model (the force and moment balances the ranking works
on); the residual with the worst windows marked (the cleaned residual whose RMS the tables give,
the raw one faint behind it, each labelled); the residual against the operating regime; the
ranking with its equivalence groups and the identified parameters; the recommended effect's
signed residual against its regressor with the fitted law drawn; before/after (``--add``): the
cleaned residual RMS of every equation, every quantity of the held-out prediction error (position,
yaw, roll, speed) per horizon, and its trace over the held-out starts.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from . import report_figures as F
from .add import residual_change, rms_by_equation
from .added_params import added_entries
from .residuals import EQUATION_LABELS, EQUATION_UNITS, EQUATIONS

__all__ = ["write_report", "render_report"]

_CSS = """
body{font-family:sans-serif;margin:2em;max-width:70em;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:2em}
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;padding:2px 6px;font-size:0.9em}
th{background:#f0f0f0}.sel{background:#e8f4e8}.msg{margin:0.2em 0}img{width:100%;display:block;margin:0.5em 0}
.small{color:#666;font-size:0.85em}
"""


def _main_equations(dg, k: int = 3) -> list[str]:
    """The equations with the largest noise-weighted residual (plus the recommendation's)."""
    res = dg.residuals
    with np.errstate(invalid="ignore", divide="ignore"):
        z2 = (res.values / res.sigma) ** 2
    fin = np.isfinite(z2)
    # mean over the evaluated rows; NaN for an equation a partial sensor set does not evaluate
    w = np.where(fin.any(axis=0), np.where(fin, z2, 0.0).sum(axis=0) / np.maximum(fin.sum(axis=0), 1), np.nan)
    order = [EQUATIONS[i] for i in np.argsort(-np.nan_to_num(w)) if res.available[i] and np.isfinite(w[i])]
    eqs = [e for e in ("long", "lat", "yaw") if e in order]
    rec = dg.ranking.entry(dg.ranking.recommendation) if dg.ranking.recommendation else None
    if rec is not None and rec.explained_by_equation:
        best = max(rec.explained_by_equation.items(), key=lambda kv: rec.explained_gain_by_equation.get(kv[0], 0.0))[0]
        if best in EQUATIONS and best not in eqs:
            eqs.insert(0, best)
    for e in order:
        if len(eqs) >= k + 1:
            break
        if e not in eqs:
            eqs.append(e)
    return eqs[:k + 1]


def _measured(dg, eq: str) -> np.ndarray:
    """The measured side of an equation on the residual rows (units of the equation)."""
    res = dg.residuals
    m = res.meas
    p = res.vehicle.params
    k = EQUATIONS.index(eq)
    if k < 3:
        return p.mass_kg * m[:, k]
    if k < 6:
        return (p.inertia_x_kgm2, p.inertia_y_kgm2, p.inertia_z_kgm2)[k - 3] * m[:, k]
    if k < 10:
        return res.vehicle.tire.wheel_inertia_kgm2 * m[:, k]
    return res.vehicle.tire.rolling_radius_m * m[:, k]


def _table(rows: list[list[str]], header: list[str], classes: list[str] | None = None) -> str:
    out = ["<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    for i, r in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes and classes[i] else ""
        out.append(f"<tr{cls}>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _fmt(v, unit="", nd=4) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{nd}g}{(' ' + unit) if unit else ''}"


def _change(c: float | None, worse: bool) -> str:
    """A relative change of a residual, labelled when it is worse (``AddResult.worse``)."""
    if c is None:
        return "-"
    return f"{100 * c:+.0f} %" + (" (worse)" if worse else "")


def _added_rows(parameters: dict) -> list[list[str]]:
    """One row per parameter of an added effect, with its status (``added_params``): a value at a
    bound is "AT BOUND ... not identified", never shown as a result."""
    from .words import EFFECT_LABELS

    rows = []
    for e, ps in added_entries(parameters):
        for k, d in ps.items():
            st = d["status"]
            if st == "at bound":
                st = f"AT BOUND ({d['bound']} bound {_fmt(d[d['bound']])}): not identified"
            elif st == "held":
                st = "held at the generic prior"
            elif st == "at start":
                st = "AT START (the generic prior): no step of the fit moved it, not fitted"
            rows.append([EFFECT_LABELS.get(e, e), k, _fmt(d["value"]), _fmt(d.get("sigma"), nd=2), st])
    return rows


def _img(uri: str, alt: str) -> str:
    return f'<img src="{uri}" alt="{html.escape(alt)}">'


def _fig(fig, alt: str) -> str:
    return "" if fig is None else _img(F.figure_svg(fig), alt)


_SIM_COLUMNS = (("position_m", "m", "position"), ("yaw_deg", "deg", "yaw"), ("roll_deg", "deg", "roll"),
                ("speed_mps", "m/s", "speed"))


def _sim_table(sb: dict, sa: dict | None, worse: dict | None = None) -> str:
    """The held-out prediction errors per horizon, before (and after, an after value the added
    effects made worse labelled: ``AddResult.worse_predictions``)."""
    header = ["horizon"]
    for _, _, label in _SIM_COLUMNS:
        header += [f"{label} before", f"{label} after"] if sa is not None else [label]
    rows = []
    for h, d in sb.items():
        row = [f"{h} s"]
        for q, unit, _ in _SIM_COLUMNS:
            row.append(_fmt(d.get(q), unit))
            if sa is not None:
                row.append(_fmt(sa.get(h, {}).get(q), unit) + (" (worse)" if q in (worse or {}).get(h, {}) else ""))
        rows.append(row)
    return _table(rows, header)


def render_report(dg) -> str:
    """The HTML text of the report for a :class:`~vdps_hil.workbench.diagnosis.Diagnosis`."""
    from .words import EFFECT_LABELS

    rk = dg.ranking
    parts = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
             f"<title>vdps diagnose: {html.escape(Path(dg.source).name)}</title>",
             f"<style>{_CSS}</style></head><body>",
             f"<h1>Model workbench: {html.escape(Path(dg.source).name)}</h1>",
             f"<p class=\"small\">{dg.table.duration_s:.1f} s of drive, {len(dg.residuals.t_s)} rows; model vehicle "
             f"{html.escape(dg.vehicle.name)}; only the recording's /raw/ topics were read. The figures are vector "
             f"graphics: zoom the page to read them.</p>",
             "<h2>Summary</h2>"]
    parts += [f"<p class=\"msg\">{html.escape(m)}</p>" for m in rk.messages]
    eqs = _main_equations(dg)
    parts.append("<h2>Measured against the model</h2>")
    parts.append("<p class=\"small\">Measured minus model is the raw residual (the estimator's errors included); "
                 "the tables and the red curves below give the cleaned residual (those errors taken out), the one "
                 "the ranking works on.</p>")
    parts.append(_fig(F.fig_traces(dg, eqs, _measured), "measured vs model"))
    parts.append("<h2>Where it fails</h2>")
    parts.append(_fig(F.fig_residuals(dg, eqs, dg.cleaned), "residuals with the worst windows"))
    if dg.cleaned is not None:
        parts.append(_table([[EQUATION_LABELS.get(q, q), _fmt(v, EQUATION_UNITS.get(q, ""))]
                             for q, v in rms_by_equation(*dg.cleaned[1:]).items()],
                            ["equation", "cleaned residual RMS (estimator errors taken out)"]))
    if dg.windows:
        parts.append(_table([[f"{w.t_start_s:.2f}-{w.t_end_s:.2f} s", EQUATION_LABELS.get(w.equation, w.equation),
                              f"{w.misfit:.3g}"] for w in dg.windows],
                            ["window", "dominant equation", "noise-weighted misfit of the raw residual"]))
    parts.append(_fig(F.fig_regimes(dg, eqs), "residuals over the operating regime"))
    parts.append("<h2>Which effect is missing</h2>")
    parts.append(_fig(F.fig_ranking(dg), "ranking"))
    rows, cls = [], []
    for e in rk.entries:
        params = ", ".join(f"{k} = {_fmt(v)} +- {_fmt(s, nd=2)}" for k, (v, s) in e.parameters.items())
        rows.append([EFFECT_LABELS.get(e.effect, e.effect), f"{100 * e.explained_fraction:.1f} %"
                     if math.isfinite(e.explained_fraction) else "-", params, "yes" if e.plausible else "no",
                     "yes" if e.excited else "no", ", ".join(e.group), e.message])
        cls.append("sel" if e.selected else "")
    parts.append(_table(rows, ["candidate", "explained (held-out)", "parameters", "plausible", "excited", "group",
                               "in words"], cls))
    if rk.groups:
        parts.append("<p>Equivalence groups (cannot be told apart on this drive):</p>")
        parts.append(_table([[", ".join(g["members"]), _fmt(g["explained_fraction"], nd=3)] for g in rk.groups],
                            ["members", "explained fraction of the lead"]))
    parts.append("<h3>Identified parameters</h3>")
    parts.append(_table([[p.message] for p in rk.parameters], ["parameter"]))
    law = F.effect_law(dg)
    if law is not None:
        parts.append(f"<h2>{html.escape(EFFECT_LABELS.get(law.effect, law.effect))} against its regressor</h2>")
        parts.append(_fig(F.fig_effect_law(law), "the effect's law"))
        parts.append(f"<p class=\"small\">The {html.escape(EQUATION_LABELS.get(law.equation, law.equation))} "
                     f"residual the model leaves without the effect (its term plus the cleaned residual of the "
                     f"model with it), against {html.escape(law.x_label)}; the line is the effect's term at its "
                     f"fitted parameters. It explains {100 * law.explained:.0f} % of that residual's mean "
                     f"square.</p>")
    if dg.add is not None:
        parts.append("<h2>Before and after</h2>")
        parts.append(_table(_added_rows(dg.add.parameters), ["added effect", "parameter", "value", "sigma", "status"]))
        parts.append(_fig(F.fig_before_after(dg), "before and after"))
        b, a = dg.add.before, dg.add.after
        change, worse = residual_change(b, a), dg.add.worse()
        rows = [[EQUATION_LABELS.get(eq, eq), _fmt(v, EQUATION_UNITS.get(eq, "")),
                 _fmt(a["residual_rms"].get(eq), EQUATION_UNITS.get(eq, "")), _change(change.get(eq), eq in worse)]
                for eq, v in b["residual_rms"].items()]
        parts.append(_table(rows, ["equation", "cleaned residual RMS before", "after", "change"]))
        sb, sa = b.get("simulation_error", {}), a.get("simulation_error", {})
        if sb:
            parts.append(_sim_table(sb, sa, dg.add.worse_predictions()))
            parts.append("<p class=\"small\">Held-out prediction error (RMS over the starts): each prediction "
                         "uses a model fitted only on data before its start.</p>")
            parts.append(_fig(F.fig_prediction_errors(dg), "prediction error before and after"))
    elif dg.before.get("simulation_error"):
        parts.append("<h2>Simulation error of the identified model</h2>")
        parts.append(_sim_table(dg.before["simulation_error"], None))
    parts += [f"<p class=\"msg\">{html.escape(m)}</p>" for m in dg.simulation_notes()]
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(dg, directory: str | Path) -> Path:
    """Write ``report.html`` into ``directory`` (created if needed); returns its path."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    p = d / "report.html"
    p.write_text(render_report(dg), encoding="utf-8")
    return p
