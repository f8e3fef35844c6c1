"""Why the filter cannot observe what it cannot: the null space of the observability matrix
put in words, for the windows of a drive and for the configured sensor set (no lookup of
conclusions; the identification side and the whole report:
``vdps_hil.identification.observability_report``).

1. Filter windows (``estimation.observability``): for each window the whitened, scaled
   observability matrix O = [R_k^-1/2 H_k Phi(t_k, t_0)]_k D has the null space N (orthonormal
   rows n_j, scaled coordinates, the right singular vectors of the singular values below
   rtol s_1). ``explain_null_space`` turns N into statements:

   * participation p_i = sum_j n_ji^2 (0..1). A state with p_i >= 1 - eps lies entirely in N:
     "X: not observable".
   * N is projected off those states and brought to reduced row-echelon form over the remaining
     states; each row with support {i, k, ...} is one unobservable combination: moving the
     states together by (c_i, c_k, ...) (scaled units) leaves every measurement unchanged.
     Two states with c_i = c_k ("phi_g, phi_r: only their difference is observable"), with
     c_i = -c_k ("only their sum"), otherwise "only combinations orthogonal to ...".
   * why: the measurement kinds of the window and the process coupling decide which; the
     report names the kinds whose Jacobian columns of those states are zero over the window
     (``structural_report``) and, for states the generic model observes but the window does
     not, says "not excited on this drive".
   * derived outputs y = g^T x: road-relative roll/pitch phi_v, theta_v (eq 4), speed and
     course: unobservable when |N g_s| / |g_s| > ``derived_threshold`` (g_s = D g, scaled).

2. Structure of the configured model (``structural_report``): the rank of O built from the
   configured measurement kinds along a *generic* trajectory (random states and IMU inputs:
   speeds 5-25 m/s, accelerations up to 3 m/s^2, rates up to 0.3 rad/s; seeded) in the full
   layout of eq 7 (road angles estimated). It is the best any drive can give; a drive's window
   with a lower rank lacks excitation. States the configured layout does not carry (road angles
   without suspension) are explained here.

Symbols: O observability matrix (whitened, scaled); N null space; D state scales (1 m, 1 m/s,
0.01 rad); rtol relative singular value threshold.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vdps_hil.estimation.ekf_reference import filter_jacobians
from vdps_hil.estimation.ekf_config import EkfConfig
from vdps_hil.estimation.kinematics import transition, vehicle_angles_eq4
from vdps_hil.estimation.observability import DEFAULT_RTOL, ObservabilityReport, default_scales, observability_rank
from vdps_hil.estimation.observations import ObsKind, make_models
from vdps_hil.estimation.states import ALL_STATE_NAMES, N_EXT, N_FULL, StateLayout

__all__ = ["Explanation", "WindowExplanation", "StructuralReport", "explain_null_space", "explain_window",
           "structural_report", "short_state_name", "STATE_LABELS"]

STATE_LABELS = {
    "x_g_m": "east position", "y_g_m": "north position", "z_g_m": "height",
    "xdot_g_mps": "east velocity", "ydot_g_mps": "north velocity", "zdot_g_mps": "vertical velocity",
    "phi_g_rad": "roll", "theta_g_rad": "pitch", "psi_g_rad": "yaw",
    "phi_r_rad": "road bank", "theta_r_rad": "road grade", "psi_v_rad": "yaw over the road",
    "gyro_bias_x_radps": "roll-rate bias", "gyro_bias_y_radps": "pitch-rate bias", "gyro_bias_z_radps": "yaw-rate bias",
    "accel_bias_x_mps2": "longitudinal accelerometer bias", "accel_bias_y_mps2": "lateral accelerometer bias",
    "accel_bias_z_mps2": "vertical accelerometer bias", "wheel_speed_scale": "wheel-speed scale",
}
"""Plain words for the state names (``STATE_NAMES``)."""

_SHORT = {n: n.rsplit("_", 1)[0] for n in ALL_STATE_NAMES}  # phi_g_rad -> phi_g
_EPS_FULL = 0.02  # participation >= 1 - eps: the state lies entirely in the null space
_COEF_MIN = 0.05  # coefficients below this (relative) are not part of a relation


@dataclass(frozen=True)
class Explanation:
    """One statement: ``names`` involved, the relation ``coefficients`` (scaled units; a
    combination that moves no measurement), ``kind`` (``not_observable``, ``only_difference``,
    ``only_sum``, ``combination``, ``not_estimated``, ``derived``, ``not_excited``) and the
    sentence ``text``."""

    kind: str
    names: tuple[str, ...]
    coefficients: tuple[float, ...]
    text: str

    def to_json(self) -> dict:
        return {"kind": self.kind, "names": list(self.names), "coefficients": list(self.coefficients),
                "text": self.text}


def short_state_name(n: str) -> str:
    """phi_g_rad -> phi_g (the state name without its unit)."""
    return _SHORT.get(n, n)


def _relation_text(names: Sequence[str], coef: np.ndarray, unseen: str = "changes no measurement"
                   ) -> tuple[str, str]:
    """(kind, sentence) for one unobservable combination over ``names``."""
    sn = [short_state_name(n) for n in names]
    if len(names) == 2:
        a, b = coef
        if abs(abs(a) - abs(b)) <= 0.1 * max(abs(a), abs(b)):
            if a * b > 0:
                return "only_difference", f"{sn[0]}, {sn[1]}: only their difference is observable"
            return "only_sum", f"{sn[0]}, {sn[1]}: only their sum is observable"
    terms = " + ".join(f"{c:+.2f} {n}" for c, n in zip(coef, sn)).replace("+ -", "- ")
    return "combination", f"{', '.join(sn)}: not separable; moving them together along ({terms}) {unseen}"


def _rref(a: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Reduced row-echelon form (partial pivoting) of a small dense matrix."""
    m = a.astype(float).copy()
    rows, cols = m.shape
    r = 0
    for c in range(cols):
        if r >= rows:
            break
        p = r + int(np.argmax(np.abs(m[r:, c])))
        if abs(m[p, c]) <= tol:
            continue
        m[[r, p]] = m[[p, r]]
        m[r] /= m[r, c]
        for k in range(rows):
            if k != r:
                m[k] -= m[k, c] * m[r]
        r += 1
    return m[:r]


