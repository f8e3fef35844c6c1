"""The diagnosis as one self-contained HTML page (``--report DIR`` -> ``DIR/report.html``).

Everything is inside the file: matplotlib figures as PNG ``data:`` URIs (base64), inline CSS, no
script, no external URL. Sections: summary in vehicle-dynamics words; measured against model
(the force and moment balances the ranking works on); residuals with the worst windows marked;
residuals against the operating regime; the ranking with its equivalence groups and the
identified parameters; before/after (``--add``).
"""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path

import numpy as np

from .residuals import EQUATION_LABELS, EQUATION_UNITS, EQUATIONS

__all__ = ["write_report", "render_report", "figure_png"]

_CSS = """
body{font-family:sans-serif;margin:2em;max-width:70em;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:2em}
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;padding:2px 6px;font-size:0.9em}
th{background:#f0f0f0}.sel{background:#e8f4e8}.msg{margin:0.2em 0}img{max-width:100%;display:block;margin:0.5em 0}
.small{color:#666;font-size:0.85em}
"""


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def figure_png(fig) -> str:
    """A matplotlib figure as a base64 PNG data URI (the figure is closed)."""
    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _img(uri: str, alt: str) -> str:
    return f'<img src="{uri}" alt="{html.escape(alt)}">'


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


def _fig_traces(dg, eqs):
    plt = _plt()
    res = dg.residuals
    fig, axes = plt.subplots(len(eqs), 1, figsize=(9, 2.0 * len(eqs)), sharex=True, squeeze=False)
    for ax, eq in zip(axes[:, 0], eqs):
        k = EQUATIONS.index(eq)
        meas = _measured(dg, eq)
        ax.plot(res.t_s, meas, lw=1.0, label="measured")
        ax.plot(res.t_s, meas - res.values[:, k], lw=1.0, label="model")
        ax.set_ylabel(f"{eq} [{EQUATION_UNITS[eq]}]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle("measured against the identified model (estimator's signals, eq 13)")
    return fig


def _fig_residuals(dg, eqs):
    plt = _plt()
    res = dg.residuals
    fig, axes = plt.subplots(len(eqs), 1, figsize=(9, 1.8 * len(eqs)), sharex=True, squeeze=False)
    for ax, eq in zip(axes[:, 0], eqs):
        k = EQUATIONS.index(eq)
        ax.plot(res.t_s, res.values[:, k], lw=0.8, color="tab:red")
        for w in dg.windows:
            ax.axvspan(w.t_start_s, w.t_end_s, color="orange", alpha=0.25)
        ax.set_ylabel(f"{eq} [{EQUATION_UNITS[eq]}]")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s] (shaded: worst windows)")
    fig.suptitle("residual = measured - model")
    return fig


def _fig_regimes(dg, eqs):
    plt = _plt()
    from .regimes import REGIME_LABELS

    names = [n for n in ("speed_mps", "ay_mps2", "ax_mps2", "slip_angle_front_deg", "slip_angle_rear_deg",
                         "roll_deg", "steer_deg", "susp_travel_mm", "slip_ratio_max") if n in dg.regimes][:6]
    if not names:
        return None
    cols = 3
    rows = int(math.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(10, 2.6 * rows), squeeze=False)
    sig = dg.residuals.sigma
    for ax, n in zip(axes.ravel(), names):
        rb = dg.regimes[n]
        for eq in eqs:
            k = EQUATIONS.index(eq)
            if math.isfinite(sig[k]) and sig[k] > 0:
                ax.plot(rb.centres, rb.rms[:, k] / sig[k], marker="o", ms=3, lw=1.0, label=eq)
        ax.set_xlabel(REGIME_LABELS.get(n, n), fontsize=8)
        ax.set_ylabel("RMS / noise", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("residual over the operating regime (RMS in units of each equation's noise)")
    fig.tight_layout()
    return fig


def _fig_ranking(dg):
    plt = _plt()
    from .words import EFFECT_LABELS

    es = dg.ranking.entries
    if not es:
        return None
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(es) + 1.0))
    y = np.arange(len(es))[::-1]
    vals = [max(e.explained_fraction, 0.0) if math.isfinite(e.explained_fraction) else 0.0 for e in es]
    colors = ["tab:green" if e.selected else ("tab:orange" if e.group else ("lightgray" if not e.excited else "tab:blue"))
              for e in es]
    ax.barh(y, vals, color=colors)
    ax.set_yticks(y)
    ax.set_yticklabels([EFFECT_LABELS.get(e.effect, e.effect) for e in es], fontsize=8)
    ax.set_xlabel("explained fraction (held-out partial R^2)")
    ax.set_xlim(0, 1)
    ax.grid(axis="x", alpha=0.3)
    ax.set_title("green: selected, orange: in an equivalence group, gray: not excited", fontsize=8)
    return fig


