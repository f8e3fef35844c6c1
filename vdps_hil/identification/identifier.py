"""The online identifier of section 5.2: one weighted RLS (``rls.WeightedRLS``, eq 19) per problem
(``problems``, eq 20-23), updated in the order mass, tracking, cornering, inertia (Gauss-Seidel:
each with the newest estimates of the others; a problem waits for its ``config.UPSTREAM`` problems),
with the parameters' covariances including what the upstream estimates contribute (consider
covariance), identifiability and convergence; a problem is "converged" only when every
parameter of it is identified (``status``: not at a bound, excited, no model mismatch, the drive
taught more than the prior).
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np

from vdps_hil.identification.config import (PROBLEM_NAMES, PROBLEM_PARAMS, UPSTREAM, IdentConfig,
                                            load_ident_config)
from vdps_hil.identification.inputs import IdentInputs
from vdps_hil.identification.mismatch import CROSS_CHECKS, MismatchMonitor
from vdps_hil.identification.problems import REGRESSORS
from vdps_hil.identification.rls import RLSCounters, WeightedRLS
from vdps_hil.identification.status import ProblemStatus, cause_without_sigma, problem_status
from vdps_hil.model.params import IdentifiedParams, Vehicle


class Identifier:
    """Online identification of the ten parameters (section 5.2), one RLS per problem.

    ``vehicle`` must be a *model* vehicle file (its params are the priors; the truth file is
    refused). ``start`` (e.g. from :func:`~.persistence.load_params`) replaces the starting
    values, not the priors used for W, the bounds and sigma0's scale.
    """

    def __init__(self, vehicle: Vehicle, config: IdentConfig | None = None,
                 start: IdentifiedParams | None = None):
        if vehicle.kind != "model":
            raise ValueError(f"the identifier needs a model vehicle file, got a {vehicle.kind!r} file")
        self._vehicle = vehicle
        self._prior = vehicle.params
        self._start = start if start is not None else vehicle.params
        self.config = config if config is not None else load_ident_config()
        self._sigma0: dict[str, np.ndarray] = {}
        self._rls = {name: self._make(name) for name in PROBLEM_NAMES}
        self._excited = {name: False for name in PROBLEM_NAMES}
        self._waiting = {name: 0 for name in PROBLEM_NAMES}
        self._ready = {name: False for name in PROBLEM_NAMES}
        self._idle = {name: 0 for name in PROBLEM_NAMES}  # consecutive inputs without an update
        self._gated = {name: {} for name in PROBLEM_NAMES}  # excitation gate -> inputs it refused
        self._structure = {name: np.zeros(len(PROBLEM_PARAMS[name])) for name in PROBLEM_NAMES}  # sum A^T Q^2 s
        self._mismatch = {name: MismatchMonitor(name, self.config.status, self.config.problem(name).q)
                          for name in PROBLEM_NAMES}
        self._inputs_rejected = 0
        self._last_t_ns: int | None = None
        self._params = self._collect()
        self._derived: dict[str, object] = {}  # covariances, problem_status: until the next update/reset

    def _make(self, name: str) -> WeightedRLS:
        pc = self.config.problem(name)
        names = PROBLEM_PARAMS[name]
        prior = np.array([getattr(self._prior, n) for n in names])
        x0 = np.array([getattr(self._start, n) for n in names])
        lo, hi = self.config.bounds_factor
        w = np.abs(prior) if pc.w is None else np.array(pc.w)
        sigma0 = pc.prior_rel_sigma * np.abs(prior) if pc.p0_scaled is None else math.sqrt(pc.p0_scaled) * w
        self._sigma0[name] = np.broadcast_to(np.asarray(sigma0, dtype=float), prior.shape).copy()
        return WeightedRLS(
            x0, sigma0, pc.q, w,
            forgetting=pc.forgetting, lower=lo * prior, upper=hi * prior,
            bounds_mode=self.config.bounds_mode, form=self.config.form,
            sigma_autocorr=self.config.sigma_autocorr, min_dof=self.config.min_dof, names=names,
            jackknife_blocks=self.config.status.sigma_blocks, jackknife_span=self.config.status.sigma_block_updates)

    def _collect(self) -> IdentifiedParams:
        """The current estimates of every problem (``_values``: name -> value, kept for
        ``update``, which changes one problem's at a time)."""
        self._values = {}
        for name, rls in self._rls.items():
            self._values.update(zip(PROBLEM_PARAMS[name], rls.x.tolist()))
        return IdentifiedParams(**self._values)

    def update(self, inputs: IdentInputs) -> None:
        """Feed one set of estimates; each problem updates if excited (mass, tracking,
        cornering, inertia, in that order, each with the newest estimates of the others)."""
        if not isinstance(inputs, IdentInputs):
            raise TypeError(f"Identifier.update needs IdentInputs, got {type(inputs).__name__}")
        self._derived.clear()
        if self._last_t_ns is not None and inputs.t_ns <= self._last_t_ns:
            self._inputs_rejected += 1  # duplicate or out of order: would count data twice
            return
        self._last_t_ns = inputs.t_ns
        for name in PROBLEM_NAMES:
            if not self._upstream_ready(name):
                self._waiting[name] += 1
                self._excited[name] = False
                continue
            reg = REGRESSORS[name](inputs, self._vehicle, self._params, self.config)
            gated = self._gated[name]
            if reg.gated is not None:
                gated[reg.gated] = gated.get(reg.gated, 0) + 1
            for gate, n in (reg.row_gates or {}).items():
                gated[gate] = gated.get(gate, 0) + int(n)
            rls = self._rls[name]
            x_prior, c_prior = rls.x, rls.covariance
            self._excited[name] = rls.update(reg.a, reg.b, reg.rows, db_dtheta=reg.db_dup)
            if self._excited[name]:
                self._add_structure(name, reg)
                self._mismatch[name].observe(inputs.t_ns, reg, x_prior, c_prior)
                self._values.update(zip(PROBLEM_PARAMS[name], rls.x.tolist()))
                self._params = IdentifiedParams(**self._values)
                self._idle[name] = 0
            else:
                self._idle[name] += 1

    def _add_structure(self, name: str, reg) -> None:
        """Accumulate g = sum_k A_k^T Q^2 s_k over the rows the update used (``Regressor.structure``
        s_k: an unmodelled term of b), with the problem's forgetting factor; the least-squares bias
        that term causes is C g (``_structure_bias``)."""
        pc = self.config.problem(name)
        if pc.forgetting != 1.0:
            self._structure[name] *= pc.forgetting
        if reg.structure is None:
            return
        # in floats, numpy's order: column sums from 0.0 over the used rows of A_i (Q_ii^2 s_i)
        a = np.asarray(reg.a, dtype=float).tolist()
        g = [0.0] * len(a[0])
        for row, s, q, used in zip(a, np.asarray(reg.structure, dtype=float).tolist(), pc.q, reg.used):
            if used and math.isfinite(s):
                f = q * q * s
                g = [gj + v * f for gj, v in zip(g, row)]
        self._structure[name] += g

    def _structure_bias(self, name: str) -> np.ndarray:
        """The least-squares bias C g of a problem's unmodelled term (``_add_structure``; C the
        RLS covariance at unit residual variance, W P W): what the fit would move if the term were
        there in full. Zero when the regressor carries none."""
        return self._rls[name].covariance @ self._structure[name]

    def _upstream_ready(self, name: str) -> bool:
        """Ready when every upstream problem has ``upstream_min_updates`` updates or has been
        unexcited for the last ``upstream_idle_inputs`` inputs (an unexcited upstream problem, e.g.
        the tracking stiffness at a constant speed, contributes ~ C lambda ~ 0 to b: its rows are
        gated because lambda is small), or after ``upstream_max_wait`` calls. Once ready a problem
        stays ready until a reset."""
        if self._ready[name]:
            return True
        cfg = self.config
        idle = cfg.upstream_idle_inputs

        def settled(up):
            return (self._rls[up].counters.updates >= cfg.upstream_min_updates
                    or (idle > 0 and self._idle[up] >= idle))
        if all(settled(up) for up in UPSTREAM[name]) or self._waiting[name] >= cfg.upstream_max_wait:
            self._ready[name] = True
        return self._ready[name]

    def reset(self, problem: str | None = None, start: IdentifiedParams | None = None) -> None:
        """Back to the starting values (or ``start``) for one problem or all."""
        if start is not None:
            self._start = start
        self._derived.clear()
        for name in PROBLEM_NAMES if problem is None else (problem,):
            if name not in self._rls:
                raise KeyError(f"unknown problem {name!r}; one of {PROBLEM_NAMES}")
            self._rls[name].reset(np.array([getattr(self._start, n) for n in PROBLEM_PARAMS[name]]))
            self._excited[name] = False
            self._idle[name] = 0
            self._gated[name] = {}
            self._structure[name] = np.zeros(len(PROBLEM_PARAMS[name]))
            self._mismatch[name].reset()
        self._ready = {name: False for name in PROBLEM_NAMES}  # dependants re-check their upstream
        self._waiting = {name: 0 for name in PROBLEM_NAMES}
        self._params = self._collect()
        if problem is None:
            self._last_t_ns = None

    # ------------------------------------------------------------------ read-only
    @property
    def params(self) -> IdentifiedParams:
        """The current estimates: a new frozen object (the model file's other figures unchanged)."""
        return self._params

    @property
    def vehicle(self) -> Vehicle:
        """The model vehicle with the identified parameters (``Vehicle.with_params``)."""
        return self._vehicle.with_params(**self._params.as_dict())

    @property
    def prior(self) -> IdentifiedParams:
        return self._prior

    def handover_params(self) -> tuple[IdentifiedParams, tuple[str, ...]]:
        """The parameters a drive hands over (``--save-params``, a calibration): the current
        estimates, except those "at bound" (``status``: unexcited or model mismatch, never a
        value), which keep this run's start value; and the names of those."""
        at_bound = tuple(p.name for st in self.problem_status.values() for p in st.params if p.status == "at bound")
        if not at_bound:
            return self._params, ()
        vals = self._params.as_dict()
        vals.update({n: getattr(self._start, n) for n in at_bound})
        return IdentifiedParams(**vals), at_bound

    @property
    def covariances(self) -> dict[str, np.ndarray]:
        """Problem -> covariance of its parameters (physical units), corrected so that it does not
        rest on the noise model alone (``_honest``), plus the consider covariance of the upstream
        estimates it used (block-diagonal over the upstream problems, cascaded in update order).
        Computed once per update (the chain reads it at every estimate); each call returns
        copies."""
        return self._derived_covariances("covariances", honest=True)

    @property
    def covariances_raw(self) -> dict[str, np.ndarray]:
        """As ``covariances`` with the RLS's covariance W P W alone: white residuals with the
        configured noise 1 / Q (``rls``), upstream included the same way (raw upstream)."""
        return self._derived_covariances("covariances_raw", honest=False)

    def _derived_covariances(self, key: str, honest: bool) -> dict[str, np.ndarray]:
        cov = self._derived.get(key)
        if cov is None:
            cov = self._derived[key] = self._covariances(honest)
        return {k: v.copy() for k, v in cov.items()}

    def _honest(self, name: str) -> np.ndarray:
        """One problem's own covariance, no upstream share. Two estimates of the variance of x_j,
        the larger taken (each is consistent under its own assumptions, neither under the
        other's):

        * model-based: s^2 f_j (W P W)_jj (``WeightedRLS.parameter_covariance``: the a posteriori
          residual variance against the design noise, the AR(1) factor of the scores), scaled by
          max(1, tau / f_j) with the residuals' long-run variance ratio tau
          (``MismatchMonitor.variance_scale``: batch means and integrated autocorrelation time);
        * the delete-a-block jackknife V_J (``WeightedRLS.jackknife_covariance``, Kuensch 1989):
          the spread of the solution over the drive, no noise model assumed; it sees what the
          residual statistics cannot: a model error the fit absorbs differently in different
          parts of the drive.

        Each parameter's row and column are scaled by sqrt(max(1, V_J,jj / C_jj)), so the
        correlations of the model-based covariance C are kept. A model-structure share is added:
        beta beta^T with beta = ``_structure_bias`` (an unmodelled term of b whose presence the
        model cannot decide, e.g. the mass problem's strut axis in pitch, ``problems``): the same
        in every block of the drive, so neither estimate above can see it."""
        rls = self._rls[name]
        d = np.sqrt(np.maximum(self._mismatch[name].variance_scale / rls.autocorr_inflation, 1.0))
        c = rls.parameter_covariance * np.outer(d, d)
        vj = rls.jackknife_covariance
        if vj is not None:
            cd = np.diag(c)
            with np.errstate(divide="ignore", invalid="ignore"):
                h = np.sqrt(np.where(cd > 0.0, np.maximum(np.diag(vj) / cd, 1.0), 1.0))
            c = c * np.outer(h, h)
        beta = self._structure_bias(name)
        return c + np.outer(beta, beta)

    def _covariances(self, honest: bool, only=None) -> dict[str, np.ndarray]:
        """Problem -> covariance (``covariances``); ``only``: these problems alone (each with its
        upstream problems: the same numbers, computed the same way)."""
        out: dict[str, np.ndarray] = {}
        for name in PROBLEM_NAMES:
            if only is not None and name not in only:
                continue
            rls = self._rls[name]
            c = self._honest(name) if honest else rls.covariance
            ups = UPSTREAM[name]
            if ups:
                blocks = [out[u] for u in ups]
                size = sum(b.shape[0] for b in blocks)
                cu, i = np.zeros((size, size)), 0
                for blk in blocks:
                    k = blk.shape[0]
                    cu[i:i + k, i:i + k] = blk
                    i += k
                c = c + rls.consider_covariance(cu)
            out[name] = c
        return out

    @property
    def sigmas(self) -> dict[str, float]:
        """Parameter field name -> standard deviation (same unit as the parameter): the corrected
        one (``covariances``), the uncertainty inherited from the upstream problems included. This
        is the sigma every output carries (status, ``/est/ident``, ``--save-params``)."""
        return _diag_sigmas(self.covariances)

    @property
    def sigmas_raw(self) -> dict[str, float]:
        """As ``sigmas`` from ``covariances_raw`` (white residuals with the configured noise): kept
        beside the corrected one to show how much the correction widened it."""
        return _diag_sigmas(self.covariances_raw)

    @property
    def identifiability(self) -> dict[str, float]:
        """Problem -> minimum eigenvalue of the accumulated A^T Q^T Q A (Table 3)."""
        return {name: rls.identifiability for name, rls in self._rls.items()}

    @property
    def excited(self) -> dict[str, bool]:
        """Problem -> whether the last ``update`` changed it."""
        return dict(self._excited)

    @property
    def counters(self) -> dict[str, RLSCounters]:
        return {name: rls.counters for name, rls in self._rls.items()}

    @property
    def waiting_upstream(self) -> dict[str, int]:
        """Problem -> updates skipped because an upstream problem was not ready yet."""
        return dict(self._waiting)

    @property
    def inputs_rejected(self) -> int:
        """Inputs refused before any problem saw them (duplicate or out-of-order t_ns)."""
        return self._inputs_rejected

    @property
    def problem_status(self) -> dict[str, ProblemStatus]:
        """Problem -> its ``status.ProblemStatus`` (per parameter: identified or why not); computed
        once per update."""
        st = self._derived.get("problem_status")
        if st is None:
            st = self._derived["problem_status"] = self._problem_status()
        return dict(st)

    def _problem_status(self) -> dict[str, ProblemStatus]:
        sig = self.sigmas
        raw = self.sigmas_raw
        return {name: problem_status(name, PROBLEM_PARAMS[name], rls, self._sigma0[name], sig,
                                     self._failed_rows(name), self._gated[name], self.config, sigmas_raw=raw)
                for name, rls in self._rls.items()}

    def _failed_rows(self, name: str) -> tuple[str, ...]:
        """The rows whose residual test failed for a problem: its own, and the downstream rows
        that test it too (``CROSS_CHECKS``, named "problem.row")."""
        failed = self._mismatch[name].failed_rows
        for p, row in CROSS_CHECKS.get(name, ()):
            if row in self._mismatch[p].failed_rows:
                failed += (f"{p}.{row}",)
        return failed

    @property
    def converged(self) -> dict[str, bool]:
        """Problem -> every parameter identified (``status``): excited, off its bounds, no model
        mismatch, identifiable, and every sigma/|x| (upstream included) below
        ``converged_rel_sigma`` after ``min_updates_converged`` updates."""
        return {name: st.converged for name, st in self.problem_status.items()}

    def converged_of(self, names) -> dict[str, bool]:
        """Problem -> converged, as ``converged`` gives it, for the named problems only. A problem
        that a cause other than its sigma already keeps from converging (not excited, at bound,
        model mismatch, not identifiable, too few updates: ``status.cause_without_sigma``) is
        answered without the corrected covariances of every problem, which ``problem_status``
        needs (about 0.5 ms, at the warning chain's 50 Hz). The others are judged by
        ``problem_status``'s own rule on the corrected covariances of these problems and their
        upstream problems alone (the same numbers; ``problem_status`` itself when this update
        already computed it)."""
        full = self._derived.get("problem_status")
        if full is not None:
            return {name: full[name].converged for name in names}
        out, todo = {}, []
        for name in names:
            failed = self._failed_rows(name)
            if cause_without_sigma(self._rls[name], self._sigma0[name], failed, self.config) is not None:
                out[name] = False
            else:
                todo.append((name, failed))
        if todo:
            sig = _diag_sigmas(self._covariances(True, _with_upstream(n for n, _ in todo)))
            for name, failed in todo:
                out[name] = problem_status(name, PROBLEM_PARAMS[name], self._rls[name], self._sigma0[name], sig,
                                           failed, self._gated[name], self.config).converged
        return out

    def mismatch_tests(self, name: str):
        """The residual tests of one problem's rows (``mismatch.RowTest``)."""
        return self._mismatch[name].tests()

    @staticmethod
    def upstream_param_names(name: str) -> tuple[str, ...]:
        """The parameters (in order) of the columns of a problem's ``Regressor.db_dup``."""
        return tuple(p for u in UPSTREAM[name] for p in PROBLEM_PARAMS[u])

    def problem(self, name: str) -> WeightedRLS:
        """The RLS of one problem (read its diagnostics; do not update it directly)."""
        return self._rls[name]

    def status(self) -> dict:
        """A JSON-ready summary (params, sigmas, identifiability, excited, converged, counters)."""
        return {
            "params": self._params.as_dict(),
            "sigmas": self.sigmas,
            "sigmas_raw": self.sigmas_raw,
            "identifiability": self.identifiability,
            "excited": self.excited,
            "converged": self.converged,
            "status": {n: st.to_json() for n, st in self.problem_status.items()},
            "mismatch": {n: [t.to_json() for t in m.tests()] for n, m in self._mismatch.items()},
            "counters": {n: {f.name: getattr(c, f.name) for f in fields(c)} for n, c in self.counters.items()},
            "waiting_upstream": self.waiting_upstream,
            "inputs_rejected": self._inputs_rejected,
        }


def _with_upstream(names) -> set[str]:
    """The named problems and every problem upstream of them (``UPSTREAM``, transitively)."""
    out, stack = set(), list(names)
    while stack:
        n = stack.pop()
        if n not in out:
            out.add(n)
            stack.extend(UPSTREAM[n])
    return out


def _diag_sigmas(cov: dict[str, np.ndarray]) -> dict[str, float]:
    out = {}
    for name, c in cov.items():
        out.update(zip(PROBLEM_PARAMS[name], (math.sqrt(max(float(v), 0.0)) for v in np.diag(c))))
    return out