def explain_null_space(null_space, names: Sequence[str], unseen: str = "changes no measurement"
                       ) -> list[Explanation]:
    """Statements about an unobservable subspace (rows: orthonormal basis, columns ``names``);
    see the module docstring (item 1). ``unseen`` ends the sentence of a general combination
    (a weak rather than null direction: "is barely seen in the data")."""
    n = np.atleast_2d(np.asarray(null_space, dtype=float))
    names = tuple(names)
    if n.size == 0:
        return []
    out: list[Explanation] = []
    part = (n ** 2).sum(axis=0)
    full = [i for i, p in enumerate(part) if p >= 1.0 - _EPS_FULL]
    for i in full:
        label = STATE_LABELS.get(names[i], names[i])
        out.append(Explanation("not_observable", (names[i],), (1.0,),
                               f"{short_state_name(names[i])} ({label}): not observable"))
    # remove the fully unobservable states' directions, keep the rest of the null space
    keep = [i for i in range(len(names)) if i not in full]
    rest = n[:, keep]
    u, s, vt = np.linalg.svd(rest, full_matrices=False)
    basis = vt[s > 1e-6]
    if basis.size == 0:
        return out
    r = _rref(basis)
    for row in r:
        idx = [k for k, c in enumerate(row) if abs(c) > _COEF_MIN * np.max(np.abs(row))]
        if len(idx) < 2:
            continue
        coef = row[idx] / np.max(np.abs(row[idx]))
        nm = tuple(names[keep[k]] for k in idx)
        kind, text = _relation_text(nm, coef, unseen)
        out.append(Explanation(kind, nm, tuple(float(c) for c in coef), text))
    return out


