"""The four identification problems of section 5.2 (eq 20-23) and the online ``Identifier``.

Model (eq 13-17), aux frame {a} for translation, vehicle frame {v} (x fwd, y left, z up) for
rotation::

    m (xdd_a - yd_a psid_v) = F_x,tire + m G_x                              (eq 13)
    m (ydd_a + xd_a psid_v) = F_y,tire + m G_y
    m zdd_a                 = F_z,spring + m G_z
    I_x wd_x = (I_y - I_z) w_y w_z + M_x
    I_y wd_y = (I_z - I_x) w_z w_x + M_y
    I_z wd_z = (I_x - I_y) w_x w_y + M_z
    I_w wd_i = -r_i F_a,i + T_i                                           (i = 1..4)
    F_z,spring,i = K_s,i H_i + D_s,i Hd_i + m_u,i g,  K_s,i = C1 exp(C2 (H_i - C3))   (eq 14)
    F_a,i = C_lambda,i lambda_i,   F_b,i = C_alpha,i alpha_i                          (eq 15)
    F_x,tire = sum(F_a,i cos d_i - F_b,i sin d_i),  F_y,tire = sum(F_a,i sin d_i + F_b,i cos d_i)
    C_alpha,f = C_alpha,1 + C_alpha,2,  C_alpha,r = C_alpha,3 + C_alpha,4   (equal sides, eq 17)

The four RLS problems ``Q A W W^-1 x = Q b`` (solved by :class:`~.rls.WeightedRLS`):

* **mass** (eq 20): x = [m_tot], A = [zdd_a - G_z], b = sum_i F_z,spring,i (``mass_form =
  "paper"``). ``"sprung"`` uses b = sum_i (K_s,i H_i + D_s,i Hd_i) + sum_i m_u,i (zdd_a - G_z):
  exact for the truth simulator's model (struts carry the sprung mass, the unsprung masses ride
  on the road); eq 20 instead books m_u g, which biases m_tot by about -m_u var(zdd_a)/g^2.
* **tracking** (eq 21): x = [C_lambda,1..4], A = diag(-r_i lambda_i), b_i = I_w wd_i - T_i.
* **cornering** (eq 22): x = [C_alpha,f, C_alpha,r], with the current estimates of m and
  C_lambda (Gauss-Seidel: the problems are updated in the order mass, tracking, cornering,
  inertia, each with the newest estimates of the others; a problem waits until the problems it
  uses have ``upstream_min_updates`` updates, see ``UPSTREAM``)::

      A = [[-(a1 sin d1 + a2 sin d2)/2, -(a3 sin d3 + a4 sin d4)/2],
           [ (a1 cos d1 + a2 cos d2)/2,  (a3 cos d3 + a4 cos d4)/2]]       (steer_form per_wheel)
      A = [[-(a1 + a2)/2 sin((d1 + d2)/2), 0], [(a1 + a2)/2 cos((d1 + d2)/2), (a3 + a4)/2]]
                                                                          (steer_form paper_mean)
      b = [m (xdd_a - yd_a psid_v - G_x) - sum C_lambda,i lambda_i cos d_i,
           m (ydd_a + xd_a psid_v - G_y) - sum C_lambda,i lambda_i sin d_i]

  ``per_wheel`` is eq 16 with C_alpha,1 = C_alpha,2 = C_alpha,f / 2 (eq 17's assumption)
  without replacing each wheel's angle by the mean; both forms are equal when d1 = d2 and
  d3 = d4 = 0. The default is ``per_wheel``; ``paper_mean`` is eq 22 as printed.
* **inertia** (eq 23): x = [I_x, I_y, I_z], b = [M_x, M_y, M_z]::

      A = [[ wd_x,     -w_y w_z,  w_y w_z],
           [ w_z w_x,   wd_y,    -w_z w_x],
           [-w_x w_y,   w_x w_y,  wd_z  ]]

Moments M_x, M_y, M_z (the paper gives them only as "functions of the forces, attitude and
geometry [25]"). We use the physics core's definition (``vdps_hil/model/core.py``, truth
variant ``unsprung_dof=True``), checked against it in ``tests/test_problems.py``: forces on the
sprung body about its CG, vehicle frame, corner i at (x_i, y_i) from ``Geometry.corner_xy_m()``:

* strut force F_s,i = K_s,i H_i + D_s,i Hd_i (eq 14 without m_u g: the unsprung weight acts on
  the wheel, not on the body; with it the static forces would leave a spurious pitch moment
  2 m_u g (l_r - l_f)) acting at (x_i, y_i);
* tire forces in the vehicle frame F_x,i = F_a,i cos d_i - F_b,i sin d_i,
  F_y,i = F_a,i sin d_i + F_b,i cos d_i (eq 16 per wheel, F_a,i = C_lambda,i lambda_i,
  F_b,i = C_alpha,axle/2 alpha_i with the current estimates) acting at the contact point
  (x_i, y_i, -h_cg) (no roll centre in the paper's model);
* the unsprung masses' horizontal weight and inertia u_i = -m_u,i (a - g) at the wheel centre
  (x_i, y_i, z_w,i), z_w,i = -(h_cg - r) + H_i, with (a - g) = (xdd_a - yd_a psid_v - G_x,
  ydd_a + xd_a psid_v - G_y) (the unsprung masses translate with the body)::

      M_x = sum_i ( y_i F_s,i + h_cg F_y,i - z_w,i u_y,i)
      M_y = sum_i (-x_i F_s,i - h_cg F_x,i + z_w,i u_x,i)
      M_z = sum_i ( x_i F_y,i - y_i F_x,i + x_i u_y,i - y_i u_x,i)

  Small-angle: the attitude relative to the road is not used (as eq 13, which writes the
  vehicle-frame forces in the aux frame). ``IdentInputs.moments_nm`` overrides them. This is
  ``moment_form = "stiffness"``.

  ``moment_form = "measured"`` (default in ``configs/identification/default.toml``): the tire
  forces enter M_x and M_y only through their sums, which the accelerometer measures: in body
  axes sum_i F_tire,i = m f_b (f_b the specific force at the CG, body axes; F_tire includes the
  normal loads' components F_z,i n_b, n_b the road normal in body axes, from the estimated
  road-relative roll and pitch)::

      M_x = sum_i y_i F_s,i + (h_cg - H_bar) m f_b,y - r n_b,y sum_i F_z,i + sum_i z_w,i m_u,i f_b,y
      M_y = -sum_i x_i F_s,i - (h_cg - H_bar) m f_b,x + r n_b,x sum_i F_z,i - sum_i z_w,i m_u,i f_b,x
      M_z = as "stiffness" (the yaw moment needs the split between the axles)

  (F_z,i = eq 14's normal load, H_bar the mean deflection, z_w,i = -(h_cg - r) + H_i; the
  physics core's moments to first order in the road-relative angles and the deflections). Why:
  the roll moment is the small difference of two large ones (the struts' y_i F_s,i and the
  tires' h_cg sum F_y): with F_y from C_alpha alpha (eq 15) a 5 % stiffness error or the Magic
  Formula's saturation, and the omitted F_z n_b,y term (body roll over the road tilts the normal
  loads), moved I_x by +16..+40 % on the paper's scenario; with the measured sums and the
  simulator's deflections I_x came to -0.4 % (linear-tire truth). It needs
  ``IdentInputs.specific_force_b_mps2`` and ``vehicle_angles_rad``; without them the stiffness
  form is used.

Symbols and units (every input is an *estimate*: EKF, alpha-beta filters, sensors; never
simulator truth)::

    xdd_a, ydd_a, zdd_a  [m/s^2]  CG acceleration, aux frame
    xd_a, yd_a           [m/s]    CG velocity, aux frame
    psid_v               [rad/s]  vehicle yaw rate relative to the road (aux frame rotation)
    G_x, G_y, G_z        [m/s^2]  gravity in the aux frame, eq 13 (``gravity_aux_mps2``)
    w, wd                [rad/s], [rad/s^2]  body rates and their alpha-beta derivatives
    H_i, Hd_i            [m], [m/s]  suspension deflection from design ride height
                          (compression positive) and rate; spring compression of eq 14 is
                          static_compression_m + H_i (``vdps_hil.conventions``)
    w_i, wd_i            [rad/s], [rad/s^2]  wheel spin and its alpha-beta derivative
    T_i                  [N m]    wheel torque (positive driving)
    lambda_i             [-]      slip ratio (F_a = C_lambda lambda, positive driving)
    alpha_i              [rad]    slip angle (F_b = C_alpha alpha, positive = force to the left)
    d_i                  [rad]    road-wheel angle, positive to the left; rear 0 (front steer)
    r_i, I_w             [m], [kg m^2]   rolling radius, wheel spin inertia (model file)
    m_tot [kg], I_x,y,z [kg m^2], C_lambda,i [N], C_alpha,f/r [N/rad]   the ten parameters

Gating (excitation): a row is used only when max_j |A[i, j]| >= ``excitation_min[i]``; the
tracking, cornering and inertia problems also need |xd_a| >= ``min_speed_mps`` (slip is
undefined at low speed), and a tracking row needs r w_i >= ``min_speed_mps``. At zero slip or
zero steer eq 21-22 are singular: those rows are simply left out (nothing is ever divided).

Misprints of the paper (section 4-5, 8 and the figures) and what we implement
---------------------------------------------------------------------------
1. Eq 23: b_4 = [M_x, M_y, M_x]; the third row is the yaw equation: b_4 = [M_x, M_y, M_z].
2. Eq 23's A matrix: checked entry by entry against eq 13's Euler equations (row 1
   I_x wd_x - I_y w_y w_z + I_z w_y w_z = M_x -> [wd_x, -w_y w_z, w_y w_z]; row 2
   I_x w_z w_x + I_y wd_y - I_z w_z w_x = M_y -> [w_z w_x, wd_y, -w_z w_x]; row 3
   -I_x w_x w_y + I_y w_x w_y + I_z wd_z = M_z -> [-w_x w_y, w_x w_y, wd_z]): **correct as
   printed**, implemented literally.
3. Eq 17: the rear pair is printed F_b,tire,r = F_b,tire,1 + F_b,tire,2; it is
   F_b,tire,3 + F_b,tire,4 ~ C_alpha,r (alpha_3 + alpha_4)/2.
4. Eq 22, b_3: the sums are printed with C_lambda,1; they are sum_i C_lambda,i lambda_i.
5. Eq 22, b_3 row 2 prints m (ydd_a - xd_a psid_v - G_y); eq 13 has m (ydd_a + xd_a psid_v)
   (the centripetal term of a frame rotating at psid_v, consistent with row 1's -yd_a psid_v).
   We follow eq 13: ``+``. (b_3 also drops the subscript a on yd and xd.)
6. Eq 19: the parameter update is printed with ``-`` before P(k+1) A_Q^T [Q b - A_Q x_Q]; it
   must be ``+`` (see ``rls``).
7. Eq 7: the state list "(phi_g, theta_g, psi_g, phi_r, theta 9r, psi_v)" has a stray "9":
   theta_r (also in ``vdps_hil.conventions``).
8. Figures 6-7: "mean values calculated from the 15th second to the 10th second"; section 7.2
   identifies at t = 10.25 s and Figure 4 uses "the 5th second to the 10th second": we take the
   window as 5-10.25 s (issue 6 fixes "mean over 5-10.25 s").
9. Eq 20: b_1 prints K_s H_i without the corner index (K_s,i, as eq 14) and the sum applies to
   all three terms: b_1 = sum_i (K_s,i H_i + D_s,i Hd_i + m_u,i g).
10. Eq 17's approximation C_alpha,f (alpha_1 + alpha_2)/2 holds for C_alpha,1 = C_alpha,2;
    eq 22 additionally replaces each wheel angle by the mean (d1 + d2)/2 (see steer_form).
11. Eq 20 writes K_s H_i^sus with H^sus the sensor's deflection; eq 14's spring law needs the
    compression from the spring's free length: we use H = static_compression_m + H^sus
    (``vdps_hil.conventions``), so b_1 balances m_tot g at rest.
12. Table 3 footnote a: "convergent rate" is a time (reaching 90 % of the real value), not a rate.
13. (Not a misprint, a gap.) Table 3 does not give P(0). With W_4 = I and P(0) = I (config
    ``p0_scaled = 1``) our noise-free inertia runs reproduce its ordering and orders of
    magnitude (q = 0.625: 0.03/0.08/0.13 s to 90 % for I_x/I_y/I_z, paper 0.08/1.63/0.24 s;
    q = 0.005: none within the run, paper "NaN"), see ``tests/test_problems.py``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Callable

import numpy as np

from vdps_hil.identification.rls import BOUNDS_MODES, FORMS, RLSCounters, WeightedRLS
from vdps_hil.model.stages import spring_force_n
from vdps_hil.model.frames import gravity_in_aux
from vdps_hil.model.params import CONFIG_DIR, Geometry, IdentifiedParams, Vehicle
from vdps_hil.units import GRAVITY_MPS2

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
UPSTREAM: dict[str, tuple[str, ...]] = {"mass": (), "tracking": (), "cornering": ("mass", "tracking"),
                                        "inertia": ("tracking", "cornering")}
"""Problems whose estimates enter a problem's b (eq 22: m, C_lambda; eq 23's moments: C_lambda,
C_alpha). A problem waits until each of these has ``upstream_min_updates`` updates (at most
``upstream_max_wait`` calls): rows built from the priors would otherwise stay in its memory
(weight 1/N without forgetting)."""


# --------------------------------------------------------------------------- configuration
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

    def problem(self, name: str) -> ProblemConfig:
        return getattr(self, name)


_GENERAL_KEYS = {"form", "bounds_mode", "bounds_factor", "min_speed_mps", "sigma_autocorr", "min_dof",
                 "converged_rel_sigma", "min_updates_converged", "steer_form", "mass_form", "upstream_min_updates",
                 "upstream_max_wait"}
_PROBLEM_KEYS = {"q", "w", "forgetting", "prior_rel_sigma", "excitation_min"}


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
    _check_keys(doc, {"schema_version", "general", *PROBLEM_NAMES}, origin)
    if doc["schema_version"] != CONFIG_SCHEMA_VERSION:
        raise IdentConfigError(f"{origin}: schema_version {doc['schema_version']!r} is not "
                               f"{CONFIG_SCHEMA_VERSION}")
    g = doc["general"]
    moment_form = g.get("moment_form", "stiffness") if isinstance(g, dict) else "stiffness"
    if isinstance(g, dict):
        g = {k: v for k, v in g.items() if k != "moment_form"}  # optional key
    _check_keys(g, _GENERAL_KEYS, f"{origin}[general]")
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
        _check_keys({k: v for k, v in t.items() if k != "p0_scaled"} if isinstance(t, dict) else t,
                    _PROBLEM_KEYS, where)
        m, n = PROBLEM_ROWS[name], len(PROBLEM_PARAMS[name])
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
            p0_scaled=(_num(t["p0_scaled"], f"{where}.p0_scaled", positive=True) if "p0_scaled" in t else None))
    return IdentConfig(
        form=g["form"], bounds_mode=g["bounds_mode"], bounds_factor=(lo, hi),
        min_speed_mps=_num(g["min_speed_mps"], f"{origin}[general].min_speed_mps", nonneg=True),
        sigma_autocorr=g["sigma_autocorr"], min_dof=g["min_dof"],
        converged_rel_sigma=_num(g["converged_rel_sigma"], f"{origin}[general].converged_rel_sigma",
                                 positive=True),
        min_updates_converged=g["min_updates_converged"], steer_form=g["steer_form"], mass_form=g["mass_form"],
        upstream_min_updates=g["upstream_min_updates"], upstream_max_wait=g["upstream_max_wait"],
        moment_form=moment_form, **problems)


def load_ident_config(path: str | Path | None = None) -> IdentConfig:
    """Load ``configs/identification/default.toml`` (or ``path``)."""
    p = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise IdentConfigError(f"cannot read identification config {p}: {e.__class__.__name__}: {e}") from None
    return parse_ident_config(text, str(p))


# ------------------------------------------------------------------------------- inputs
def _tup(v, n: int, name: str) -> tuple[float, ...]:
    t = tuple(float(e) for e in v)
    if len(t) != n:
        raise ValueError(f"IdentInputs.{name}: expected {n} values, got {len(t)}")
    return t


@dataclass(frozen=True, slots=True)
class IdentInputs:
    """Estimated quantities at one instant (never simulator truth). Units in the names; frames:
    aux {a} for translation, vehicle {v} for rotation; wheels in order FL, FR, RR, RL."""

    t_ns: int
    xdd_a_mps2: float
    ydd_a_mps2: float
    zdd_a_mps2: float
    xd_a_mps: float
    yd_a_mps: float
    psi_v_dot_radps: float
    gravity_aux_mps2: tuple[float, float, float]  # (G_x, G_y, G_z), eq 13
    omega_radps: tuple[float, float, float]  # body rates (w_x, w_y, w_z)
    omega_dot_radps2: tuple[float, float, float]  # alpha-beta derivatives
    susp_deflection_m: tuple[float, float, float, float]  # H_i, compression positive
    susp_rate_mps: tuple[float, float, float, float]  # Hd_i
    wheel_speed_radps: tuple[float, float, float, float]
    wheel_accel_radps2: tuple[float, float, float, float]
    wheel_torque_nm: tuple[float, float, float, float]
    slip_ratio: tuple[float, float, float, float]
    slip_angle_rad: tuple[float, float, float, float]
    wheel_angle_rad: tuple[float, float, float, float]  # delta_i (rear 0 for front steer)
    moments_nm: tuple[float, float, float] | None = None  # override of (M_x, M_y, M_z)
    specific_force_b_mps2: tuple[float, float, float] | None = None  # f at the CG, body axes ("measured")
    vehicle_angles_rad: tuple[float, float] | None = None  # road-relative (phi_v, theta_v), eq 4

    def __post_init__(self):
        if not isinstance(self.t_ns, int) or isinstance(self.t_ns, bool):
            raise TypeError(f"IdentInputs.t_ns must be int nanoseconds, got {type(self.t_ns).__name__}")
        for name, n in (("gravity_aux_mps2", 3), ("omega_radps", 3), ("omega_dot_radps2", 3),
                        ("susp_deflection_m", 4), ("susp_rate_mps", 4), ("wheel_speed_radps", 4),
                        ("wheel_accel_radps2", 4), ("wheel_torque_nm", 4), ("slip_ratio", 4),
                        ("slip_angle_rad", 4), ("wheel_angle_rad", 4)):
            object.__setattr__(self, name, _tup(getattr(self, name), n, name))
        if self.moments_nm is not None:
            object.__setattr__(self, "moments_nm", _tup(self.moments_nm, 3, "moments_nm"))
        if self.specific_force_b_mps2 is not None:
            object.__setattr__(self, "specific_force_b_mps2", _tup(self.specific_force_b_mps2, 3,
                                                                   "specific_force_b_mps2"))
        if self.vehicle_angles_rad is not None:
            object.__setattr__(self, "vehicle_angles_rad", _tup(self.vehicle_angles_rad, 2, "vehicle_angles_rad"))


def gravity_aux_mps2(phi_r_rad: float, theta_r_rad: float, psi_v_rad: float) -> tuple[float, float, float]:
    """(G_x, G_y, G_z) of eq 13 from the *estimated* road bank, grade and vehicle yaw."""
    g = gravity_in_aux(phi_r_rad, theta_r_rad, psi_v_rad, GRAVITY_MPS2)
    return float(g[0]), float(g[1]), float(g[2])


# ------------------------------------------------------------------- forces and moments
def spring_compression_m(vehicle: Vehicle, susp_deflection_m) -> np.ndarray:
    """H of eq 14 (compression from the spring's free length) = static + deflection [m]."""
    static = np.array([vehicle.axle(i).static_compression_m for i in range(4)])
    return static + np.asarray(susp_deflection_m, dtype=float)


def suspension_forces_n(vehicle: Vehicle, susp_deflection_m, susp_rate_mps,
                        include_unsprung_weight: bool = True) -> np.ndarray:
    """Per corner [N], the spring law of eq 14 (``model.stages.spring_force_n``):

    * with the unsprung weight: F_z,spring,i = K_s H + D_s Hd + m_u g, the normal load of the
      paper's reduced model, with eq 14's clamp as the physics core applies it (lift-off when
      K_s H + m_u g <= 0, and never negative);
    * without: the strut force K_s H + D_s Hd acting on the sprung body (no clamp: tension past
      the free length stands in for the rebound stop, as in the core)."""
    h = spring_compression_m(vehicle, susp_deflection_m)
    hd = np.asarray(susp_rate_mps, dtype=float)
    out = np.empty(4)
    for i in range(4):
        ax = vehicle.axle(i)
        hs = float(h[i])
        if not (math.isfinite(hs) and math.isfinite(hd[i])):
            out[i] = math.nan
            continue
        fsp = spring_force_n(min(hs, 10.0), ax.spring_c1_npm, ax.spring_c2_per_m, ax.spring_c3_m)
        if not include_unsprung_weight:
            out[i] = fsp + ax.damper_nspm * hd[i]
            continue
        mug = ax.unsprung_mass_kg * GRAVITY_MPS2
        out[i] = 0.0 if fsp + mug <= 0.0 else max(fsp + ax.damper_nspm * hd[i] + mug, 0.0)
    return out


def tire_forces_wheel_n(slip_ratio, slip_angle_rad, params: IdentifiedParams) -> tuple[np.ndarray, np.ndarray]:
    """Eq 15 with eq 17's equal sides: F_a,i = C_lambda,i lambda_i, F_b,i = C_alpha,axle/2
    alpha_i [N], wheel frame (a forward along the wheel, b to its left)."""
    c_l = np.array(params.tracking_stiffness_n)
    c_a = np.array([params.cornering_stiffness_front_nprad, params.cornering_stiffness_front_nprad,
                    params.cornering_stiffness_rear_nprad, params.cornering_stiffness_rear_nprad]) / 2.0
    return c_l * np.asarray(slip_ratio, dtype=float), c_a * np.asarray(slip_angle_rad, dtype=float)


def tire_forces_body_n(f_a_n, f_b_n, wheel_angle_rad) -> tuple[np.ndarray, np.ndarray]:
    """Eq 16 per wheel: wheel-frame forces rotated by the wheel angle into the vehicle frame."""
    d = np.asarray(wheel_angle_rad, dtype=float)
    fa, fb = np.asarray(f_a_n, dtype=float), np.asarray(f_b_n, dtype=float)
    c, s = np.cos(d), np.sin(d)
    return fa * c - fb * s, fa * s + fb * c


def body_moments_nm(geometry: Geometry, f_susp_body_n, f_x_n, f_y_n) -> np.ndarray:
    """(M_x, M_y, M_z) about the CG, vehicle frame, of the strut and tire forces:
    sum_i r_i x F_i with r_i = (x_i, y_i, -h_cg) and F_i = (F_x,i, F_y,i, F_s,i)."""
    xy = np.array(geometry.corner_xy_m())
    x, y, h = xy[:, 0], xy[:, 1], geometry.h_cg_m
    fs, fx, fy = (np.asarray(v, dtype=float) for v in (f_susp_body_n, f_x_n, f_y_n))
    return np.array([np.sum(y * fs + h * fy), np.sum(-x * fs - h * fx), np.sum(x * fy - y * fx)])


def unsprung_inertia_moments_nm(vehicle: Vehicle, inp: IdentInputs) -> np.ndarray:
    """(M_x, M_y, M_z) of the unsprung masses' horizontal weight and inertia (d'Alembert force
    m_u,i (g - a) at the wheel centre r_w,i = (x_i, y_i, -(h_cg - r) + H_i)), as the physics
    core applies them to the sprung body. a - g in the aux frame is (xdd_a - yd_a psid_v - G_x,
    ydd_a + xd_a psid_v - G_y) (eq 13's left-hand sides over m)."""
    geo = vehicle.geometry
    xy = np.array(geo.corner_xy_m())
    mu = np.array([vehicle.axle(i).unsprung_mass_kg for i in range(4)])
    zw = -(geo.h_cg_m - vehicle.tire.rolling_radius_m) + np.asarray(inp.susp_deflection_m, dtype=float)
    psid = inp.psi_v_dot_radps
    ux = -mu * (inp.xdd_a_mps2 - inp.yd_a_mps * psid - inp.gravity_aux_mps2[0])
    uy = -mu * (inp.ydd_a_mps2 + inp.xd_a_mps * psid - inp.gravity_aux_mps2[1])
    return np.array([np.sum(-zw * uy), np.sum(zw * ux), np.sum(xy[:, 0] * uy - xy[:, 1] * ux)])


def moments_from_inputs(vehicle: Vehicle, params: IdentifiedParams, inp: IdentInputs,
                        form: str = "stiffness") -> np.ndarray:
    """b_4 of eq 23: strut forces (eq 14), tire forces (eq 15-17 with ``params``) and the
    unsprung masses' horizontal weight and inertia; ``form = "measured"`` takes M_x, M_y from
    the measured specific force (module docstring) when the inputs carry it."""
    if inp.moments_nm is not None:
        return np.array(inp.moments_nm)
    fs = suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps, include_unsprung_weight=False)
    fa, fb = tire_forces_wheel_n(inp.slip_ratio, inp.slip_angle_rad, params)
    fx, fy = tire_forces_body_n(fa, fb, inp.wheel_angle_rad)
    m = body_moments_nm(vehicle.geometry, fs, fx, fy) + unsprung_inertia_moments_nm(vehicle, inp)
    if form == "measured" and inp.specific_force_b_mps2 is not None and inp.vehicle_angles_rad is not None:
        m[0], m[1] = measured_roll_pitch_moments_nm(vehicle, params.mass_kg, inp, fs)
    return m


