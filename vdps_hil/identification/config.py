"""The identification problems by name and their configuration (``configs/identification/*.toml``).

``PROBLEM_NAMES`` (the update order), ``PROBLEM_PARAMS`` (the parameters of each problem, fields
of ``model.params.IdentifiedParams``), ``PROBLEM_ROWS`` (rows of its regressor) and ``UPSTREAM``
(problems whose estimates enter its b) define the four problems of eq 20-23 (``problems``);
``IdentConfig`` (general settings) and one ``ProblemConfig`` per problem (Q, W, forgetting,
prior sigma, excitation gate) are parsed from TOML with one-line errors (``IdentConfigError``).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from vdps_hil.identification.rls import BOUNDS_MODES, FORMS
from vdps_hil.model.params import CONFIG_DIR

IDENT_CONFIG_DIR = CONFIG_DIR / "identification"
DEFAULT_CONFIG_PATH = IDENT_CONFIG_DIR / "default.toml"
CONFIG_SCHEMA_VERSION = 1
STEER_FORMS = ("per_wheel", "paper_mean")
MASS_FORMS = ("paper", "sprung")
MOMENT_FORMS = ("stiffness", "measured")

PROBLEM_NAMES: tuple[str, ...] = ("mass", "tracking", "cornering", "inertia")
"""Update order (Gauss-Seidel: each problem uses the newest estimates of the previous ones)."""

PROBLEM_PARAMS: dict[str, tuple[str, ...]] = {
    "mass": ("mass_kg",),
    "tracking": ("tracking_stiffness_1_n", "tracking_stiffness_2_n", "tracking_stiffness_3_n",
                 "tracking_stiffness_4_n"),
    "cornering": ("cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad"),
    "inertia": ("inertia_x_kgm2", "inertia_y_kgm2", "inertia_z_kgm2"),
}
PROBLEM_ROWS = {"mass": 1, "tracking": 4, "cornering": 2, "inertia": 3}
OPTIONAL_ROWS = {"cornering": 1}
"""Rows a problem may add after its PROBLEM_ROWS: a ``[cornering]`` table whose ``q`` and
``excitation_min`` have 3 entries uses eq 22's yaw row (``problems.cornering_regressor``)."""
UPSTREAM: dict[str, tuple[str, ...]] = {"mass": (), "tracking": (), "cornering": ("mass", "tracking"),
                                        "inertia": ("tracking", "cornering")}
"""Problems whose estimates enter a problem's b (eq 22: m, C_lambda; eq 23's moments: C_lambda,
C_alpha). A problem waits until each of these has ``upstream_min_updates`` updates (at most
``upstream_max_wait`` calls): rows built from the priors would otherwise stay in its memory
(weight 1/N without forgetting)."""


class IdentConfigError(ValueError):
    """An identification config that cannot be used (one-line message)."""


@dataclass(frozen=True)
class ProblemConfig:
    q: tuple[float, ...]  # diagonal of Q, 1/(unit of b_i), one per row
    w: tuple[float, ...] | None  # diagonal of W, one per parameter; None = the priors
    forgetting: float  # lambda in (0, 1]
    prior_rel_sigma: float  # prior sd as a fraction of the prior value
    excitation_min: tuple[float, ...]  # per row, in the regressor row's unit
    p0_scaled: float | None = None  # if set: P_Q(0) = p0_scaled I (the paper's P(0)), overrides prior_rel_sigma
    lateral_accel_min_mps2: float = 0.0  # cornering only: no row below this lateral excitation (``problems``)
    lateral_accel_max_mps2: float = math.inf  # cornering only: no row beyond eq 15's linear range
    slip_noise_factor: float = 0.0  # cornering only: |alpha_axle| >= factor x sigma_alpha
    load_band: float = math.inf  # tracking only: a wheel's row needs |F_z,i / F_z0,i - 1| <= this (``problems``)


@dataclass(frozen=True)
class StatusConfig:
    """When a parameter is reported identified (``identification.status``): ``bound_margin``
    (a value within this fraction of its bound's distance is "at bound"), ``min_variance_ratio``
    (prior / posterior variance along the parameter, unit residual variance, below which the
    drive taught too little: "not identifiable"), and the model-mismatch test of each problem
    (``identification.mismatch``: ``mismatch_*``), and the block jackknife behind the reported
    sigmas (``identification.jackknife``: ``sigma_blocks``, ``sigma_block_updates``)."""

    bound_margin: float = 0.02
    min_variance_ratio: float = 4.0
    mismatch_test: bool = True
    mismatch_min_rows: int = 200
    mismatch_variance_max: float = 50.0
    mismatch_lag_s: float = 0.5
    mismatch_whiteness_max: float = 1.0
    sigma_blocks: int = 10  # the jackknife's target block count K (``jackknife``); 0: model-based sigmas only
    sigma_block_updates: int = 50  # updates in a first block (the span doubles as the drive grows)