# ------------------------------------------------------------------------------- derived outputs
def derived_gradients(x_full: np.ndarray) -> dict[str, np.ndarray]:
    """Gradients (full 12-state, physical units) of derived outputs at ``x_full``: road-relative
    roll and pitch (eq 4), horizontal speed and course over ground."""
    x = np.asarray(x_full, dtype=float)
    _, jac = vehicle_angles_eq4(x[6:11], with_jacobian=True)
    g = {}
    for k, name in ((0, "phi_v"), (1, "theta_v")):
        v = np.zeros(N_FULL)
        v[6:11] = jac[k]
        g[name] = v
    vx, vy = x[3], x[4]
    sp = math.hypot(vx, vy)
    if sp > 1e-6:
        v = np.zeros(N_FULL)
        v[3], v[4] = vx / sp, vy / sp
        g["speed"] = v
        c = np.zeros(N_FULL)
        c[3], c[4] = -vy / sp ** 2, vx / sp ** 2
        g["course"] = c
    return g


DERIVED_THRESHOLD = 1e-3
"""A derived output whose gradient has more than this fraction inside the null space is not
observable (a linear function of the states is observable iff its gradient is orthogonal to the
null space; the threshold only absorbs round-off)."""


def derived_observability(null_space, layout: StateLayout, x_full, scales=None) -> dict[str, float]:
    """For each derived output y = g^T x: the fraction |N g_s|^2 / |g_s|^2 of its (scaled,
    filter-layout) gradient inside the null space (0 observable; > ``DERIVED_THRESHOLD`` not
    observable)."""
    n = np.atleast_2d(np.asarray(null_space, dtype=float))
    idx = layout.full_index
    d = default_scales(layout) if scales is None else np.asarray(scales, dtype=float)
    out = {}
    for name, g in derived_gradients(x_full).items():
        gs = np.concatenate([g, np.zeros(N_EXT - N_FULL)])[idx] * d  # d y / d (x / D), filter layout
        norm2 = float(gs @ gs)
        if norm2 <= 0.0:
            continue
        out[name] = float(np.sum((n @ gs) ** 2) / norm2) if n.size else 0.0
    return out


# ------------------------------------------------------------------------------- structure
@dataclass(frozen=True)
class StructuralReport:
    """Generic observability of a configuration (module docstring, item 2): ``rank`` of
    ``n_states`` (full layout, road angles estimated), the unobservable states, explanations,
    ``not_estimated`` (states the configured layout fixes, with why), and per measurement kind
    the states its Jacobian never touches along the generic trajectory (``blind``)."""

    kinds: tuple[str, ...]
    rank: int
    n_states: int
    unobservable: tuple[str, ...]
    explanations: tuple[Explanation, ...]
    not_estimated: tuple[Explanation, ...]
    report: ObservabilityReport

    def to_json(self) -> dict:
        return {"kinds": list(self.kinds), "rank": self.rank, "n_states": self.n_states,
                "unobservable": list(self.unobservable),
                "explanations": [e.to_json() for e in self.explanations],
                "not_estimated": [e.to_json() for e in self.not_estimated]}


