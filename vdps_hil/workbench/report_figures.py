"""The report's figures and the data behind them (``report`` puts them into the page).

Every figure is SVG (vector: it stays sharp at any browser zoom), embedded as a ``data:`` URI;
time series are thinned to at most ``MAX_POINTS`` points per line (every k-th row) so the page
stays a few MB on long drives.

Which residual is drawn: the plots of "where it fails" and of the recommended effect show the
*cleaned* residual (``add.cleaned_residuals``: the estimator's errors taken out, the residual
the ranking works on), the same residual whose RMS the tables give; the raw residual
(measured - model, estimator errors included) is drawn faint behind it and labelled so.

The recommended effect against its regressor (:func:`effect_law`): a component-plus-residual
plot. The fitted law is the effect's own term at its fitted parameters (the residual of the
identified model without it minus the residual with it, row by row, in the equation's units:
-1/2 rho C_d A v^2 for drag); the points are that term plus the cleaned residual of the model
with it, i.e. what the model without the effect leaves once the estimator's errors are taken
out; both against the physical quantity the law depends on (``EFFECT_REGRESSOR``: speed for
drag, front slip angle for tire saturation, ...). The points scatter about the law by what the
model still leaves.
"""

from __future__ import annotations

import base64
import io
import math
from dataclasses import dataclass

import numpy as np

from .add import rms_by_equation
from .residuals import EQUATION_LABELS, EQUATION_UNITS, EQUATIONS

__all__ = ["figure_svg", "EffectLaw", "effect_law", "EFFECT_REGRESSOR", "MAX_POINTS", "fig_traces",
           "fig_residuals", "fig_regimes", "fig_ranking", "fig_before_after", "fig_prediction_errors",
           "fig_effect_law"]

MAX_POINTS = 2500
"""At most this many points per line of a time-series plot."""

EFFECT_REGRESSOR = {
    "aero_drag": "speed_mps", "rolling_resistance": "speed_mps", "low_pressure_tire": "speed_mps",
    "crosswind": "heading_deg", "magic_formula_tire": "slip_angle_front_deg", "linear_tire": "slip_angle_front_deg",
    "load_dependent_cornering_stiffness": "ay_mps2", "steering_compliance": "ay_mps2", "roll_stiffness": "roll_deg",
    "imu_lever_arm": "yaw_rate_degps", "imu_bias": "t_s", "steering_offset": "t_s",
}
"""Effect -> the quantity its law depends on (x of the law plot); another effect: time."""

_EXTRA_LABELS = {"heading_deg": "heading [deg]", "yaw_rate_degps": "yaw rate [deg/s]", "t_s": "time [s]"}


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def figure_svg(fig) -> str:
    """A matplotlib figure as a base64 SVG data URI (the figure is closed)."""
    plt = _plt()
    buf = io.BytesIO()
    # text stays text (small, selectable); fixed ids and no date: the same diagnosis, the same page
    with plt.rc_context({"svg.fonttype": "none", "svg.hashsalt": "vdps-hil"}):
        fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return "data:image/svg+xml;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _thin(n: int) -> slice:
    return slice(None, None, max(1, int(math.ceil(n / MAX_POINTS))))


# ------------------------------------------------------------------------ the effect's law
@dataclass
class EffectLaw:
    """The recommended (or added) effect against its regressor (module docstring): per cleaned
    residual row ``x`` (``x_name``), ``residual`` without the effect and ``law`` (its fitted
    contribution) in units of ``equation``; ``explained`` = 1 - RMS(with)^2 / RMS(without)^2."""

    effect: str
    equation: str
    x_name: str
    x_label: str
    x: np.ndarray
    residual: np.ndarray
    law: np.ndarray
    explained: float


def _regressor(table, rows: np.ndarray, t_s: np.ndarray, name: str, regimes: dict) -> np.ndarray | None:
    c = table.columns
    if name == "t_s":
        return np.asarray(t_s, dtype=float)
    if name == "heading_deg":
        return np.degrees(np.mod(np.asarray(c["yaw_g_rad"], dtype=float)[rows], 2 * math.pi))
    if name == "yaw_rate_degps":
        return np.degrees(np.asarray(c["rate_b_radps_z"], dtype=float)[rows])
    return regimes.get(name)