@dataclass(frozen=True)
class IdentConfig:
    form: str
    bounds_mode: str
    bounds_factor: tuple[float, float]  # physical bounds = factor x model-file prior
    min_speed_mps: float
    sigma_autocorr: bool
    min_dof: int
    converged_rel_sigma: float
    min_updates_converged: int
    steer_form: str
    mass_form: str
    upstream_min_updates: int
    upstream_max_wait: int
    mass: ProblemConfig
    tracking: ProblemConfig
    cornering: ProblemConfig
    inertia: ProblemConfig
    moment_form: str = "stiffness"  # eq 23's b: "stiffness" (eq 15 forces) or "measured" (docstring)
    upstream_idle_inputs: int = 0  # an upstream problem unexcited for this many inputs does not block (0: off)
    suspension_max_interval_s: float = 0.02  # strut-force rows need suspension this fresh (``problems``)
    status: StatusConfig = StatusConfig()

    def problem(self, name: str) -> ProblemConfig:
        return getattr(self, name)


_GENERAL_KEYS = {"form", "bounds_mode", "bounds_factor", "min_speed_mps", "sigma_autocorr", "min_dof",
                 "converged_rel_sigma", "min_updates_converged", "steer_form", "mass_form", "upstream_min_updates",
                 "upstream_max_wait"}
_GENERAL_OPTIONAL = {"moment_form", "upstream_idle_inputs", "suspension_max_interval_s"}
_PROBLEM_KEYS = {"q", "w", "forgetting", "prior_rel_sigma", "excitation_min"}
_PROBLEM_OPTIONAL = {"p0_scaled", "lateral_accel_min_mps2", "lateral_accel_max_mps2", "slip_noise_factor", "load_band"}
_CORNERING_ONLY = {"lateral_accel_min_mps2", "lateral_accel_max_mps2", "slip_noise_factor"}
_TRACKING_ONLY = {"load_band"}