def road_normal_body(phi_v_rad: float, theta_v_rad: float) -> np.ndarray:
    """n_b = C_r^v e_z: the road normal in body axes from the road-relative roll and pitch
    (eq 3-4 with psi_v = 0; body parallel to the road: (0, 0, 1))."""
    sp, cp, st, ct = math.sin(phi_v_rad), math.cos(phi_v_rad), math.sin(theta_v_rad), math.cos(theta_v_rad)
    return np.array([st, sp * ct, cp * ct])


def measured_roll_pitch_moments_nm(vehicle: Vehicle, mass_kg: float, inp: IdentInputs, strut_n=None
                                   ) -> tuple[float, float]:
    """(M_x, M_y) of the ``"measured"`` moment form (module docstring) [N m]."""
    geo = vehicle.geometry
    xy = np.array(geo.corner_xy_m())
    h, r = geo.h_cg_m, vehicle.tire.rolling_radius_m
    fs = (suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps, include_unsprung_weight=False)
          if strut_n is None else np.asarray(strut_n, dtype=float))
    fz = float(np.sum(suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps)))
    hh = np.asarray(inp.susp_deflection_m, dtype=float)
    mu = np.array([vehicle.axle(i).unsprung_mass_kg for i in range(4)])
    zw = -(h - r) + hh
    n = road_normal_body(*inp.vehicle_angles_rad)
    f = inp.specific_force_b_mps2
    lever = h - float(np.mean(hh))
    mx = float(np.sum(xy[:, 1] * fs) + lever * mass_kg * f[1] - r * n[1] * fz + np.sum(zw * mu) * f[1])
    my = float(-np.sum(xy[:, 0] * fs) - lever * mass_kg * f[0] + r * n[0] * fz - np.sum(zw * mu) * f[0])
    return mx, my