def effect_law(dg, config=None) -> EffectLaw | None:
    """The law plot's data for the diagnosis's recommendation (or its first ``--add``), or None
    (nothing recommended, or the effect is not one of the model's at the ranking's final point)."""
    from .add import FittedModel, cleaned_residuals
    from .regimes import REGIME_LABELS, regime_variables
    from .residuals import compute_residuals

    rk = dg.ranking
    name = dg.add.added[0] if dg.add is not None and dg.add.added else rk.recommendation
    if name is None:
        return None
    if name in rk.effects:
        veh, effs = rk.base_vehicle, rk.effects
    elif dg.add is not None and name in dg.add.fitted.effects:
        veh, effs = dg.add.fitted.vehicle, dg.add.fitted.effects
    else:
        return None
    try:
        t_s, rows, names, r_with = cleaned_residuals(dg.table, FittedModel(veh, effs), dg.vehicle, config)
        raw_with = compute_residuals(dg.table, veh, effs)
        raw_without = compute_residuals(dg.table, veh, effs.without(name))
    except ValueError:
        return None
    p_with = {int(i): k for k, i in enumerate(raw_with.index)}
    p_without = {int(i): k for k, i in enumerate(raw_without.index)}
    keep = np.array([int(i) in p_with and int(i) in p_without for i in rows], dtype=bool)
    if not keep.any():
        return None
    rows, t_s, r_with = rows[keep], np.asarray(t_s)[keep], r_with[keep]
    iw = np.array([p_with[int(i)] for i in rows])
    io_ = np.array([p_without[int(i)] for i in rows])
    sig = dg.residuals.sigma
    # the equation where the effect's term removes the most noise-weighted square residual
    best, best_gain, best_c = None, 0.0, None
    for j, q in enumerate(names):
        k = EQUATIONS.index(q)
        c = np.nan_to_num(raw_without.values[io_, k] - raw_with.values[iw, k])  # its term in r = measured - model
        y1 = r_with[:, j]
        gain = float((np.mean((y1 + c) ** 2) - np.mean(y1 * y1)) / sig[k] ** 2) if sig[k] > 0 else 0.0
        if math.isfinite(gain) and gain > best_gain:
            best, best_gain, best_c = q, gain, c
    if best is None:
        return None
    y1 = r_with[:, names.index(best)]
    y0 = y1 + best_c
    x_name = EFFECT_REGRESSOR.get(name, "t_s")
    regs = regime_variables(dg.table, raw_with)
    regs = {k: np.asarray(v)[iw] for k, v in regs.items()}
    x = _regressor(dg.table, rows, t_s, x_name, regs)
    if x is None:
        x_name, x = "t_s", np.asarray(t_s, dtype=float)
    e0 = float(np.mean(y0 * y0))
    return EffectLaw(name, best, x_name, REGIME_LABELS.get(x_name, _EXTRA_LABELS.get(x_name, x_name)),
                     np.asarray(x, dtype=float), y0, best_c,
                     float(1.0 - np.mean(y1 * y1) / e0) if e0 > 0 else math.nan)


def _bin_means(x: np.ndarray, y: np.ndarray, n_bins: int = 12) -> tuple[np.ndarray, np.ndarray]:
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 2 or np.ptp(x) <= 0:
        return x[:0], y[:0]
    edges = np.quantile(x, np.linspace(0, 1, n_bins + 1))
    k = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, n_bins - 1)
    xs, ys = [], []
    for b in range(n_bins):
        m = k == b
        if m.sum() >= 3:
            xs.append(float(np.mean(x[m])))
            ys.append(float(np.mean(y[m])))
    return np.array(xs), np.array(ys)


def fig_effect_law(law: EffectLaw):
    from .words import EFFECT_LABELS

    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4.5), layout="constrained")
    sl = _thin(len(law.x))
    unit = EQUATION_UNITS[law.equation]
    ax.plot(law.x[sl], law.residual[sl], ".", ms=2.5, alpha=0.35, color="tab:gray",
            label="its term + the cleaned residual with it = what the model leaves without it (one point per row)")
    bx, by = _bin_means(law.x, law.residual)
    ax.plot(bx, by, "o", ms=5, color="tab:blue", label="its bin means")
    lx, ly = _bin_means(law.x, law.law)
    ax.plot(lx, ly, "-", lw=2.0, color="tab:green",
            label="fitted law (the effect's term at its fitted parameters)")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel(law.x_label)
    ax.set_ylabel(f"{EQUATION_LABELS.get(law.equation, law.equation)} residual [{unit}]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    ax.set_title(f"{EFFECT_LABELS.get(law.effect, law.effect)}: signed residual against its regressor "
                 f"({100 * law.explained:.0f} % of this residual's mean square explained)", fontsize=10)
    return fig


# ------------------------------------------------------------------------ the drive
def _column(n: int, row_height_in: float):
    """A figure of ``n`` stacked panels sharing the time axis: (fig, axes (n, 1))."""
    return _plt().subplots(n, 1, figsize=(11, row_height_in * n), sharex=True, squeeze=False, layout="constrained")


