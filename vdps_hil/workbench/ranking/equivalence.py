"""Equivalence groups: which other candidates and identified parameters this drive cannot tell
apart from an entry.

Another candidate or an identified parameter A is equivalent to c when A's columns reproduce c's
fitted contribution d_c = X_c theta_c with R^2 >= ``corr_threshold``^2 (|correlation| >= 0.95
for one column; a large variance inflation for several) with plausible values. In Gram-matrix
form, with the GNSS and velocity nuisance partialled out (G_p = G - G_.N G_NN^+ G_N.)::

    v   = theta_c^T G_p[c, c] theta_c               (the energy of d_c)
    g   = G_p[A, c] theta_c,   theta_A = G_p[A, A]^+ g
    R^2 = g^T theta_A / v                          (the part of d_c that A's columns reproduce)

For a fitted entry A must also not fit significantly worse (BIC on n_eff):
n_eff ln(1 + (1 - R^2) v / SSE) <= ``bic_margin``; for a prior-size direction or a parameter's
move the correlation alone decides. A selected nonlinear effect is represented by its whole
contribution (the residual it removes), not by the direction of a change of its parameter.

A re-identified parameter that moved from the model file's value is an entry of its own (its
explained fraction is that of its re-identification) and the effects that would explain the same
change form its group -- e.g. the front cornering stiffness and steering compliance, which a drive
in the linear range cannot tell apart. The recommendation's group also takes in a rival that
passed every selection test on its own (first round) and whose fitted contribution the
recommendation reproduces: both explain the residual, so the drive does not tell them apart
(e.g. tire saturation and load-dependent stiffness on a 5 m/s^2 sine sweep, where either wins the
held-out comparison depending on the seed).
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..candidate_base import PARAM_ALIASES
from .config import RankingConfig
from .design import Design
from .results import RankEntry, json_number

__all__ = ["fill_groups", "group_list", "merge_rivals"]


class _Mimic:
    """R^2 of one candidate's columns reproducing a contribution (module docstring)."""

    def __init__(self, d: Design, cfg: RankingConfig, n_eff: float, sse: float):
        self.d, self.cfg, self.n_eff, self.sse = d, cfg, n_eff, sse
        self.r2min = cfg.corr_threshold ** 2
        gram_total = d.stats()[0].sum(axis=(0, 1))  # G = X^T X over all rows
        nu = d.columns_of(["_nuisance", "_smooth", "_structure"])
        if nu:
            gnn = gram_total[np.ix_(nu, nu)]
            # G_p: the Gram matrix with the nuisance columns partialled out
            self.gp = gram_total - gram_total[:, nu] @ np.linalg.lstsq(gnn, gram_total[nu, :], rcond=None)[0]
        else:
            self.gp = gram_total

    def __call__(self, th_a, cols_a, name, significance: bool = True) -> tuple[float, np.ndarray]:
        """(R^2, theta of ``name`` in its own units) reproducing theta_a on the columns cols_a.
        vv: v = theta_a^T G_p theta_a; goo: G_p[A, A]; goa: g = G_p[A, a] theta_a; th: theta_A."""
        d, gp = self.d, self.gp
        cols = d.blocks[name]
        vv = float(th_a @ gp[np.ix_(cols_a, cols_a)] @ th_a)
        if vv <= 0:
            return 0.0, np.zeros(len(cols))
        goo = gp[np.ix_(cols, cols)]
        goa = gp[np.ix_(cols, cols_a)] @ th_a
        th = np.linalg.lstsq(goo, goa, rcond=None)[0]
        r2 = float(goa @ th) / vv
        # a fitted effect: not told apart only if the alternative is not significantly worse
        # (BIC on n_eff); a prior-size direction or a parameter's move: correlation alone
        if significance:
            worse = self.n_eff * math.log1p(max(1.0 - r2, 0.0) * vv / max(self.sse, 1e-300))
            if worse > self.cfg.bic_margin:
                r2 = min(r2, self.r2min - 1e-9)
        return r2, np.array([t / d.scale[k] for t, k in zip(th, cols)])


def fill_groups(d: Design, by_name, entries, params, current, thetas, cfg: RankingConfig, n_eff: float = 1.0,
                sse: float = 1.0, selected=(), phis: dict | None = None) -> None:
    """Fill each entry's ``group`` (module docstring), in Gram-matrix form with the GNSS
    nuisance partialled out."""
    # a selected nonlinear effect: its whole contribution (the residual it removes), not the
    # direction of a change of its parameter
    contrib = {}
    for e in entries:
        if e.selected and not by_name[e.effect].linear and e.effect in d.ctx.effects:
            contrib[e.effect] = d.add_block(f"_contrib:{e.effect}", d.ctx.removal(e.effect)[:, :, None], None)
    mimic = _Mimic(d, cfg, n_eff, sse)
    for e in entries:
        if e.excited:
            _entry_group(d, mimic, by_name, e, params, thetas, contrib, phis, cfg)
    for p in params:
        _parameter_group(d, mimic, by_name, p, cfg)