def _fig_before_after(dg):
    if dg.add is None:
        return None
    plt = _plt()
    b, a = dg.add.before, dg.add.after
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
    rb, ra = b.get("residual_rms", {}), a.get("residual_rms", {})
    eqs = [e for e in rb if rb.get(e) and ra.get(e) is not None]
    x = np.arange(len(eqs))
    axes[0].bar(x - 0.2, [1.0] * len(eqs), 0.4, label="before")
    axes[0].bar(x + 0.2, [ra[e] / rb[e] for e in eqs], 0.4, label="after")
    axes[0].set_xticks(x)
    axes[0].set_xticklabels(eqs, rotation=60, fontsize=7)
    axes[0].set_ylabel("residual RMS / before")
    axes[0].legend(fontsize=8)
    sb, sa = b.get("simulation_error", {}), a.get("simulation_error", {})
    hs = [h for h in sb if h in sa]
    if hs:
        xb = np.arange(len(hs))
        axes[1].bar(xb - 0.2, [sb[h]["position_m"] or 0.0 for h in hs], 0.4, label="before")
        axes[1].bar(xb + 0.2, [sa[h]["position_m"] or 0.0 for h in hs], 0.4, label="after")
        axes[1].set_xticks(xb)
        axes[1].set_xticklabels([f"{h} s" for h in hs])
        axes[1].set_ylabel("position error [m] (RMS over starts)")
        axes[1].legend(fontsize=8)
    else:
        axes[1].text(0.5, 0.5, "no simulation error (drive too short)", ha="center")
    fig.suptitle("before -> after adding " + ", ".join(dg.add.added))
    fig.tight_layout()
    return fig


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


def render_report(dg) -> str:
    """The HTML text of the report for a :class:`~vdps_hil.workbench.diagnosis.Diagnosis`."""
    from .words import EFFECT_LABELS

    rk = dg.ranking
    parts = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
             f"<title>vdps diagnose: {html.escape(Path(dg.source).name)}</title>",
             f"<style>{_CSS}</style></head><body>",
             f"<h1>Model workbench: {html.escape(Path(dg.source).name)}</h1>",
             f"<p class=\"small\">{dg.table.duration_s:.1f} s of drive, {len(dg.residuals.t_s)} rows; model vehicle "
             f"{html.escape(dg.vehicle.name)}; only the recording's /raw/ topics were read.</p>",
             "<h2>Summary</h2>"]
    parts += [f"<p class=\"msg\">{html.escape(m)}</p>" for m in rk.messages]
    eqs = _main_equations(dg)
    parts.append("<h2>Measured against the model</h2>")
    parts.append(_img(figure_png(_fig_traces(dg, eqs)), "measured vs model"))
    parts.append("<h2>Where it fails</h2>")
    parts.append(_img(figure_png(_fig_residuals(dg, eqs)), "residuals with the worst windows"))
    if dg.windows:
        parts.append(_table([[f"{w.t_start_s:.2f}-{w.t_end_s:.2f} s", EQUATION_LABELS.get(w.equation, w.equation),
                              f"{w.misfit:.3g}"] for w in dg.windows],
                            ["window", "dominant equation", "noise-weighted misfit"]))
    fr = _fig_regimes(dg, eqs)
    if fr is not None:
        parts.append(_img(figure_png(fr), "residuals over the operating regime"))
    parts.append("<h2>Which effect is missing</h2>")
    fk = _fig_ranking(dg)
    if fk is not None:
        parts.append(_img(figure_png(fk), "ranking"))
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
    if dg.add is not None:
        parts.append("<h2>Before and after</h2>")
        fb = _fig_before_after(dg)
        if fb is not None:
            parts.append(_img(figure_png(fb), "before and after"))
        b, a = dg.add.before, dg.add.after
        rows = [[eq, _fmt(v, EQUATION_UNITS.get(eq, "")), _fmt(a["residual_rms"].get(eq), EQUATION_UNITS.get(eq, ""))]
                for eq, v in b["residual_rms"].items()]
        parts.append(_table(rows, ["equation", "before", "after"]))
        sb, sa = b.get("simulation_error", {}), a.get("simulation_error", {})
        if sb:
            rows = [[f"{h} s", _fmt(sb[h].get("position_m"), "m"), _fmt(sa.get(h, {}).get("position_m"), "m"),
                     _fmt(sb[h].get("yaw_deg"), "deg"), _fmt(sa.get(h, {}).get("yaw_deg"), "deg")] for h in sb]
            parts.append(_table(rows, ["horizon", "position before", "position after", "yaw before", "yaw after"]))
            parts.append("<p class=\"small\">Each prediction uses a model fitted only on data before its start.</p>")
    elif dg.before.get("simulation_error"):
        parts.append("<h2>Simulation error of the identified model</h2>")
        sb = dg.before["simulation_error"]
        parts.append(_table([[f"{h} s", _fmt(d.get("position_m"), "m"), _fmt(d.get("yaw_deg"), "deg"),
                              _fmt(d.get("roll_deg"), "deg"), _fmt(d.get("speed_mps"), "m/s")] for h, d in sb.items()],
                            ["horizon", "position", "yaw", "roll", "speed"]))
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