def _generic_states(rng, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A generic, physically consistent linearisation path: one road plane (bank, grade ~ 2 deg)
    for the whole trajectory (eq 6: constant road angles), the vehicle's speed, course and
    attitude over the road varying epoch to epoch, IMU inputs with accelerations and rates."""
    xs = np.zeros((k, N_FULL))
    fs = np.zeros((k, 3))
    ws = np.zeros((k, 3))
    road = rng.normal(0.0, 0.035, 2)
    for i in range(k):
        sp = rng.uniform(5.0, 25.0)
        crs = rng.uniform(-math.pi, math.pi)
        xs[i, 0:3] = rng.normal(0.0, 200.0, 3)
        xs[i, 3:6] = (sp * math.cos(crs), sp * math.sin(crs), rng.normal(0.0, 0.3))
        xs[i, 6:8] = road + rng.normal(0.0, 0.02, 2)
        xs[i, 8] = crs + rng.normal(0.0, 0.03)
        xs[i, 9:11] = road
        fs[i] = (rng.uniform(-3, 3), rng.uniform(-3, 3), 9.80665 + rng.normal(0.0, 0.5))
        ws[i] = rng.uniform(-0.3, 0.3, 3)
    return xs, fs, ws


_NOMINAL_SIGMA = {ObsKind.GNSS_POS: 1.0, ObsKind.GNSS_ATT: 0.007, ObsKind.GNSS_VEL: 0.1, ObsKind.Y2_GPS: 0.007,
                  ObsKind.Y1_SUS: 4e-4, ObsKind.Y2_SUS_PLANE: 0.001, ObsKind.Y2_SUS_RATE: 0.05,
                  ObsKind.WHEEL_SPEED: 0.05, ObsKind.NHC: 0.1}
"""Whitening of the generic analysis: Table 1 sigmas (GNSS 1 m, attitude 0.4 deg, speed 0.1 m/s,
suspension 1 mm over the wheelbase, heave rate 0.05 m/s); wheel speed 0.05 m/s and the
non-holonomic constraint 0.1 m/s (pipeline defaults)."""


def _blocks_along(xs, fs, ws, layout: StateLayout, kinds, lever_arm, dt: float, wheel_positions_m=None,
                  nhc_point_m=(0.0, 0.0, 0.0)):
    """R = nominal sigma^2 I per kind, Phi products along the generic trajectory, H of each kind
    per epoch."""
    models = make_models(lever_arm, wheel_positions_m, nhc_point_m)
    blocks = []
    phi = np.eye(layout.n)
    for x, f, w in zip(xs, fs, ws):
        xf, e = layout.expand(layout.from_full(x), ext=True)
        for k in kinds:
            aux = _generic_aux(k, w)
            h = models[k].jacobian(xf, aux)
            h = h @ e[:h.shape[1]]
            blocks.append(h @ phi / _NOMINAL_SIGMA[k])
        F, _ = filter_jacobians(layout, xf, f, w)
        phi = transition(F, dt) @ phi
    return blocks


def _generic_aux(kind, w):
    """The aux argument of a kind along the generic trajectory (body rate w where used)."""
    if kind in (ObsKind.GNSS_VEL, ObsKind.NHC):
        return w
    if kind == ObsKind.WHEEL_SPEED:
        return (w, (0.0,) * 4, (0.25,) * 4)
    return None


def structural_report(ekf_config: EkfConfig, gnss_lever_arm_m=(0.0, 0.0, 0.0), *, epochs: int = 40,
                      dt_s: float = 0.2, seed: int = 0, rtol: float = DEFAULT_RTOL) -> StructuralReport:
    """Generic observability of ``ekf_config``'s measurement kinds in the full layout (module
    docstring, item 2). Deterministic for a seed."""
    full_cfg = dataclasses.replace(ekf_config, estimate_road=True)
    layout = full_cfg.layout()
    kinds = tuple(sorted(full_cfg.kinds(), key=lambda k: k.value))
    rng = np.random.default_rng(seed)
    xs, fs, ws = _generic_states(rng, epochs)
    blocks = _blocks_along(xs, fs, ws, layout, kinds, gnss_lever_arm_m, dt_s)
    names = layout.names
    scales = default_scales(layout)
    rep = observability_rank(blocks, names, scales, rtol)
    expl = explain_null_space(rep.null_space, names)
    # which kinds are blind to which states (zero columns over the whole trajectory)
    seen = {}
    models = make_models(gnss_lever_arm_m)
    for k in kinds:
        col = np.zeros(layout.n)
        for x, w in zip(xs, ws):
            xf, e = layout.expand(layout.from_full(x), ext=True)
            h = models[k].jacobian(xf, _generic_aux(k, w))
            col += np.abs(h @ e[:h.shape[1]]).sum(axis=0)
        seen[k.value] = col > 0
    why = []
    for ex in expl:
        idx = [names.index(n) for n in ex.names]
        blind = [k for k, s in seen.items() if not any(s[i] for i in idx)]
        if blind and len(blind) == len(seen):
            why.append(dataclasses.replace(ex, text=ex.text + f" (no measurement kind of this sensor set "
                                           f"({', '.join(seen) or 'none'}) depends on "
                                           f"{'it' if len(idx) == 1 else 'them'}, and the process model "
                                           "does not couple it to one that does)"))
        else:
            why.append(ex)
    not_est = []
    cfg_layout = ekf_config.layout()
    dropped = [n for n in names if n not in cfg_layout.names]
    if dropped:
        dropped_unobs = [n for n in dropped if n in rep.unobservable]
        text = (f"{', '.join(short_state_name(n) for n in dropped)}: not estimated (fixed at 0) by this configuration"
                + ("; the generic rank analysis finds them unobservable with these sensors" if dropped_unobs
                   else ""))
        not_est.append(Explanation("not_estimated", tuple(dropped), tuple(1.0 for _ in dropped), text))
        # consequences for the road-relative angles (eq 4): gradient inside the null space
        x0 = xs[0]
        frac = derived_observability(rep.null_space, layout, x0, scales)
        for nm in ("phi_v", "theta_v"):
            if frac.get(nm, 0.0) > DERIVED_THRESHOLD:
                not_est.append(Explanation("derived", (nm,), (frac[nm],),
                                           f"{nm} (road-relative {'roll' if nm == 'phi_v' else 'pitch'}, eq 4): "
                                           f"not observable ({100 * frac[nm]:.0f} % of its gradient lies in the "
                                           "unobservable subspace: it needs the road angles)"))
    return StructuralReport(tuple(k.value for k in kinds), rep.rank, rep.n_states, rep.unobservable, tuple(why),
                            tuple(not_est), rep)


# ------------------------------------------------------------------------------- windows
@dataclass(frozen=True)
class WindowExplanation:
    """One filter window: times, rank, unobservable states, explanations, derived outputs'
    null-space fractions, and states the generic model observes but this window does not
    (``not_excited``)."""

    t_start_s: float
    t_end_s: float
    rank: int
    n_states: int
    unobservable: tuple[str, ...]
    explanations: tuple[Explanation, ...]
    derived: dict
    not_excited: tuple[str, ...]

    def to_json(self) -> dict:
        return {"t_start_s": self.t_start_s, "t_end_s": self.t_end_s, "rank": self.rank, "n_states": self.n_states,
                "unobservable": list(self.unobservable), "explanations": [e.to_json() for e in self.explanations],
                "derived_null_fraction": dict(self.derived), "not_excited": list(self.not_excited)}


def explain_window(t0_ns: int, t1_ns: int, rep: ObservabilityReport, layout: StateLayout, x_full=None,
                   structural: StructuralReport | None = None) -> WindowExplanation:
    """Explain one pipeline window (``EstimatorPipeline.observability_reports`` entry)."""
    names = layout.names
    expl = list(explain_null_space(rep.null_space, names))
    derived = {} if x_full is None else derived_observability(rep.null_space, layout, x_full)
    not_exc: tuple[str, ...] = ()
    if structural is not None:
        not_exc = tuple(n for n in rep.unobservable if n not in structural.unobservable)
        if not_exc:
            expl.append(Explanation("not_excited", not_exc, tuple(1.0 for _ in not_exc),
                                    f"{', '.join(short_state_name(n) for n in not_exc)}: observable with these sensors "
                                    "(generic rank analysis) but not excited in this window"))
    return WindowExplanation(t0_ns / 1e9, t1_ns / 1e9, rep.rank, rep.n_states, rep.unobservable, tuple(expl),
                             derived, not_exc)