# --------------------------------------------------------------------------- regressors
@dataclass(frozen=True)
class Regressor:
    """A_rls (m x n, physical), b (m), the rows that are excited (m booleans) and, for problems
    whose b uses other problems' estimates, db/dtheta (m x p) over the upstream parameters in
    ``upstream_param_names(problem)`` order (for the consider covariance)."""

    a: np.ndarray
    b: np.ndarray
    rows: np.ndarray
    db_dup: np.ndarray | None = None


def _gate(a: np.ndarray, thresholds, moving=True) -> np.ndarray:
    """Rows whose largest |entry| reaches the threshold. Non-finite rows pass, so the RLS NaN
    guard leaves them out *and counts them*."""
    with np.errstate(invalid="ignore"):
        mag = np.max(np.abs(a), axis=1)
        return ((mag >= np.asarray(thresholds)) | ~np.isfinite(mag)) & moving


def mass_regressor(inp: IdentInputs, vehicle: Vehicle, cfg: IdentConfig) -> Regressor:
    """Eq 20: A = [zdd_a - G_z], b = sum_i F_z,spring,i (``mass_form = "paper"``), or
    b = sum_i (K_s H + D_s Hd) + sum_i m_u,i (zdd_a - G_z) (``"sprung"``: the struts carry the
    sprung mass, the unsprung masses follow the road and weigh on the tires directly)."""
    a = np.array([[inp.zdd_a_mps2 - inp.gravity_aux_mps2[2]]])
    if cfg.mass_form == "paper":
        b = np.array([np.sum(suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps))])
    else:
        struts = suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps, include_unsprung_weight=False)
        b = np.array([np.sum(struts) + vehicle.unsprung_mass_total_kg * a[0, 0]])
    return Regressor(a, b, _gate(a, cfg.mass.excitation_min))