def _num(v, where: str, positive: bool = False, nonneg: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise IdentConfigError(f"{where}: expected a finite number, got {v!r}")
    if positive and v <= 0:
        raise IdentConfigError(f"{where}: must be positive, got {v!r}")
    if nonneg and v < 0:
        raise IdentConfigError(f"{where}: must not be negative, got {v!r}")
    return float(v)


def _nums(v, n: int, where: str, positive: bool = False, nonneg: bool = False) -> tuple[float, ...]:
    if not isinstance(v, list) or len(v) != n:
        raise IdentConfigError(f"{where}: expected a list of {n} numbers")
    return tuple(_num(e, f"{where}[{i}]", positive, nonneg) for i, e in enumerate(v))


def _check_keys(table, allowed: set, where: str) -> None:
    if not isinstance(table, dict):
        raise IdentConfigError(f"{where}: expected a table")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise IdentConfigError(f"{where}: unknown key {unknown[0]!r}")
    missing = sorted(allowed - set(table))
    if missing:
        raise IdentConfigError(f"{where}: missing key {missing[0]!r}")


def parse_ident_config(text: str, origin: str = "<string>") -> IdentConfig:
    """Parse an identification config (TOML text); one-line :class:`IdentConfigError`."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise IdentConfigError(f"{origin}: malformed TOML: {e}") from None
    _check_keys({k: v for k, v in doc.items() if k != "status"}, {"schema_version", "general", *PROBLEM_NAMES}, origin)
    if doc["schema_version"] != CONFIG_SCHEMA_VERSION:
        raise IdentConfigError(f"{origin}: schema_version {doc['schema_version']!r} is not "
                               f"{CONFIG_SCHEMA_VERSION}")
    g = doc["general"]
    opt = {k: v for k, v in g.items() if k in _GENERAL_OPTIONAL} if isinstance(g, dict) else {}
    moment_form = opt.get("moment_form", "stiffness")
    if isinstance(g, dict):
        g = {k: v for k, v in g.items() if k not in _GENERAL_OPTIONAL}
    _check_keys(g, _GENERAL_KEYS, f"{origin}[general]")
    idle = opt.get("upstream_idle_inputs", 0)
    if isinstance(idle, bool) or not isinstance(idle, int) or idle < 0:
        raise IdentConfigError(f"{origin}[general].upstream_idle_inputs: expected a non-negative integer")
    if moment_form not in MOMENT_FORMS:
        raise IdentConfigError(f"{origin}[general].moment_form: one of {MOMENT_FORMS}, got {moment_form!r}")
    if g["form"] not in FORMS:
        raise IdentConfigError(f"{origin}[general].form: one of {FORMS}, got {g['form']!r}")
    if g["bounds_mode"] not in BOUNDS_MODES:
        raise IdentConfigError(f"{origin}[general].bounds_mode: one of {BOUNDS_MODES}, got {g['bounds_mode']!r}")
    if g["steer_form"] not in STEER_FORMS:
        raise IdentConfigError(f"{origin}[general].steer_form: one of {STEER_FORMS}, got {g['steer_form']!r}")
    if g["mass_form"] not in MASS_FORMS:
        raise IdentConfigError(f"{origin}[general].mass_form: one of {MASS_FORMS}, got {g['mass_form']!r}")
    if not isinstance(g["sigma_autocorr"], bool):
        raise IdentConfigError(f"{origin}[general].sigma_autocorr: expected true or false")
    lo, hi = _nums(g["bounds_factor"], 2, f"{origin}[general].bounds_factor", positive=True)
    if not lo < 1.0 < hi:
        raise IdentConfigError(f"{origin}[general].bounds_factor: need lo < 1 < hi, got [{lo}, {hi}]")
    for k in ("min_dof", "min_updates_converged", "upstream_min_updates", "upstream_max_wait"):
        if isinstance(g[k], bool) or not isinstance(g[k], int) or g[k] < 0:
            raise IdentConfigError(f"{origin}[general].{k}: expected a non-negative integer")
    problems = {}
    for name in PROBLEM_NAMES:
        where = f"{origin}[{name}]"
        t = doc[name]
        _check_keys({k: v for k, v in t.items() if k not in _PROBLEM_OPTIONAL} if isinstance(t, dict) else t,
                    _PROBLEM_KEYS, where)
        if name != "cornering" and set(t) & _CORNERING_ONLY:
            raise IdentConfigError(f"{where}: {sorted(set(t) & _CORNERING_ONLY)[0]!r} applies to [cornering] only")
        if name != "tracking" and set(t) & _TRACKING_ONLY:
            raise IdentConfigError(f"{where}: {sorted(set(t) & _TRACKING_ONLY)[0]!r} applies to [tracking] only")
        m, n = PROBLEM_ROWS[name], len(PROBLEM_PARAMS[name])
        if isinstance(t.get("q"), list) and len(t["q"]) == m + OPTIONAL_ROWS.get(name, 0):
            m = len(t["q"])
        w = t["w"]
        if w == "prior":
            w_t = None
        else:
            w_t = _nums(w, n, f"{where}.w", positive=True)
        lam = _num(t["forgetting"], f"{where}.forgetting", positive=True)
        if lam > 1.0:
            raise IdentConfigError(f"{where}.forgetting: must be in (0, 1], got {lam}")
        problems[name] = ProblemConfig(
            q=_nums(t["q"], m, f"{where}.q", positive=True), w=w_t, forgetting=lam,
            prior_rel_sigma=_num(t["prior_rel_sigma"], f"{where}.prior_rel_sigma", positive=True),
            excitation_min=_nums(t["excitation_min"], m, f"{where}.excitation_min", nonneg=True),
            p0_scaled=(_num(t["p0_scaled"], f"{where}.p0_scaled", positive=True) if "p0_scaled" in t else None),
            **{k: _num(t[k], f"{where}.{k}", nonneg=True) for k in _CORNERING_ONLY | _TRACKING_ONLY if k in t})
    return IdentConfig(
        form=g["form"], bounds_mode=g["bounds_mode"], bounds_factor=(lo, hi),
        min_speed_mps=_num(g["min_speed_mps"], f"{origin}[general].min_speed_mps", nonneg=True),
        sigma_autocorr=g["sigma_autocorr"], min_dof=g["min_dof"],
        converged_rel_sigma=_num(g["converged_rel_sigma"], f"{origin}[general].converged_rel_sigma",
                                 positive=True),
        min_updates_converged=g["min_updates_converged"], steer_form=g["steer_form"], mass_form=g["mass_form"],
        upstream_min_updates=g["upstream_min_updates"], upstream_max_wait=g["upstream_max_wait"],
        moment_form=moment_form, upstream_idle_inputs=idle,
        suspension_max_interval_s=_num(opt.get("suspension_max_interval_s", IdentConfig.suspension_max_interval_s),
                                       f"{origin}[general].suspension_max_interval_s", positive=True),
        status=_status_config(doc.get("status", {}), origin),
        **problems)


def _status_config(t, origin: str) -> StatusConfig:
    """The optional ``[status]`` table (``StatusConfig``; every key optional)."""
    where = f"{origin}[status]"
    if not isinstance(t, dict):
        raise IdentConfigError(f"{where}: expected a table")
    known = {f.name: f.type for f in dataclasses.fields(StatusConfig)}
    unknown = sorted(set(t) - set(known))
    if unknown:
        raise IdentConfigError(f"{where}: unknown key {unknown[0]!r}")
    kw = {}
    for k, v in t.items():
        default = getattr(StatusConfig, k)
        if isinstance(default, bool):
            if not isinstance(v, bool):
                raise IdentConfigError(f"{where}.{k}: expected true or false")
            kw[k] = v
        elif isinstance(default, int):
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise IdentConfigError(f"{where}.{k}: expected a non-negative integer")
            kw[k] = v
        else:
            kw[k] = _num(v, f"{where}.{k}", nonneg=True)
    return StatusConfig(**kw)


def load_ident_config(path: str | Path | None = None) -> IdentConfig:
    """Load ``configs/identification/default.toml`` (or ``path``)."""
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise IdentConfigError(f"cannot read identification config {p}: {e.__class__.__name__}: {e}") from None
    return parse_ident_config(text, str(p))