def _entry_direction(d: Design, c, e: RankEntry, thetas, contrib, phis, fitted: bool):
    """(theta in scaled units, columns) of an entry's contribution: its whole contribution (a
    selected nonlinear effect), its change columns times its value (selected linear), its
    prior-size direction (selected nonlinear without one, or not fitted), else its fit."""
    cols = d.blocks[e.effect]
    if e.effect in contrib:
        cols = contrib[e.effect]
        th = np.array([d.scale[k] for k in cols])
    elif e.selected:
        # the selected effect's contribution: its change columns times its value (linear
        # candidates) or its prior-size direction (nonlinear ones)
        if phis and e.effect in phis:
            phi = np.asarray(phis[e.effect], dtype=float)
        else:
            phi = np.array([v for v, _ in list(e.parameters.values())[:len(cols)]])
        th = (phi if c.linear and len(phi) == len(cols) else np.ones(len(cols))) * np.array([d.scale[k] for k in cols])
    else:
        theta = thetas[e.effect]
        th = np.array([t * d.scale[k] for t, k in zip(theta, cols)])
        if not fitted:
            th = c.prior_theta() * np.array([d.scale[k] for k in cols])
    return th, cols


def _entry_group(d: Design, mimic: _Mimic, by_name, e: RankEntry, params, thetas, contrib, phis,
                 cfg: RankingConfig) -> None:
    """The group of one excited candidate entry: every other candidate and identified parameter
    that reproduces its contribution with plausible values."""
    c = by_name[e.effect]
    fitted = e.selected or e.explained_fraction >= cfg.min_explained
    th, cols = _entry_direction(d, c, e, thetas, contrib, phis, fitted)
    grp = [e.effect]
    for other in by_name:
        if other == e.effect:
            continue
        r2, th_o = mimic(th, cols, other, fitted)
        if os.environ.get("VDPS_WB_DEBUG") and r2 > 0.5:
            print(f"[groups] {e.effect} ~ {other}: r2 {r2:.3f} plausible {by_name[other].plausible(th_o)}")
        if r2 >= mimic.r2min and by_name[other].plausible(th_o):
            grp.append(other)
    for p in params:
        pname = next(iter(p.parameters))
        if pname not in d.blocks:
            continue
        r2, th_o = mimic(th, cols, pname, fitted)
        cur = next(iter(p.parameters.values()))[0]
        if r2 >= mimic.r2min and cur + th_o[0] > 0:
            grp.append(p.effect)
    e.group = grp if len(grp) > 1 else []


def _parameter_group(d: Design, mimic: _Mimic, by_name, p: RankEntry, cfg: RankingConfig) -> None:
    """A parameter entry's group: which effects would explain its move from the reference."""
    pname = next(iter(p.parameters))
    if pname not in d.blocks:
        return
    k = d.blocks[pname][0]
    ref_v = p.reference[pname]
    cur = next(iter(p.parameters.values()))[0]
    if p.explained_fraction < cfg.min_explained:
        return
    th = np.array([(cur - ref_v) * d.scale[k]])
    grp = [p.effect]
    for other in by_name:
        r2, th_o = mimic(th, [k], other, False)
        if r2 >= mimic.r2min and by_name[other].plausible(th_o):
            grp.append(other)
    p.group = grp if len(grp) > 1 else []


def merge_rivals(entries: list[RankEntry], rec: str, eligible_first: set[str]) -> list[str]:
    """The recommendation's group takes in a rival that passed every selection test on its own in
    the first round (``eligible_first``) and whose fitted contribution the recommendation
    reproduces: both explain the residual, the drive does not tell them apart (the one with the
    larger held-out explained fraction leads). Returns the names equivalent to ``rec``."""
    rec_e = next(e for e in entries if e.effect == rec)
    for e in entries:
        if e.effect != rec and rec in e.group and e.effect in eligible_first and e.effect not in rec_e.group:
            rec_e.group = (rec_e.group or [rec]) + [e.effect]
    return [g for g in rec_e.group if g != rec]


def group_list(entries, params) -> list[dict]:
    """Equivalence groups with at least one effect, largest explained fraction first."""
    seen = set()
    out = []
    for e in sorted(entries + params, key=lambda e: -(e.explained_fraction if math.isfinite(e.explained_fraction) else -1)):
        if len(e.group) < 2:
            continue
        key = frozenset(e.group)
        if key in seen:
            continue
        if not any(g for g in e.group if g not in PARAM_ALIASES.values()):
            continue
        seen.add(key)
        out.append({"members": list(e.group), "lead": e.effect,
                    "explained_fraction": json_number(e.explained_fraction)})
    return out