def tracking_regressor(inp: IdentInputs, vehicle: Vehicle, cfg: IdentConfig) -> Regressor:
    """Eq 21: A = diag(-r lambda_i), b_i = I_w wd_i - T_i."""
    r, iw = vehicle.tire.rolling_radius_m, vehicle.tire.wheel_inertia_kgm2
    lam = np.asarray(inp.slip_ratio)
    a = np.diag(-r * lam)
    b = iw * np.asarray(inp.wheel_accel_radps2) - np.asarray(inp.wheel_torque_nm)
    with np.errstate(invalid="ignore"):
        moving = ((abs(inp.xd_a_mps) >= cfg.min_speed_mps)
                  & (r * np.asarray(inp.wheel_speed_radps) >= cfg.min_speed_mps))
    return Regressor(a, b, _gate(a, cfg.tracking.excitation_min, moving))


def cornering_regressor(inp: IdentInputs, vehicle: Vehicle, params: IdentifiedParams,
                        cfg: IdentConfig) -> Regressor:
    """Eq 22 with the current mass and tracking stiffness estimates in ``params``."""
    al = np.asarray(inp.slip_angle_rad)
    d = np.asarray(inp.wheel_angle_rad)
    if cfg.steer_form == "per_wheel":
        s, c = al * np.sin(d), al * np.cos(d)
        a = np.array([[-(s[0] + s[1]) / 2.0, -(s[2] + s[3]) / 2.0],
                      [(c[0] + c[1]) / 2.0, (c[2] + c[3]) / 2.0]])
    else:  # eq 22 as printed
        af, ar, df = (al[0] + al[1]) / 2.0, (al[2] + al[3]) / 2.0, (d[0] + d[1]) / 2.0
        a = np.array([[-af * math.sin(df), 0.0], [af * math.cos(df), ar]])
    fa = np.array(params.tracking_stiffness_n) * np.asarray(inp.slip_ratio)
    m, g = params.mass_kg, inp.gravity_aux_mps2
    psid = inp.psi_v_dot_radps
    acc = np.array([inp.xdd_a_mps2 - inp.yd_a_mps * psid - g[0], inp.ydd_a_mps2 + inp.xd_a_mps * psid - g[1]])
    b = m * acc - np.array([np.sum(fa * np.cos(d)), np.sum(fa * np.sin(d))])
    lam = np.asarray(inp.slip_ratio)
    db = np.column_stack([acc, -np.vstack([lam * np.cos(d), lam * np.sin(d)])])  # d/d[m, C_lambda,1..4]
    return Regressor(a, b, _gate(a, cfg.cornering.excitation_min, abs(inp.xd_a_mps) >= cfg.min_speed_mps), db)