def fig_traces(dg, eqs, measured):
    res = dg.residuals
    fig, axes = _column(len(eqs), 2.4)
    sl = _thin(len(res.t_s))
    for ax, eq in zip(axes[:, 0], eqs):
        k = EQUATIONS.index(eq)
        meas = measured(dg, eq)
        ax.plot(res.t_s[sl], meas[sl], lw=1.0, label="measured")
        ax.plot(res.t_s[sl], (meas - res.values[:, k])[sl], lw=1.0, label="model")
        ax.set_ylabel(f"{eq} [{EQUATION_UNITS[eq]}]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle("measured against the identified model (estimator's signals, eq 13; their difference is the "
                 "raw residual)")
    return fig


def fig_residuals(dg, eqs, cleaned):
    """Cleaned residual (the tables' residual) with the raw one faint behind it (module docstring)."""
    res = dg.residuals
    fig, axes = _column(len(eqs), 2.2)
    sl = _thin(len(res.t_s))
    t_c, names, vals = cleaned if cleaned is not None else (None, [], None)
    rms_all = rms_by_equation(names, vals) if cleaned is not None else {}
    slc = _thin(len(t_c)) if t_c is not None else sl
    for ax, eq in zip(axes[:, 0], eqs):
        k = EQUATIONS.index(eq)
        ax.plot(res.t_s[sl], res.values[sl, k], lw=0.6, color="0.75", label="raw (estimator errors included)")
        if eq in names:
            v = vals[:, names.index(eq)]
            rms = rms_all[eq] if rms_all[eq] is not None else math.nan
            ax.plot(t_c[slc], v[slc], lw=0.9, color="tab:red", label=f"cleaned (RMS {rms:.3g} {EQUATION_UNITS[eq]}, "
                                                                     f"as in the tables)")
        for w in dg.windows:
            ax.axvspan(w.t_start_s, w.t_end_s, color="orange", alpha=0.25)
        ax.set_ylabel(f"{eq} [{EQUATION_UNITS[eq]}]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("time [s] (shaded: worst windows)")
    fig.suptitle("residual = measured - model")
    return fig


def fig_regimes(dg, eqs):
    plt = _plt()
    from .regimes import REGIME_LABELS

    names = [n for n in ("speed_mps", "ay_mps2", "ax_mps2", "slip_angle_front_deg", "slip_angle_rear_deg",
                         "roll_deg", "steer_deg", "susp_travel_mm", "slip_ratio_max") if n in dg.regimes][:6]
    if not names:
        return None
    cols = 3
    rows = int(math.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(11, 3.0 * rows), squeeze=False, layout="constrained")
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
    fig.suptitle("raw residual over the operating regime (RMS in units of each equation's noise)")
    return fig


def fig_ranking(dg):
    plt = _plt()
    from .words import EFFECT_LABELS

    es = dg.ranking.entries
    if not es:
        return None
    fig, ax = plt.subplots(figsize=(10, 0.4 * len(es) + 1.2), layout="constrained")
    y = np.arange(len(es))[::-1]
    vals = [max(e.explained_fraction, 0.0) if math.isfinite(e.explained_fraction) else 0.0 for e in es]
    colors = ["tab:green" if e.selected else ("tab:orange" if e.group else ("lightgray" if not e.excited else "tab:blue"))
              for e in es]
    ax.barh(y, vals, color=colors)
    ax.set_yticks(y)
    ax.set_yticklabels([EFFECT_LABELS.get(e.effect, e.effect) for e in es], fontsize=9)
    ax.set_xlabel("explained fraction (held-out partial R^2)")
    ax.set_xlim(0, 1)
    ax.grid(axis="x", alpha=0.3)
    ax.set_title("green: selected, orange: in an equivalence group, gray: not excited", fontsize=9)
    return fig


# ------------------------------------------------------------------------ before / after
def fig_before_after(dg):
    if dg.add is None:
        return None
    plt = _plt()
    b, a = dg.add.before, dg.add.after
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6), layout="constrained")
    rb, ra = b.get("residual_rms", {}), a.get("residual_rms", {})
    eqs = [e for e in rb if rb.get(e) and ra.get(e) is not None]
    x = np.arange(len(eqs))
    axes[0].bar(x - 0.2, [1.0] * len(eqs), 0.4, label="before")
    axes[0].bar(x + 0.2, [ra[e] / rb[e] for e in eqs], 0.4, label="after")
    axes[0].set_xticks(x)
    axes[0].set_xticklabels(eqs, rotation=60, fontsize=8)
    axes[0].set_ylabel("cleaned residual RMS / before")
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
    return fig


_SIM_QUANTITIES = (("position_m", "position error [m]"), ("yaw_deg", "yaw error [deg]"),
                   ("roll_deg", "roll error [deg]"), ("speed_mps", "speed error [m/s]"))


def fig_prediction_errors(dg):
    """Before/after traces: each held-out prediction's error at the longest horizon against its
    start time (each start's model was fitted only on data before it), one panel per quantity."""
    add = dg.add
    if add is None or add.sim_before is None or add.sim_after is None or add.sim_before.missing_inputs:
        return None
    sb, sa = add.sim_before, add.sim_after
    if not len(sb.t0_s):
        return None
    h = len(sb.horizons_s) - 1
    fig, axes = _column(len(_SIM_QUANTITIES), 2.0)
    for ax, (q, label) in zip(axes[:, 0], _SIM_QUANTITIES):
        ax.plot(sb.t0_s, np.abs(getattr(sb, q)[:, h]), "o-", ms=3, lw=1.0, label="before")
        ax.plot(sa.t0_s, np.abs(getattr(sa, q)[:, h]), "o-", ms=3, lw=1.0, label="after")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("start of the held-out prediction [s]")
    fig.suptitle(f"error {sb.horizons_s[h]:g} s after each start, before -> after adding {', '.join(add.added)} "
                 f"(gaps: the prediction diverged or the drive ended)")
    return fig
