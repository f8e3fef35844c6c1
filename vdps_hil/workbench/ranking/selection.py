"""Selection: the candidates ranked by their held-out explained fraction, forward selection by
an information criterion and evidence thresholds, and the final entries (:func:`rank`).

Explained fraction (``explained_fraction``): the partial R^2 of a candidate on held-out data,
blocked cross-validation (:meth:`~vdps_hil.workbench.ranking.design.Design.cv`)::

    EF_c = 1 - SSE_cv(S + c) / SSE_cv(S)

S = the base model (N, B) plus the effects already selected; per equation the same ratio over its rows.

Forward selection: the candidate with the largest EF is added when (a) its BIC on the effective
sample size improves by more than ``bic_margin``::

    dBIC = n_eff ln(SSE(S + c) / SSE(S)) + p_c ln(n_eff),   n_eff = sum_g n_g / tau_g

(tau_g the integrated autocorrelation time of equation g's residual), (b) EF_c >=
``min_explained_overall`` -- or, for a sensor effect, >= ``min_explained_innovations`` of the
GNSS/IMU innovations, where a sensor error must show (on the force balance alone a sensor effect
needs >= ``min_explained_sensor_balance`` overall); or, for a non-sensor effect whose own equations are
all force/moment balances (no wheel-speed rows), >= ``min_explained_dynamics`` of the ten balance
equations (the kinematic wheel-speed rows, whose whitened misfit dominates the total on a
circle, do not dilute it) -- and >= ``min_explained`` on the candidate's own equations (those
holding >= 10 % of its prior-size contribution), (c) the fitted parameters are physically
plausible (``ParamSpec`` ranges: negative drag and so on are rejected) and (d) the drive excites it: at its generic prior
magnitude the effect would stand ``excitation_z`` noise sigmas (effective) above zero. The first
selected effect is the ``recommendation``.

Excitation of candidate c at its generic prior magnitude theta_0 (scaled columns), beyond what
the always-on base columns b reproduce::

    z_c = sqrt((v_c - v_b) n_eff / n),   v_c = theta_0^T G_cc theta_0,   v_b = g^T G_bb^+ g,  g = G_bc theta_0

(G = X^T X of the whole drive). A candidate whose v_b / v_c (with b the ten parameters alone)
reaches ``corr_threshold``^2, and whose fitted contribution keeps no significant part the
re-identification cannot reproduce (``_base_equivalent``), is the same as a re-identification
on this drive: never a recommendation, reported as a group (:mod:`~vdps_hil.workbench.ranking.equivalence`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from vdps_hil.model.effects import EffectSet
from vdps_hil.model.effects.base import Effect
from vdps_hil.model.params import Vehicle

from ..candidate_base import PARAM_ALIASES, Candidate
from ..candidates import table_candidates
from ..coverage import MIN_ROWS, coverage_messages, not_ranked_lines, unusable_reason
from ..dataset import DriveTable
from ..innovations import Innovations, compute_innovations
from ..residuals import DYNAMIC_EQUATIONS, RowStates, row_states
from .config import GROUP_NAMES, INNOVATION_GROUPS, RankingConfig
from .design import Design, effective_sample_size, sigma_of, theta_of
from .equivalence import fill_groups, group_list, merge_rivals
from .gram import take
from .identification import Joint, Point, build_design, identify, joint_fit, linear_joint_fit
from .ordering import order_selected, unique_contributions
from .results import RankEntry, Ranking, rk_message
from .rls_check import cross_check
from .sensor_fit import sensor_fit

__all__ = ["rank"]


@dataclass
class _Search:
    """The forward selection's state: the drive, the current linearisation point with its design
    and always-on columns, the current model's SSE and held-out SSE per group (``cv_cur``), the
    selected candidates, and per judged candidate its joint fit and figures (``steps``)."""

    table: DriveTable
    states: RowStates
    inn: Innovations
    vehicle: Vehicle
    cfg: RankingConfig
    by_name: dict[str, Candidate]
    point: Point
    d: Design
    always: list
    sse_cur: float
    cv_cur: np.ndarray
    n_eff: float
    n_rows: int
    ratio: float  # n_eff / n_rows
    selected: dict[str, Candidate] = field(default_factory=dict)
    joints: dict[str, Joint] = field(default_factory=dict)
    steps: dict[str, dict] = field(default_factory=dict)


@dataclass
class _Excitation:
    """Per candidate: z (``excitation``, module docstring), the base parameters' share of its
    prior-size contribution (``base_equiv`` = v_b / v_c) and its own row groups (``own_groups``:
    those holding >= 10 % of that contribution's energy)."""

    excitation: dict[str, float]
    base_equiv: dict[str, float]
    own_groups: dict[str, np.ndarray]


def rank(table: DriveTable, vehicle: Vehicle, effects: EffectSet | Sequence[Effect] = (), *,
         candidates: Sequence[Candidate] | None = None, user_effects: Sequence[type[Effect]] = (),
         config: RankingConfig | None = None, mask: np.ndarray | None = None) -> Ranking:
    """Identify the model on the drive, then rank the effect candidates (module docstring).

    ``vehicle``: the model vehicle (its parameters are the reference/priors); ``effects``: the
    model's effects (from ``--model``); ``candidates``: default every registered effect not in the
    model plus ``user_effects``; ``mask``: table rows to use (default all)."""
    cfg = config or RankingConfig()
    effects = effects if isinstance(effects, EffectSet) else EffectSet(effects)
    if mask is not None:
        table = table.slice(mask)
    states = row_states(table, vehicle)
    if len(states.index) < MIN_ROWS:
        raise ValueError(unusable_reason(table))
    inn = compute_innovations(table)
    point, d, always, _ = identify(table, vehicle, effects, states, inn, cfg, reference=vehicle)
    cands, not_ranked = table_candidates(table, states.index, effects, user_effects, candidates)
    by_name: dict[str, Candidate] = {c.name: c for c in cands}
    ctx = d.ctx
    for c in cands:
        xd, xi = c.columns(ctx)
        d.add_block(c.name, xd, xi)
    th0, sse_cur = d.objective(always)
    r0 = d.y - d.predict(always, th0)
    n_eff = effective_sample_size(d, r0)
    n_rows = len(d.y)
    s = _Search(table, states, inn, vehicle, cfg, by_name, point, d, always, sse_cur, d.cv(always), n_eff, n_rows,
                n_eff / n_rows)
    ev = _excitation(s)
    _forward_selection(s, ev)
    rk = _result(s, ev)
    rk.messages = coverage_messages(table, states.index) + rk.messages + not_ranked_lines(not_ranked)
    rk.design = rk.context = None  # the drive-sized design is not read after the ranking: freed here
    return rk


def _prior_contribution(G: np.ndarray, base: list, d, name: str, c, theta=None) -> tuple[float, float]:
    """(v, v_base) of candidate ``name`` at its generic prior magnitude (or at ``theta``, its
    own units): v = th' G_cc th, its weighted sum of squares over the drive, and v_base =
    g' G_bb^+ g (g = G_bc th), the part of it the ``base`` columns reproduce (0 without base
    columns). th: theta_0 in scaled columns, vv: v, gbv: g."""
    cols = d.blocks[name]
    th = (c.prior_theta() if theta is None else np.asarray(theta, dtype=float)) * np.array([d.scale[k] for k in cols])
    vv = float(th @ G[np.ix_(cols, cols)] @ th)
    if not len(base):
        return vv, 0.0
    gbv = G[np.ix_(base, cols)] @ th
    return vv, float(gbv @ np.linalg.lstsq(G[np.ix_(base, base)], gbv, rcond=None)[0])


def _excitation(s: _Search) -> _Excitation:
    """Excitation, base equivalence and own row groups of every candidate (module docstring)."""
    d, cfg, states = s.d, s.cfg, s.states
    # excitation of every candidate at its generic prior magnitude (beyond what the base absorbs)
    excit = {}
    gram_total = d.stats()[0].sum(axis=(0, 1))  # G = X^T X over all rows
    for name, c in s.by_name.items():
        prior_energy, base_reproduced = _prior_contribution(gram_total, s.always, d, name, c)  # v_c, v_b
        excit[name] = math.sqrt(max(prior_energy - base_reproduced, 0.0) * s.ratio)
    # an effect that acts through the tires' lateral forces cannot be judged when the tires carry
    # no lateral load: the slip angles are then the estimator's noise (as for the cornering
    # stiffnesses, ``excited_parameters``)
    gram_per_group = d.stats()[0].sum(axis=0)  # G_g = X_g^T X_g per row group g
    lateral = [GROUP_NAMES.index(g) for g in ("lat", "roll", "yaw")]
    lat_ok = "cornering_stiffness_front_nprad" in (states.excited_params or set()) or \
        "cornering_stiffness_front_nprad" not in cfg.identify
    # a candidate whose prior-size contribution the ten parameters reproduce (R^2 >= 0.95^2) is
    # the same as a re-identification on this drive (e.g. steering compliance and the front
    # cornering stiffness in the linear range): never a recommendation, reported as a group
    base_cols = d.columns_of(list(cfg.identify))
    base_equiv: dict[str, float] = {}
    if base_cols:
        for name, c in s.by_name.items():
            prior_energy, base_reproduced = _prior_contribution(gram_total, base_cols, d, name, c)
            if prior_energy > 0:
                base_equiv[name] = base_reproduced / prior_energy
    own_groups: dict[str, np.ndarray] = {}
    for name, c in s.by_name.items():
        cols = d.blocks[name]
        theta_prior = c.prior_theta() * np.array([d.scale[k] for k in cols])  # scaled columns
        # energy per row group of the prior-size contribution: theta^T G_g theta
        energy = np.array([float(theta_prior @ gram_per_group[g][np.ix_(cols, cols)] @ theta_prior)
                           for g in range(len(GROUP_NAMES))])
        # the candidate's own equations: where its prior-size contribution has >= 10 % of its energy
        own_groups[name] = energy >= 0.1 * energy.sum() if energy.sum() > 0 else np.zeros(len(GROUP_NAMES), bool)
        if energy.sum() > 0 and energy[lateral].sum() >= 0.5 * energy.sum() and not lat_ok:
            excit[name] = 0.0
    return _Excitation(excit, base_equiv, own_groups)


def _forward_selection(s: _Search, ev: _Excitation) -> None:
    """Add the best candidate that passes every test (module docstring), re-linearise there, and
    repeat, at most ``max_effects`` times."""
    cfg = s.cfg
    for _ in range(cfg.max_effects):
        best = None
        for ef_s, name, theta in _shortlist(s, ev):
            judged = _judge(s, ev, name, theta)
            if judged is None:
                continue
            ok, ef, j = judged
            if ok and (best is None or ef > best[1]):  # the design freed is the one no longer the best
                best, j = (name, ef, j), (None if best is None else best[2])
            if j is not None:
                j.design = None  # only a selected candidate's design is read again (``_selected_entry``)
        if best is None:
            break
        name, ef, j = best
        s.selected[name] = s.by_name[name]
        s.point = j.point
        rest = [c for n, c in s.by_name.items() if n not in s.selected]
        ctx, s.d, s.always = build_design(s.table, s.states, s.inn, s.vehicle, s.point, cfg, s.selected, rest)
        th_c, s.sse_cur = s.d.objective(s.always)
        s.cv_cur = s.d.cv(s.always)


def _shortlist(s: _Search, ev: _Excitation) -> list[tuple[float, str, np.ndarray]]:
    """(screening EF, name, theta) of the candidates to fit jointly this round: the best ``shortlist``
    with EF > 0 and a plausible screening fit (a linear one's joint fit; implausible ones hid others),
    every sensor effect whose fit explains ``min_explained_innovations`` of the innovations (``_evidence``:
    ranked by the overall EF alone, a sensor error that hardly touches the force balance falls
    behind balance effects that fit its side effects), and every nonlinear one not yet found weak."""
    d, cfg = s.d, s.cfg
    inn_g = np.array([GROUP_NAMES.index(g) for g in INNOVATION_GROUPS])
    screen, sensor = [], set()
    for name, c in s.by_name.items():
        if name in s.selected or not d.has_signal(name) or ev.excitation[name] < cfg.excitation_z:
            continue
        cols = s.always + d.blocks[name]
        cv = d.cv(cols)
        ef = 1.0 - cv.sum() / max(s.cv_cur.sum(), 1e-300)
        if c.family == "measurement" and _explained(cv, s.cv_cur, inn_g) >= cfg.min_explained_innovations:
            sensor.add(name)
        if c.family == "measurement":  # its own evidence: the innovations alone (``sensor_fit``)
            sf = sensor_fit(d, s.always, name)
            if sf is not None and sf.held_out_dbic() < -cfg.bic_margin:
                sensor.add(name)
        th, _, _ = d.fit(cols)
        screen.append((ef, name, theta_of(d, name, cols, th)))
    screen.sort(key=lambda t: -t[0])
    short = [t for t in screen if t[0] > 0.0 and (not s.by_name[t[1]].linear or s.by_name[t[1]].plausible(t[2]))][:cfg.shortlist]
    short += [t for t in screen if t[1] in sensor and t not in short]
    # nonlinear candidates are judged by their joint fit in any case: at a linearisation
    # point far from the truth their screening column can hide them
    short += [t for t in screen[cfg.shortlist:] if not s.by_name[t[1]].linear and t[1] not in sensor and t not in short
              and (t[1] not in s.steps or s.steps[t[1]]["ef"] > 0.5 * cfg.min_explained)]
    return short


def _explained(cv_with: np.ndarray, cv_before: np.ndarray, groups) -> float:
    """1 - SSE_cv(S + c) / SSE_cv(S) over the row groups ``groups``."""
    return 1.0 - cv_with[groups].sum() / max(cv_before[groups].sum(), 1e-300)


def _judge(s: _Search, ev: _Excitation, name: str, theta) -> tuple[bool, float, Joint] | None:
    """Fit one shortlisted candidate jointly, record its figures in ``s.steps``, and say whether it
    passes every selection test: (ok, EF, joint fit), None when it cannot be fitted."""
    cfg, c = s.cfg, s.by_name[name]
    if c.linear:
        j = linear_joint_fit(s.d, s.always, c, theta, s.point, cfg, s.vehicle, s.ratio, s.selected)
    else:
        j = joint_fit(s.table, s.states, s.inn, s.vehicle, s.point, s.selected, c, theta, cfg, s.ratio, s.sse_cur,
                      s.cv_cur)
    if j is None:
        return None
    cv_before = j.cv_without if j.cv_without is not None else s.cv_cur
    sse_before = j.sse_without if math.isfinite(j.sse_without) else s.sse_cur
    ef = 1.0 - j.cv.sum() / max(cv_before.sum(), 1e-300)
    own = ev.own_groups.get(name)
    ef_own = _explained(j.cv, cv_before, own) if own is not None and own.any() else ef
    dbic = s.n_eff * math.log(max(j.sse, 1e-300) / max(sse_before, 1e-300)) + len(j.phi) * math.log(s.n_eff)
    st = s.steps[name] = {"ef": ef, "ef_own": ef_own, "dbic": dbic, "joint": j, "cv_before": cv_before}
    if os.environ.get("VDPS_WB_DEBUG"):
        print(f"[ranking] {name}: ef {ef:.3f} own {ef_own:.3f} dbic {dbic:.1f} phi {j.phi} "
              f"inn {1.0 - j.cv[-3:].sum() / max(cv_before[-3:].sum(), 1e-300):.3f} "
              f"plausible {c.phi_plausible(j.phi)} material {c.material(j.phi, cfg.material_fraction)}")
    s.joints[name] = j
    inn_g = np.array([GROUP_NAMES.index(g) for g in INNOVATION_GROUPS])
    st["ef_innovations"] = ef_inn = _explained(j.cv, cv_before, inn_g)
    # enough of the residual overall -- or, for a sensor effect, of the GNSS/IMU innovations, where a
    # sensor error shows even when the force balance hardly sees it -- or, for an effect on the force
    # balance alone (no kinematic rows among its own equations), of the ten balance equations of eq 13
    st["ef_dynamics"] = ef_dyn = _explained(j.cv, cv_before, np.arange(len(DYNAMIC_EQUATIONS)))
    balance_only = own is not None and own.any() and not own[len(DYNAMIC_EQUATIONS):].any()
    evidence = _evidence(c, cfg, ef, ef_inn, ef_dyn, balance_only)
    if j.sensor is not None:  # fitted on its innovations: BIC of their held-out SSE (``sensor_fit``)
        st["dbic_innovations"] = dbic_inn = j.sensor.held_out_dbic()
        evidence = evidence or dbic_inn < -cfg.bic_margin
        if dbic_inn < -cfg.bic_margin:  # its own rows are the innovations it was fitted on, where
            ef_own = st["ef_own"] = j.sensor.own_fraction()  # its parameters were paid for
            dbic = st["dbic"] = dbic - len(j.phi) * math.log(s.n_eff)
    if os.environ.get("VDPS_WB_DEBUG"):
        print(f"[ranking] {name}: ef_dyn {ef_dyn:.3f} balance_only {balance_only} evidence {evidence} "
              f"base_equiv {ev.base_equiv.get(name, 0.0):.3f}")
    if _base_equivalent(s, ev, name, c, j.phi):
        evidence = False  # the same as re-identifying a parameter: reported as a group
    # a sensor effect is fitted on its innovations and judged there (``sensor_fit``): the overall
    # figure is then the balance rows' model error, which it was not fitted to absorb
    ok = (dbic < -cfg.bic_margin and ef_own >= cfg.min_explained and (ef > 0.0 or c.family == "measurement")
          and evidence and c.phi_plausible(j.phi) and c.material(j.phi, cfg.material_fraction))
    if not s.selected:
        st["eligible_first"] = bool(ok)
    return ok, ef, j


def _base_equivalent(s: _Search, ev: _Excitation, name: str, c: Candidate, phi) -> bool:
    """Whether re-identifying the ten parameters does what the candidate does: its prior-size
    contribution is reproduced by them (``base_equiv`` >= ``corr_threshold``^2) and, for a
    candidate of several parameters (whose fit can leave the prior's direction), at its fitted
    values the part of its contribution d = X_c phi that the always-on columns b (the
    parameters and the nuisance) do not reproduce is not significant (BIC on n_eff, as for the
    groups, :mod:`.equivalence`)::

        n_eff ln(1 + (1 - R^2) v / SSE) <= bic_margin,   v = phi' G_cc phi,  R^2 = g' G_bb^+ g / v

    R^2 alone is blind to size: a load-dependent stiffness on a 5 m/s^2 sine sweep is 95 % a
    change of the axle stiffnesses, and the other 5 % of its large contribution still explain a
    third of the held-out residual the re-identified model leaves."""
    thr = s.cfg.corr_threshold ** 2
    if ev.base_equiv.get(name, 0.0) < thr:
        return False
    if len(phi) != len(s.d.blocks[name]) or len(phi) < 2 or not s.always:
        return True  # one parameter: its contribution's direction is that of its prior
    v, vb = _prior_contribution(s.d.stats()[0].sum(axis=(0, 1)), s.always, s.d, name, c, phi)
    if v <= 0:
        return True
    worse = s.n_eff * math.log1p(max(1.0 - vb / v, 0.0) * v / max(s.sse_cur, 1e-300))
    if os.environ.get("VDPS_WB_DEBUG"):
        print(f"[ranking] {name}: fitted R^2 on the base {vb / v:.3f}, unreproduced part dBIC {worse:.1f}")
    return vb / v >= thr and worse <= s.cfg.bic_margin


def _evidence(c: Candidate, cfg: RankingConfig, ef: float, ef_inn: float, ef_dyn: float, balance_only: bool) -> bool:
    """Test (b) of the module docstring: enough of the residual explained on the candidate's
    evidence path."""
    if c.family == "measurement":
        # a sensor error shows in the innovations; through the force balance alone it
        # must explain more, as its several parameters also fit the reduced model's own
        # shortcomings (a lateral force lagging the slip looks like a lever arm on a weave)
        return ef_inn >= cfg.min_explained_innovations or ef >= max(
            cfg.min_explained_overall, cfg.min_explained_sensor_balance)
    return ef >= cfg.min_explained_overall or (balance_only and ef_dyn >= cfg.min_explained_dynamics)


def _result(s: _Search, ev: _Excitation) -> Ranking:
    """The final entries on the design at the final point, their groups, the recommendation and
    its equivalents, and the words."""
    d, always, point, cfg = s.d, s.always, s.point, s.cfg
    th_fin, sse_fin, _ = d.fit(always)
    s2 = sse_fin / max(s.n_rows - len(always), 1)
    entries, thetas = [], {}
    for name, c in s.by_name.items():
        if name in s.selected:
            thetas[name] = np.array([t * 0 for t in point.phis[name]])
            entries.append(_selected_entry(s, ev, name, c, s2))
        else:
            entry, thetas[name] = _candidate_entry(s, ev, name, c, s2, sse_fin)
            entries.append(entry)
    unique = unique_contributions(s.table, s.states, s.inn, s.vehicle, point, cfg, s.selected, s.cv_cur)
    order = order_selected(list(s.selected), unique, [n for n, c in s.selected.items() if c.family == "measurement"])
    for e in entries:
        e.unique_fraction = unique.get(e.effect, math.nan)
    entries.sort(key=lambda e: (order.index(e.effect) if e.effect in order else len(order),
                                -(e.explained_fraction if math.isfinite(e.explained_fraction) else -1)))
    params = _parameter_entries(d, s.vehicle, point.base, always, s.ratio, s2, cfg)
    cross_check(params, s.table.rls)  # the identifier's verdict, when the table carries its result (rls_check)
    fill_groups(d, s.by_name, entries, params, always, thetas, cfg, s.n_eff, sse_fin, s.selected, point.phis)
    groups = group_list(entries, params)
    rec = order[0] if order else None
    eq_to = []
    if rec:
        eq_to = merge_rivals(entries, rec, {n for n, st in s.steps.items() if st.get("eligible_first")})
        groups = group_list(entries, params)
    rk = Ranking(entries=entries, parameters=params, recommendation=rec, equivalent_to=eq_to, selected=order,
                 groups=groups, messages=[], n_eff=s.n_eff, n_rows=s.n_rows, base_vehicle=point.base,
                 reference_vehicle=s.vehicle, effects=point.effects, context=d.ctx, design=d, candidates=s.by_name,
                 thetas=thetas)
    from ..words import describe_ranking
    rk.messages = describe_ranking(rk)
    for e in rk.entries + rk.parameters:
        e.message = rk_message(rk, e)
    return rk


def _per_group(d: Design, name: str, cv_with: np.ndarray, cv_before: np.ndarray) -> tuple[dict, dict]:
    """Explained fraction and SSE gain per row group where the candidate has a column."""
    per, gain = {}, {}
    for g, gname in enumerate(GROUP_NAMES):
        if cv_before[g] > 0 and _group_has_signal(d, name, g):
            per[gname] = float(1.0 - cv_with[g] / cv_before[g])
            gain[gname] = float(cv_before[g] - cv_with[g])
    return per, gain


def _selected_entry(s: _Search, ev: _Excitation, name: str, c: Candidate, s2: float) -> RankEntry:
    """A selected candidate: its figures from the round it was selected in, its parameters at
    the final point."""
    st = s.steps[name]
    j = st["joint"]
    per, gain = _per_group(j.design, name, j.cv, st["cv_before"])
    phi = s.point.phis[name]
    sig = sigma_of(s.d, name, s.always, s2, s.ratio)
    return RankEntry(effect=name, kind=c.kind, explained_fraction=st["ef"], explained_by_equation=per,
                     parameters=c.phi_report(phi, sig), plausible=c.phi_plausible(phi),
                     excited=True, excitation_z=ev.excitation[name], group=[], selected=True,
                     delta_bic=st["dbic"], explained_gain_by_equation=gain)


def _candidate_entry(s: _Search, ev: _Excitation, name: str, c: Candidate, s2: float,
                     sse_fin: float) -> tuple[RankEntry, np.ndarray]:
    """A candidate not selected, judged against the final model: (entry, its fitted theta)."""
    d, cfg = s.d, s.cfg
    cols = s.always + d.blocks[name]
    cv_w = d.cv(cols)
    ef = 1.0 - cv_w.sum() / max(s.cv_cur.sum(), 1e-300)
    per, gain = _per_group(d, name, cv_w, s.cv_cur)
    th, sse_w, _ = d.fit(cols)
    theta = theta_of(d, name, cols, th)
    sig = sigma_of(d, name, cols, s2, s.ratio)
    jt = s.joints.get(name)
    if jt is not None and name in s.steps:
        dbic = s.steps[name]["dbic"]
        params = c.phi_report(jt.phi, jt.sigma)
        plaus = c.phi_plausible(jt.phi)
    else:
        dbic = s.n_eff * math.log(max(sse_w, 1e-300) / max(sse_fin, 1e-300)) + len(d.blocks[name]) * math.log(s.n_eff)
        params = c.report_params(theta, sig)
        plaus = c.plausible(theta)
    entry = RankEntry(effect=name, kind=c.kind, explained_fraction=ef, explained_by_equation=per,
                      parameters=params, plausible=plaus,
                      excited=ev.excitation[name] >= cfg.excitation_z, excitation_z=ev.excitation[name], group=[],
                      selected=False, delta_bic=dbic, explained_gain_by_equation=gain)
    return entry, theta


def _group_has_signal(d: Design, name: str, g: int) -> bool:
    rows = d.group == g
    rows = np.flatnonzero(rows)
    return any(np.any(take(d.cols[k], rows) != 0) for k in d.blocks[name])


def _parameter_entries(d: Design, ref: Vehicle, base: Vehicle, current, ratio, s2,
                       cfg: RankingConfig) -> list[RankEntry]:
    """The identified parameters as entries: value, sigma, explained fraction of moving each
    from the reference (model file) value to the identified one. Plausible: the value lies
    within ``base_bounds`` times the model file's (positive; the base fit keeps the model's
    value inside them, ``model_value``)."""
    out = []
    lo, hi = cfg.base_bounds
    G, c, yy, _ = d.stats()
    th_all, _, _ = d.fit(current)
    pos = {k: j for j, k in enumerate(current)}
    for p in cfg.identify:
        ref_v = getattr(ref.params, p)
        cur = getattr(base.params, p)
        if p not in d.blocks:
            out.append(RankEntry(effect=PARAM_ALIASES[p], kind="parameter", explained_fraction=0.0,
                                 explained_by_equation={}, parameters={p: (cur, math.nan)}, plausible=cur > 0,
                                 excited=False, excitation_z=math.nan, group=[], reference={p: ref_v},
                                 model_value={p: cur}, plausible_range={p: (lo * ref_v, hi * ref_v)}))
            continue
        k = d.blocks[p][0]
        # residual with the parameter back at the reference: y + X_p (ref - cur) ... in scaled units
        shift = (ref_v - cur) * d.scale[k]
        others = [j for j in current if j != k]
        cv_ref = _cv_shifted(d, others, k, shift)
        cv_fit = d.cv(current)
        ef = 1.0 - cv_fit.sum() / max(cv_ref.sum(), 1e-300)
        sig = sigma_of(d, p, current, s2, ratio)[0]
        val = cur + th_all[pos[k]] / d.scale[k]
        e = RankEntry(effect=PARAM_ALIASES[p], kind="parameter", explained_fraction=ef, explained_by_equation={},
                      parameters={p: (val, sig)}, plausible=bool(lo * ref_v <= val <= hi * ref_v),
                      excited=True, excitation_z=math.nan, group=[], reference={p: ref_v}, model_value={p: cur},
                      plausible_range={p: (lo * ref_v, hi * ref_v)})
        out.append(e)
    out.sort(key=lambda e: -e.explained_fraction)
    return out


def _cv_shifted(d: Design, cols, k: int, shift: float) -> np.ndarray:
    """Held-out SSE per group with column k fixed at -shift (i.e. y replaced by y + shift x_k)."""
    G, c, yy, _ = d.stats()
    # y' = y + s x_k: c' = c + s G[:, k], yy' = yy + 2 s c_k + s^2 G_kk
    c2 = c + shift * G[:, :, :, k]
    yy2 = yy + 2.0 * shift * c[:, :, k] + shift * shift * G[:, :, k, k]
    out = np.zeros(len(GROUP_NAMES))
    cols = list(cols)
    for held, train in d.folds():
        th = d.solve(G[train].sum(axis=(0, 1)), c2[train].sum(axis=(0, 1)), cols)
        cc = c2[held][:, :, cols]
        v = yy2[held] - 2.0 * np.einsum("bgp,p->bg", cc, th) + G[held].quad(cols, th)
        out += v.sum(axis=0)
    return out