def inertia_regressor(inp: IdentInputs, vehicle: Vehicle, params: IdentifiedParams,
                      cfg: IdentConfig) -> Regressor:
    """Eq 23 (A as printed, b_4 = [M_x, M_y, M_z]) with the moments of ``moments_from_inputs``."""
    wx, wy, wz = inp.omega_radps
    dx, dy, dz = inp.omega_dot_radps2
    a = np.array([[dx, -wy * wz, wy * wz],
                  [wz * wx, dy, -wz * wx],
                  [-wx * wy, wx * wy, dz]])
    b = moments_from_inputs(vehicle, params, inp, cfg.moment_form)
    db = np.zeros((3, 6)) if inp.moments_nm is not None else _moment_sensitivity(vehicle.geometry, inp)
    if (cfg.moment_form == "measured" and inp.specific_force_b_mps2 is not None
            and inp.vehicle_angles_rad is not None):
        db[:2, :] = 0.0  # M_x, M_y no longer use the tire stiffnesses
    return Regressor(a, b, _gate(a, cfg.inertia.excitation_min, abs(inp.xd_a_mps) >= cfg.min_speed_mps), db)


def _moment_sensitivity(geometry: Geometry, inp: IdentInputs) -> np.ndarray:
    """d(M_x, M_y, M_z)/d(C_lambda,1..4, C_alpha,f, C_alpha,r): the moments are linear in the
    tire stiffnesses; dM/dF_x,i = (0, -h, -y_i), dM/dF_y,i = (h, 0, x_i)."""
    xy = np.array(geometry.corner_xy_m())
    h = geometry.h_cg_m
    d = np.asarray(inp.wheel_angle_rad)
    lam, al = np.asarray(inp.slip_ratio), np.asarray(inp.slip_angle_rad)
    dm_dfx = np.stack([np.zeros(4), np.full(4, -h), -xy[:, 1]])  # 3 x 4
    dm_dfy = np.stack([np.full(4, h), np.zeros(4), xy[:, 0]])
    c, s = np.cos(d), np.sin(d)
    out = np.zeros((3, 6))
    out[:, :4] = dm_dfx * (lam * c) + dm_dfy * (lam * s)
    per_wheel = dm_dfx * (-al * s / 2.0) + dm_dfy * (al * c / 2.0)
    out[:, 4] = per_wheel[:, 0] + per_wheel[:, 1]
    out[:, 5] = per_wheel[:, 2] + per_wheel[:, 3]
    return out


