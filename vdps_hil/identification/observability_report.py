"""The observability report: what a sensor set and a drive let the system estimate and identify,
and *why not*, computed from the linearised filter and the identification information (no
lookup of conclusions).

1. Filter windows and 2. the structure of the configured model: the null space of the
   linearised filter's observability matrix explained (``estimation.observability_explain``:
   ``explain_window``, ``structural_report``).

3. Identification (``identification_report``): for each RLS problem (eq 20-23) the accumulated
   information I = sum A^T Q^T Q A (physical A, ``WeightedRLS.information``) is compared with
   the prior information P0^-1 = diag(1 / sigma0^2) in the prior-relative coordinates
   u_j = x_j / x0_j::

       G = S I S,   S = diag(sigma0)   (information gain: eigenvalue 1 = as much as the prior)

   with eigenvalues g_1 <= ... <= g_n and eigenvectors e_1..e_n (in u). A direction is
   *identified* when g >= ``gain_threshold`` (default 1: the drive at least halves the prior
   variance along it). Unidentified directions are explained from the RLS counters and, with
   an ``IdentificationMonitor``, from the inputs: rows never usable because an input was NaN
   (which IdentInputs fields), rows gated by ``excitation_min`` (the largest |A_ij| reached vs
   the gate), or used rows that are collinear (only the combination e_n is identified).

Symbols: I, G information [1/unit^2], gain [-]; sigma0 prior standard deviation (parameter unit).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from vdps_hil.estimation.observability_explain import (Explanation, StructuralReport, WindowExplanation,
                                                        explain_null_space, explain_window, short_state_name,
                                                        structural_report)
from vdps_hil.identification.config import PROBLEM_NAMES, PROBLEM_PARAMS, load_ident_config
from vdps_hil.identification.inputs import IdentInputs
from vdps_hil.identification.problems import REGRESSORS, SUSPENSION_GATE

__all__ = ["ProblemReport", "IdentificationMonitor", "ObservabilityReportDoc", "identification_report",
           "input_dependencies", "observability_report"]


def _example_inputs():
    """A finite, excited IdentInputs (only used to find which fields each problem reads). Optional
    fields (default None; ``moments_nm`` excepted: it overrides the moments) get finite values
    of the length their check accepts."""
    base = IdentInputs(t_ns=1, xdd_a_mps2=0.7, ydd_a_mps2=1.3, zdd_a_mps2=0.4, xd_a_mps=15.0, yd_a_mps=0.3,
                       psi_v_dot_radps=0.1, gravity_aux_mps2=(0.1, -0.2, -9.8), omega_radps=(0.05, -0.04, 0.1),
                       omega_dot_radps2=(0.3, -0.2, 0.4), susp_deflection_m=(0.01, -0.01, 0.02, -0.02),
                       susp_rate_mps=(0.05, -0.05, 0.04, -0.04), wheel_speed_radps=(48.0, 47.0, 46.5, 47.5),
                       wheel_accel_radps2=(2.0, 2.1, 1.9, 2.0), wheel_torque_nm=(300.0, 310.0, 290.0, 305.0),
                       slip_ratio=(0.02, 0.021, 0.019, 0.02), slip_angle_rad=(0.02, 0.021, 0.015, 0.016),
                       wheel_angle_rad=(0.05, 0.048, 0.0, 0.0))
    for f in dataclasses.fields(base):
        if f.name == "moments_nm" or getattr(base, f.name) is not None:
            continue
        for n in (3, 2, 4, 1):
            try:
                base = dataclasses.replace(base, **{f.name: tuple(0.1 * (k + 1) for k in range(n))})
                break
            except (TypeError, ValueError):
                continue
    if getattr(base, "specific_force_b_mps2", None) is not None:
        base = dataclasses.replace(base, specific_force_b_mps2=(0.7, 1.3, 9.9))
    return base


def input_dependencies(vehicle, config=None) -> dict[str, tuple[str, ...]]:
    """Problem -> the IdentInputs fields its regressor (A or b) reads, found by setting each
    field to NaN in an excited example and seeing which rows turn non-finite (computed)."""
    cfg = config or load_ident_config()
    base = _example_inputs()
    skip = {"t_ns", "moments_nm"}
    fields_ = [f.name for f in dataclasses.fields(base) if f.name not in skip]
    out = {}
    for name in PROBLEM_NAMES:
        deps = []
        for fn in fields_:
            v = getattr(base, fn)
            if v is None:
                continue
            nan = tuple(math.nan for _ in v) if isinstance(v, tuple) else math.nan
            inp = dataclasses.replace(base, **{fn: nan})
            reg = REGRESSORS[name](inp, vehicle, vehicle.params, cfg)
            if not (np.isfinite(reg.a).all() and np.isfinite(reg.b).all()):
                deps.append(fn)
        out[name] = tuple(deps)
    return out


class IdentificationMonitor:
    """A drop-in wrapper of an ``Identifier`` (``update(inputs)`` passes through; every other
    attribute is the identifier's) that records, per problem, why rows were not usable: the
    IdentInputs fields that were NaN (among those the problem reads, ``input_dependencies``),
    rows gated by ``excitation_min`` and the largest |A_ij| each row reached."""

    def __init__(self, identifier):
        self._idf = identifier
        self._deps = input_dependencies(identifier.vehicle, identifier.config)
        self.calls = 0
        self.nan_fields = {n: {} for n in PROBLEM_NAMES}
        self.max_excitation = {n: None for n in PROBLEM_NAMES}
        self.gated_rows = {n: 0 for n in PROBLEM_NAMES}
        self.rows_seen = {n: 0 for n in PROBLEM_NAMES}

    def __getattr__(self, name):
        return getattr(self._idf, name)

    @property
    def identifier(self):
        return self._idf

    @property
    def dependencies(self) -> dict[str, tuple[str, ...]]:
        return dict(self._deps)

    def update(self, inputs) -> None:
        self.calls += 1
        idf = self._idf
        params = idf.params
        for name in PROBLEM_NAMES:
            for fn in self._deps[name]:
                v = getattr(inputs, fn)
                if v is None:
                    continue
                bad = any(not math.isfinite(x) for x in v) if isinstance(v, tuple) else not math.isfinite(v)
                if bad:
                    self.nan_fields[name][fn] = self.nan_fields[name].get(fn, 0) + 1
            try:
                reg = REGRESSORS[name](inputs, idf.vehicle, params, idf.config)
            except (ValueError, ArithmeticError):
                continue
            with np.errstate(invalid="ignore"):
                mag = np.max(np.abs(reg.a), axis=1)
            fin = np.isfinite(mag)
            cur = self.max_excitation[name]
            mag0 = np.where(fin, mag, 0.0)
            self.max_excitation[name] = mag0 if cur is None else np.maximum(cur, mag0)
            self.rows_seen[name] += int(fin.sum())
            self.gated_rows[name] += int(np.count_nonzero(fin & ~np.asarray(reg.rows, dtype=bool)))
        idf.update(inputs)


PROBLEM_STATUSES = ("identified", "partially_identified", "not_excited", "inputs_missing", "waiting_upstream")


@dataclass(frozen=True)
class ProblemReport:
    """One identification problem over the drive: parameter names, information-gain
    eigenvalues (ascending) and eigenvectors (columns, prior-relative coordinates), the number of
    identified directions, ``status`` (``PROBLEM_STATUSES``), explanations and the RLS counters."""

    problem: str
    params: tuple[str, ...]
    gains: tuple[float, ...]
    eigenvectors: tuple[tuple[float, ...], ...]
    information_eigenvalues: tuple[float, ...]
    identified: int
    status: str
    explanations: tuple[Explanation, ...]
    counters: dict

    @property
    def fully_identified(self) -> bool:
        return self.identified == len(self.params)

    def to_json(self) -> dict:
        return {"params": list(self.params), "status": self.status, "gain_eigenvalues": list(self.gains),
                "information_eigenvalues": list(self.information_eigenvalues),
                "eigenvectors": [list(v) for v in self.eigenvectors], "identified_directions": self.identified,
                "explanations": [e.to_json() for e in self.explanations], "counters": dict(self.counters)}


def _prior_sigma(identifier, problem: str) -> np.ndarray:
    cfg = identifier.config.problem(problem)
    names = PROBLEM_PARAMS[problem]
    prior = np.array([getattr(identifier.prior, n) for n in names])
    w = np.abs(prior) if cfg.w is None else np.array(cfg.w)
    return cfg.prior_rel_sigma * np.abs(prior) if cfg.p0_scaled is None else math.sqrt(cfg.p0_scaled) * w


MISSING_SHARE = 0.5
"""A problem whose needed inputs were NaN in more than this share of the updates is
``inputs_missing``."""
GATED_SHARE = 0.5
"""... whose finite rows were below the excitation gate in more than this share is
``not_excited`` (as is one that gathered less information than its prior)."""


def identification_report(identifier, monitor: IdentificationMonitor | None = None,
                          gain_threshold: float = 1.0) -> dict[str, ProblemReport]:
    """Per problem (module docstring, item 3). ``identifier`` may be the monitor itself."""
    if isinstance(identifier, IdentificationMonitor):
        monitor, identifier = identifier, identifier.identifier
    out = {}
    for name in PROBLEM_NAMES:
        rls = identifier.problem(name)
        names = PROBLEM_PARAMS[name]
        info = rls.information
        s0 = _prior_sigma(identifier, name)
        prior = np.abs(np.array([getattr(identifier.prior, n) for n in names]))
        # prior-relative coordinates u = x / x0: I_u = diag(x0) I diag(x0), prior info diag(x0^2 / s0^2);
        # gain G = S_u I_u S_u with S_u = diag(s0 / x0) (= diag(s0) I diag(s0))
        g = s0[:, None] * info * s0[None, :]
        gains, vecs = np.linalg.eigh(0.5 * (g + g.T))
        gains = np.maximum(gains, 0.0)
        ident = int(np.sum(gains >= gain_threshold))
        c = rls.counters
        counters = {"updates": c.updates, "rows_used": c.rows_used, "not_excited": c.not_excited,
                    "nan_rows": c.nan_rows, "waiting_upstream": identifier.waiting_upstream.get(name, 0)}
        status, cause = _ident_status(name, rls, monitor, identifier, ident, len(names))
        expl: list[Explanation] = []
        if ident < len(names):
            weak = vecs[:, gains < gain_threshold].T  # unidentified directions (u coordinates)
            if ident == 0:
                expl.append(Explanation(status, tuple(names), tuple(1.0 for _ in names),
                                        f"{name} ({', '.join(names)}): {status.replace('_', ' ')} -- {cause}"))
            else:
                for e in explain_null_space(weak, names, "is barely seen in the data"):
                    text = e.text.replace("not observable", "not identified").replace("is observable", "is identified")
                    expl.append(Explanation(e.kind if e.kind != "not_observable" else "not_identified", e.names,
                                            e.coefficients, f"{name}: {text} ({cause})"))
        out[name] = ProblemReport(name, tuple(names), tuple(float(v) for v in gains),
                                  tuple(tuple(float(x) for x in vecs[:, k]) for k in range(len(names))),
                                  tuple(float(v) for v in np.linalg.eigvalsh(0.5 * (info + info.T))), ident, status,
                                  tuple(expl), counters)
    return out


def _ident_status(name: str, rls, monitor: IdentificationMonitor | None, identifier, ident: int, n: int
                  ) -> tuple[str, str]:
    """(status, cause) of one problem from its counters and, if given, the monitor."""
    c = rls.counters
    gate = identifier.config.problem(name).excitation_min
    waited = identifier.waiting_upstream.get(name, 0)
    if ident == n:
        return "identified", f"{c.rows_used} rows used"
    parts = []
    status = None
    if monitor is not None and monitor.calls:
        nf = {k: v for k, v in monitor.nan_fields[name].items() if v > 0.01 * monitor.calls}
        if nf:
            worst = sorted(nf.items(), key=lambda kv: -kv[1])
            parts.append("NaN inputs: " + ", ".join(f"{k} in {100 * v / monitor.calls:.0f} % of updates"
                                                    for k, v in worst[:4]))
            if max(nf.values()) > MISSING_SHARE * monitor.calls:
                status = "inputs_missing"
        mx = monitor.max_excitation[name]
        seen = monitor.rows_seen[name]
        named = identifier.problem_status[name].gated  # gates with a name: rows they refused
        for g_name, n_rows in sorted(named.items()):
            if n_rows:
                lim = identifier.config.suspension_max_interval_s
                parts.append(f"{n_rows} rows refused as '{g_name}'" + (
                    f" (their strut forces need suspension samples at most {lim:g} s apart and {lim:g} s old)"
                    if g_name == SUSPENSION_GATE else ""))
        if mx is not None and seen:
            low = [i for i, (m, g) in enumerate(zip(mx, gate)) if m < g]
            share = max(monitor.gated_rows[name] - sum(named.values()), 0) / seen
            if low:
                parts.append("below the excitation gate: "
                             + ", ".join(f"row {i + 1} max |A| {mx[i]:.3g} < {gate[i]:.3g}" for i in low))
            if share > 0:
                parts.append(f"{100 * share:.0f} % of the finite rows below the excitation gate")
            if status is None and (share > GATED_SHARE or len(low) == len(gate)):
                status = "not_excited"
    if status is None:
        if c.rows_used == 0 and c.nan_rows:
            status = "inputs_missing"
            parts.append(f"every row that passed the gate had a NaN input ({c.nan_rows} rows)")
        elif c.updates == 0 and waited:
            status = "waiting_upstream"
        elif c.rows_used == 0:
            status = "not_excited"
            parts.append(f"{c.not_excited} calls without a row above the excitation gate")
        elif ident == 0:
            status = "not_excited"
            parts.append(f"{c.rows_used} rows used, carrying less information than the prior")
        else:
            status = "partially_identified"
            parts.append(f"{c.rows_used} rows used; the excitation did not separate the parameters")
    if waited:
        parts.append(f"waited {waited} calls for the upstream problems")
    return status, "; ".join(parts)



@dataclass(frozen=True)
class ObservabilityReportDoc:
    """Everything ``vdps replay --json`` carries under ``observability``: the configuration's
    structure, the windows explained, and (with an identifier) the identification problems."""

    structural: StructuralReport
    windows: tuple[WindowExplanation, ...]
    identification: dict

    def to_json(self) -> dict:
        return {"structural": self.structural.to_json(), "windows": [w.to_json() for w in self.windows],
                "identification": {k: v.to_json() for k, v in self.identification.items()}}

    def summary_lines(self) -> list[str]:
        s = self.structural
        lines = [f"sensor set: {', '.join(s.kinds) or 'no GNSS/suspension measurement'}; generic rank {s.rank} of "
                 f"{s.n_states}"]
        lines += [f"  {e.text}" for e in (*s.not_estimated, *s.explanations)]
        for w in self.windows:
            unobservable = ", ".join(short_state_name(n) for n in w.unobservable)
            lines.append(f"window {w.t_start_s:.1f}-{w.t_end_s:.1f} s: rank {w.rank}/{w.n_states}"
                         + (f", unobservable {unobservable}" if w.unobservable else ""))
        for name, p in self.identification.items():
            lines.append(f"{name}: {p.status}, {p.identified}/{len(p.params)} directions identified, gains "
                         + ", ".join(f"{g:.3g}" for g in p.gains))
            lines += [f"  {e.text}" for e in p.explanations]
        return lines


def observability_report(pipeline, identifier=None, monitor: IdentificationMonitor | None = None,
                         include_in_progress: bool = True) -> ObservabilityReportDoc:
    """The report of a pipeline run (``EstimatorPipeline``; its windows need
    ``observability_window_s``) and optionally its identifier. This is the call ``vdps replay``
    wires: ``observability_report(system.pipeline, system.identifier).to_json()``."""
    cfg = pipeline.config.ekf
    st = structural_report(cfg, pipeline.vehicle.mounting.gnss_lever_arm_m)
    layout = pipeline.ekf.layout
    x_full = None
    if pipeline.ekf.initialized:
        x_full = pipeline.ekf.full_state()[0]
    wins = [explain_window(a, b, r, layout, x_full, st) for a, b, r in pipeline.observability_reports]
    if include_in_progress:
        now = pipeline.observability_now()
        if now is not None and now.rows:
            t1 = pipeline.ekf.t_ns or 0
            t0 = pipeline.observability_reports[-1][1] if pipeline.observability_reports else t1
            wins.append(explain_window(t0, t1, now, layout, x_full, st))
    ident = {} if identifier is None and monitor is None else identification_report(identifier or monitor, monitor)
    return ObservabilityReportDoc(st, tuple(wins), ident)