RegressorBuilder = Callable[[IdentInputs, Vehicle, IdentifiedParams, IdentConfig], Regressor]

REGRESSORS: dict[str, RegressorBuilder] = {
    "mass": lambda inp, v, p, c: mass_regressor(inp, v, c),
    "tracking": lambda inp, v, p, c: tracking_regressor(inp, v, c),
    "cornering": cornering_regressor,
    "inertia": inertia_regressor,
}
"""Problem name -> regressor builder (inputs, model vehicle, current params, config)."""


def balanced_weighting(row_rms, total: float | None = None) -> np.ndarray:
    """A diagonal Q that balances the rows (paper section 8, Table 3): Q_ii proportional to
    1 / rms(row i of A), normalised so that sum Q_ii^2 = ``total`` (default: the number of
    rows, i.e. the same sum as Q = I). For a diagonally dominant A this maximises the minimum
    eigenvalue of sum A^T Q^T Q A for a fixed sum Q_ii^2."""
    r = np.asarray(row_rms, dtype=float)
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise ValueError("row rms values must be finite and positive")
    q = 1.0 / r
    tot = float(len(r)) if total is None else float(total)
    return q * math.sqrt(tot / float(np.sum(q * q)))


# --------------------------------------------------------------------------- identifier
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
        self._rls = {name: self._make(name) for name in PROBLEM_NAMES}
        self._excited = {name: False for name in PROBLEM_NAMES}
        self._waiting = {name: 0 for name in PROBLEM_NAMES}
        self._ready = {name: False for name in PROBLEM_NAMES}
        self._inputs_rejected = 0
        self._last_t_ns: int | None = None
        self._params = self._collect()

    def _make(self, name: str) -> WeightedRLS:
        pc = self.config.problem(name)
        names = PROBLEM_PARAMS[name]
        prior = np.array([getattr(self._prior, n) for n in names])
        x0 = np.array([getattr(self._start, n) for n in names])
        lo, hi = self.config.bounds_factor
        w = np.abs(prior) if pc.w is None else np.array(pc.w)
        sigma0 = pc.prior_rel_sigma * np.abs(prior) if pc.p0_scaled is None else math.sqrt(pc.p0_scaled) * w
        return WeightedRLS(
            x0, sigma0, pc.q, w,
            forgetting=pc.forgetting, lower=lo * prior, upper=hi * prior,
            bounds_mode=self.config.bounds_mode, form=self.config.form,
            sigma_autocorr=self.config.sigma_autocorr, min_dof=self.config.min_dof, names=names)

    def _collect(self) -> IdentifiedParams:
        vals = {}
        for name, rls in self._rls.items():
            vals.update(zip(PROBLEM_PARAMS[name], (float(v) for v in rls.x)))
        return replace(self._prior, **vals)

    def update(self, inputs: IdentInputs) -> None:
        """Feed one set of estimates; each problem updates if excited (mass, tracking,
        cornering, inertia, in that order, each with the newest estimates of the others)."""
        if not isinstance(inputs, IdentInputs):
            raise TypeError(f"Identifier.update needs IdentInputs, got {type(inputs).__name__}")
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
            self._excited[name] = self._rls[name].update(reg.a, reg.b, reg.rows, db_dtheta=reg.db_dup)
            if self._excited[name]:
                self._params = self._collect()

    def _upstream_ready(self, name: str) -> bool:
        """Ready when every upstream problem has ``upstream_min_updates`` updates, or after
        ``upstream_max_wait`` calls (an upstream problem that is never excited, e.g. the
        tracking stiffness of a wheel that never slips, contributes ~ C lambda ~ 0 to b anyway).
        Once ready a problem stays ready until a reset."""
        if self._ready[name]:
            return True
        if (all(self._rls[up].counters.updates >= self.config.upstream_min_updates for up in UPSTREAM[name])
                or self._waiting[name] >= self.config.upstream_max_wait):
            self._ready[name] = True
        return self._ready[name]

    def reset(self, problem: str | None = None, start: IdentifiedParams | None = None) -> None:
        """Back to the starting values (or ``start``) for one problem or all."""
        if start is not None:
            self._start = start
        for name in PROBLEM_NAMES if problem is None else (problem,):
            if name not in self._rls:
                raise KeyError(f"unknown problem {name!r}; one of {PROBLEM_NAMES}")
            self._rls[name].reset(np.array([getattr(self._start, n) for n in PROBLEM_PARAMS[name]]))
            self._excited[name] = False
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

    @property
    def covariances(self) -> dict[str, np.ndarray]:
        """Problem -> covariance of its parameters (physical units): the RLS's own
        (``parameter_covariance``) plus the consider covariance of the upstream estimates it
        used (block-diagonal over the upstream problems, cascaded in update order)."""
        out: dict[str, np.ndarray] = {}
        for name in PROBLEM_NAMES:
            rls = self._rls[name]
            c = rls.parameter_covariance
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
        """Parameter field name -> standard deviation (same unit as the parameter), including
        the uncertainty inherited from the upstream problems (``covariances``)."""
        out = {}
        for name, c in self.covariances.items():
            out.update(zip(PROBLEM_PARAMS[name], (math.sqrt(max(float(v), 0.0)) for v in np.diag(c))))
        return out

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
    def converged(self) -> dict[str, bool]:
        """Problem -> every sigma/|x| (``sigmas``, upstream included) below
        ``converged_rel_sigma`` after enough updates."""
        out = {}
        sig = self.sigmas
        for name, rls in self._rls.items():
            rel = np.array([sig[n] for n in PROBLEM_PARAMS[name]]) / np.maximum(np.abs(rls.x), 1e-300)
            out[name] = bool(rls.counters.updates >= self.config.min_updates_converged
                             and np.all(rel < self.config.converged_rel_sigma))
        return out

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
            "identifiability": self.identifiability,
            "excited": self.excited,
            "converged": self.converged,
            "counters": {n: {f.name: getattr(c, f.name) for f in fields(c)} for n, c in self.counters.items()},
            "waiting_upstream": self.waiting_upstream,
            "inputs_rejected": self._inputs_rejected,
        }

