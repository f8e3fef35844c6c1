"""The four identification problems of section 5.2 (eq 20-23): their regressors (the online
``identifier.Identifier`` runs them).

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
  "paper"``). ``"sprung"`` (the default) uses b = sum_i (K_s,i H_i + D_s,i Hd_i) +
  sum_i m_u,i (zdd_a - G_z): exact for the truth simulator's model (struts carry the sprung mass,
  the unsprung masses ride on the road). Eq 20 instead books m_u g; with the feeder's
  A = f_z (the specific force along the struts, body z: ``feeder``), which falls below g in a
  corner (the body rolls outwards: f_z = g cos phi - a_y sin phi), it gives m_tot + m_u (g - A)/A:
  on CommonRoad set 1's ramped circle +0.37 % (A 9.05 m/s^2 at 7.7 m/s^2 lateral), +0.09 % on its
  lane change, against sigmas below 0.1 % (issue 17; ``"sprung"``: within 0.01 %).
  The regressor also carries the strut-axis term (``Regressor.structure``): eq 20 balances the
  struts along the body z axis, as the physics core does (its wheels move along the body z axis,
  so a pitched body's struts take the tires' body-z share); a model whose struts stay normal to
  the road in pitch (CommonRoad's multibody: its vertical balance has no pitch) needs
  A + theta_v f_x instead, i.e. b carries m_s theta_v f_x more (+0.2..+0.3 % of m_tot on its
  accelerate/brake drives; a real car's anti-dive/anti-squat linkage adds a term of this kind).
  The identifier does not guess the axis: it reports the least-squares bias this term would
  cause as a model-structure share of the mass sigma (``identifier``).
* **tracking** (eq 21): x = [C_lambda,1..4], A = diag(-r_i lambda_i), b_i = I_w wd_i - T_i.
* **cornering** (eq 22): x = [C_alpha,f, C_alpha,r], with the current estimates of m and
  C_lambda (Gauss-Seidel: the problems are updated in the order mass, tracking, cornering,
  inertia, each with the newest estimates of the others; a problem waits until the problems it
  uses have ``upstream_min_updates`` updates, see ``config.UPSTREAM``)::

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

Moments M_x, M_y, M_z of b_4 (the paper gives them only as "functions of the forces, attitude and
geometry [25]"): the physics core's definition, in the ``"stiffness"`` and ``"measured"``
``moment_form``; see the ``forces`` module docstring.

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
from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import numpy as np

from vdps_hil.identification.config import IdentConfig
from vdps_hil.identification.forces import (corner_xy_array, moments_from_inputs, road_normal_body, sum_from_zero,
                                            roll_centre_heights_m, slip_angles_rad, unsprung_inertia_moments_nm)
from vdps_hil.model.spring_law import suspension_forces_n
from vdps_hil.identification.inputs import IdentInputs
from vdps_hil.model.params import IdentifiedParams, Vehicle


@dataclass(frozen=True)
class Regressor:
    """A_rls (m x n, physical), b (m), the rows that are excited (m booleans) and, for problems
    whose b uses other problems' estimates, db/dtheta (m x p) over the upstream parameters in
    ``Identifier.upstream_param_names(problem)`` order (for the consider covariance)."""

    a: np.ndarray
    b: np.ndarray
    rows: np.ndarray
    db_dup: np.ndarray | None = None
    gated: str | None = None  # the excitation gate that refused every row (counted by the identifier)
    structure: np.ndarray | None = None  # per row: an unmodelled term of b the fit cannot tell (N; identifier)
    row_gates: dict | None = None  # validity gate -> rows it refused in this input (counted by the identifier)

    @cached_property
    def used(self) -> tuple[bool, ...]:
        """Per row: excited (``rows``) with A's row and b finite: the rows the RLS uses (its NaN
        guard), which the identifier's statistics follow (made once)."""
        return tuple(u and math.isfinite(b) and all(map(math.isfinite, row))
                     for u, b, row in zip(np.asarray(self.rows, dtype=bool).tolist(),
                                          np.asarray(self.b, dtype=float).tolist(),
                                          np.asarray(self.a, dtype=float).tolist(), strict=True))


def _gate(a, thresholds, moving=True) -> np.ndarray:
    """Rows (of an array or a list of lists) whose largest |entry| reaches the threshold, and
    ``moving`` (one bool, or one per row). Non-finite rows pass, so the RLS NaN
    guard leaves them out *and counts them*. (Per row in Python: these are 1-4 rows of 1-3
    entries, where numpy's reductions cost more than the arithmetic.)"""
    out = []
    for row, thr in zip(a.tolist() if isinstance(a, np.ndarray) else a, thresholds, strict=True):
        mag = 0.0
        for v in row:
            v = abs(v)
            if not v <= math.inf:  # NaN: the row passes (np.max propagates it)
                mag = math.inf
                break
            if v > mag:
                mag = v
        out.append(mag >= thr)
    if isinstance(moving, (list, tuple, np.ndarray)):  # per row; else one bool (numpy's & with it: 1-2 us)
        return np.array([g and bool(m) for g, m in zip(out, moving, strict=True)], dtype=bool)
    return np.array(out, dtype=bool) if moving else np.zeros(len(out), dtype=bool)


def mass_regressor(inp: IdentInputs, vehicle: Vehicle, cfg: IdentConfig,
                   params: IdentifiedParams | None = None) -> Regressor:
    """Eq 20: A = [zdd_a - G_z], b = sum_i F_z,spring,i (``mass_form = "paper"``), or
    b = sum_i (K_s H + D_s Hd) + sum_i m_u,i (zdd_a - G_z) (``"sprung"``: the struts carry the
    sprung mass, the unsprung masses follow the road and weigh on the tires directly).
    ``structure`` = m_s theta_v f_x [N] (the strut-axis term, module docstring; m_s = the current
    m_tot estimate of ``params`` (default the prior) less the unsprung masses), None without the
    specific force or the vehicle angles."""
    a = np.array([[inp.zdd_a_mps2 - inp.gravity_aux_mps2[2]]])
    if cfg.mass_form == "paper":
        b = np.array([suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps).sum()])
    else:
        struts = suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps, include_unsprung_weight=False)
        b = np.array([sum_from_zero(struts) + vehicle.unsprung_mass_total_kg * a[0, 0]])
    structure = None
    if inp.specific_force_b_mps2 is not None and inp.vehicle_angles_rad is not None:
        m_s = (params or vehicle.params).mass_kg - vehicle.unsprung_mass_total_kg
        structure = np.array([m_s * inp.vehicle_angles_rad[1] * inp.specific_force_b_mps2[0]])
    return Regressor(a, b, _gate(a, cfg.mass.excitation_min), structure=structure)


SUSPENSION_GATE = "suspension too slow"
"""The row gate of ``suspension_gate`` (counted by the identifier, named in the reports)."""


def suspension_stale(inp: IdentInputs, cfg: IdentConfig) -> bool:
    """The suspension deflections are older than ``cfg.suspension_max_interval_s`` (or missing:
    inf); inputs built by hand (``susp_interval_s`` None) are never stale."""
    dt = inp.susp_interval_s
    return dt is not None and dt > cfg.suspension_max_interval_s


def suspension_gate(inp: IdentInputs, cfg: IdentConfig, rows: np.ndarray, strut_rows) -> tuple[np.ndarray, dict | None]:
    """Refuse the rows whose b holds strut forces (eq 14: K_s H + D_s Hd; ``strut_rows``) when
    the suspension deflections are older than ``cfg.suspension_max_interval_s``
    (``inp.susp_interval_s``: the longer of the last sampling interval and the newest sample's
    age). Returns (rows, {SUSPENSION_GATE: refused} or None). Used by eq 23's roll and pitch rows;
    eq 20's mass row is not gated: its A (about g) and b are the static weight, which a held
    deflection carries (its dynamic share averages out over a drive).

    Why: the strut forces must follow the body's heave, pitch and roll (about 1-2 Hz), and their
    damper share needs the deflection rate. Sampled every T, a deflection is up to T old and its
    rate, differenced over T, lags by about T/2: phases of 2 pi f T and pi f T at frequency f, at
    2 Hz 0.25 and 0.13 rad (14 and 7 deg) for T = 0.02 s, growing in proportion beyond it. The
    paper's Table 1 prints the suspension at 1 Hz (profile ``table1``): each sample restarts the
    alpha-beta filter (its gap limit), the rate is 0, the deflection a held value up to 1 s old,
    and the inertia problem ended with I_x and I_y on their bounds even on noise-free sensors
    (-59 %, -79 %) from rows it should not have used. ``None`` (inputs built by hand) is not
    gated."""
    if not suspension_stale(inp, cfg):
        return rows, None
    if not all(math.isfinite(h) for h in inp.susp_deflection_m):
        return rows, None  # no suspension at all: NaN rows, which the RLS leaves out and counts
    out = rows.copy()
    idx = list(strut_rows)
    n = int(np.count_nonzero(out[idx]))
    out[idx] = False
    return out, ({SUSPENSION_GATE: n} if n else None)


def tracking_regressor(inp: IdentInputs, vehicle: Vehicle, cfg: IdentConfig,
                       params: IdentifiedParams | None = None) -> Regressor:
    """Eq 21: A = diag(-r lambda_i), b_i = I_w wd_i - T_i, with the optional load gate
    (``[tracking] load_band``: rows with |F_z,i / F_z0,i - 1| above it are refused, counted as
    "load transfer"). ``structure`` (the load-transfer term, ``load_ratio``): a tire whose slope
    grows with its load, C_lambda,i F_z,i / F_z0,i, puts A_ii C_lambda,i (F_z,i / F_z0,i - 1) more
    into b_i; C_lambda,i the current estimate in ``params`` (default the prior)."""
    r, iw, v_min = vehicle.tire.rolling_radius_m, vehicle.tire.wheel_inertia_kgm2, cfg.min_speed_mps
    ra = [-r * lam for lam in inp.slip_ratio]  # per wheel in floats (the elementwise numpy's operations)
    a = np.diag(ra)
    b = np.array([iw * acc - t for acc, t in zip(inp.wheel_accel_radps2, inp.wheel_torque_nm, strict=True)])
    fast = abs(inp.xd_a_mps) >= v_min
    rows = _gate([[v] for v in ra], cfg.tracking.excitation_min,  # A's rows: 0 but the diagonal
                 [fast and r * w >= v_min for w in inp.wheel_speed_radps])
    dev = [v - 1.0 for v in load_ratio(inp, vehicle).tolist()]
    structure = np.array([x * c * e for x, c, e in zip(ra, (params or vehicle.params).tracking_stiffness_n, dev,
                                                       strict=True)])
    band = cfg.tracking.load_band
    off = [abs(e) > band for e in dev] if math.isfinite(band) else [False] * 4
    rows = rows.tolist()
    refused = sum(1 for u, o in zip(rows, off) if u and o)
    return Regressor(a, b, np.array([u and not o for u, o in zip(rows, off)]), structure=structure,
                     row_gates={"load transfer": refused} if refused else None)


def load_ratio(inp: IdentInputs, vehicle: Vehicle) -> np.ndarray:
    """F_z,i / F_z0,i per wheel: F_z,i = K_s H + D_s Hd + m_u g, the eq 14 normal load from the
    estimated deflections (``model.spring_law``), F_z0,i its value at the design ride height (the
    static load); NaN where not finite.

    Why it matters to eq 21 (issue 17, ident session): a tire's slip stiffness grows with its load
    (the Magic Formula's K_x = p_kx1 F_z, linear in it), so C_lambda,i is a figure at one load, the
    static one, while a wheel is excited exactly when it drives or brakes, i.e. under load
    transfer of one sign. On a CommonRoad sine with in-phase acceleration (set 1, tuning seed 101)
    the driven front-left wheel carried 0.75 of its static load on the rows it was excited on and
    its estimate came out -42 %: the truth's F_x against kappa -42 %, the pure-slip Magic Formula at
    those loads -41 %; combined slip and the estimated slip ratio add 1-3 %. The model cannot tell
    whether a car's tire scales so (ours, a linear tire, does not), so the term is reported in the
    sigma (``identifier._structure_bias``); ``load_band`` would refuse the rows instead."""
    fz = suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps)
    fz0 = suspension_forces_n(vehicle, (0.0,) * 4, (0.0,) * 4)
    loads, static = fz.tolist(), fz0.tolist()
    if 0.0 in static:  # a corner without static load: numpy's inf / NaN
        with np.errstate(invalid="ignore", divide="ignore"):
            return fz / fz0
    return np.array([f / f0 for f, f0 in zip(loads, static)])


def cornering_regressor(inp: IdentInputs, vehicle: Vehicle, params: IdentifiedParams,
                        cfg: IdentConfig) -> Regressor:
    """Eq 22 with the current mass and tracking stiffness estimates in ``params``."""
    # per wheel in plain floats: the elementwise numpy's operations, sums from 0.0 in wheel order
    al = slip_angles_rad(vehicle, inp)
    d, lam = inp.wheel_angle_rad, inp.slip_ratio
    cos_d, sin_d = [math.cos(v) for v in d], [math.sin(v) for v in d]
    if cfg.steer_form == "per_wheel":
        s, c = [v * w for v, w in zip(al.tolist(), sin_d)], [v * w for v, w in zip(al.tolist(), cos_d)]
        a = np.array([[-(s[0] + s[1]) / 2.0, -(s[2] + s[3]) / 2.0],
                      [(c[0] + c[1]) / 2.0, (c[2] + c[3]) / 2.0]])
    else:  # eq 22 as printed
        af, ar, df = (al[0] + al[1]) / 2.0, (al[2] + al[3]) / 2.0, (d[0] + d[1]) / 2.0
        a = np.array([[-af * math.sin(df), 0.0], [af * math.cos(df), ar]])
    fa = [k * v for k, v in zip(params.tracking_stiffness_n, lam, strict=True)]
    m, g = params.mass_kg, inp.gravity_aux_mps2
    psid = inp.psi_v_dot_radps
    acc = [inp.xdd_a_mps2 - inp.yd_a_mps * psid - g[0], inp.ydd_a_mps2 + inp.xd_a_mps * psid - g[1]]
    fx = fy = 0.0
    for f, cd, sd in zip(fa, cos_d, sin_d):
        fx += f * cd
        fy += f * sd
    b = np.array([m * acc[0] - fx, m * acc[1] - fy])
    db = np.array([[acc[0]] + [-(v * cd) for v, cd in zip(lam, cos_d)],  # d/d[m, C_lambda,1..4]
                   [acc[1]] + [-(v * sd) for v, sd in zip(lam, sin_d)]])
    if len(cfg.cornering.q) == 3:  # the yaw row
        a_z, b_z, db_z = _cornering_yaw_row(inp, vehicle, params, np.array(fa), al)
        # its b uses I_z: weight sd_row / sqrt(sd_row^2 + (sigma_Iz wd_z)^2), sigma_Iz the prior's
        s_iz = cfg.inertia.prior_rel_sigma * vehicle.params.inertia_z_kgm2 * cfg.cornering.q[2]
        k = 1.0 / math.sqrt(1.0 + (s_iz * inp.omega_dot_radps2[2]) ** 2)
        a, b, db = np.vstack([a, k * a_z]), np.append(b, k * b_z), np.vstack([db, k * db_z])
    rows = _gate(a, cfg.cornering.excitation_min, abs(inp.xd_a_mps) >= cfg.min_speed_mps)
    gated = lateral_gate(inp, al, acc[1], cfg.cornering)
    if gated is not None:
        rows = np.zeros(len(rows), dtype=bool)
    return Regressor(a, b, rows, db, gated)


def _cornering_yaw_row(inp: IdentInputs, vehicle: Vehicle, params: IdentifiedParams, fa, al):
    """Eq 22's optional third row: eq 13's yaw balance (eq 23's third row) with the eq 15 lateral
    forces F_b,i = C_alpha,axle / 2 alpha_i as the unknowns (``forces``' moment, corner i at
    (x_i, y_i))::

        A_3 = [sum_{i=1,2} (x_i cos d_i + y_i sin d_i) alpha_i / 2,  sum_{i=3,4} (...) / 2]
        b_3 = I_z wd_z - (I_x - I_y) w_x w_y - sum_i (x_i F_a,i sin d_i - y_i F_a,i cos d_i) - M_z,u

    (F_a,i = C_lambda,i lambda_i, M_z,u the unsprung masses' term of ``forces``; I from the current
    estimates, Gauss-Seidel as m in rows 1-2). Why: rows 1-2 weigh the two axles almost only
    through F_f + F_r = m a_y, whose columns alpha_f and alpha_r are nearly collinear (on a steady
    circle both follow a_y), so the split is left to small transient differences, and a slip
    estimate a few percent off moved C_alpha,f by +58 % and C_alpha,r by -3 % on a CommonRoad sine
    (issue 17, second session); the yaw balance weighs them by their levers, l_f F_f - l_r F_r =
    I_z wd_z + ..., and at a steady state (wd_z ~ 0) it needs no inertia at all. The caller
    weights the row by 1 / sqrt(1 + (q_3 sigma_Iz wd_z)^2) (sigma_Iz the inertia problem's prior
    sigma, q_3 = 1 / the row's design noise): the row's variance with the inertia's uncertainty
    added, so rows at a large yaw acceleration, where a wrong I_z would bias the split, count
    little (Gauss-Seidel with the prior I_z early in a drive). ``al``: the slip angles of rows
    1-2 (``forces.slip_angles_rad``). Returns
    (A_3 [m rad], b_3 [N m], db_3/d[m, C_lambda,1..4])."""
    xy = corner_xy_array(vehicle.geometry)
    d, lam = (np.asarray(v, dtype=float) for v in (inp.wheel_angle_rad, inp.slip_ratio))
    lever = (xy[:, 0] * np.cos(d) + xy[:, 1] * np.sin(d)) * al / 2.0
    lon = xy[:, 0] * np.sin(d) - xy[:, 1] * np.cos(d)  # M_z per unit F_a,i
    wx, wy = (float(v) if math.isfinite(v) else 0.0 for v in inp.omega_radps[:2])  # ESC: no w_x, w_y (as the EKF)
    m_u = unsprung_inertia_moments_nm(vehicle, inp)[2]
    b = (params.inertia_z_kgm2 * inp.omega_dot_radps2[2] - (params.inertia_x_kgm2 - params.inertia_y_kgm2) * wx * wy
         - float((lon * fa).sum()) - m_u)
    return (np.array([lever[0] + lever[1], lever[2] + lever[3]]), b, np.concatenate([[0.0], -lon * lam]))


def lateral_gate(inp: IdentInputs, slip_angle_rad, lateral_accel_mps2: float, pc) -> str | None:
    """The cornering problem's excitation gates (``ProblemConfig``), or None when they pass:

    * ``"lateral excitation"``: |a_y| = |ydd_a + xd_a psid_v - G_y| below
      ``lateral_accel_min_mps2``: the lateral force is not above its noise, so whatever the
      noise does to the slip-angle estimate (which is what a straight drive shows) eq 22 would
      fit noise;
    * ``"linear range"``: |a_y| beyond ``lateral_accel_max_mps2``: eq 15's F = C_alpha alpha
      holds in the tire's linear range only (a saturating tire's secant stiffness is below its
      slope);
    * ``"slip noise"``: the larger axle slip angle |(alpha_1 + alpha_2) / 2|, |(alpha_3 +
      alpha_4) / 2| below ``slip_noise_factor`` x sigma_alpha, sigma_alpha = sigma(yd_a) / |xd_a|
      (the EKF's lateral velocity uncertainty, ``IdentInputs.lateral_velocity_sigma_mps``)."""
    ay = abs(lateral_accel_mps2)
    if not math.isfinite(ay):
        return None  # the NaN guard counts it
    if ay < pc.lateral_accel_min_mps2:
        return "lateral excitation"
    if ay > pc.lateral_accel_max_mps2:
        return "linear range"
    sv = inp.lateral_velocity_sigma_mps
    if pc.slip_noise_factor > 0.0 and sv is not None and math.isfinite(sv):
        al = np.asarray(slip_angle_rad, dtype=float)
        axle = max(abs(al[0] + al[1]), abs(al[2] + al[3])) / 2.0
        if axle < pc.slip_noise_factor * sv / max(abs(inp.xd_a_mps), 1e-9):
            return "slip noise"
    return None


def inertia_regressor(inp: IdentInputs, vehicle: Vehicle, params: IdentifiedParams,
                      cfg: IdentConfig) -> Regressor:
    """Eq 23 (A as printed, b_4 = [M_x, M_y, M_z]) with the moments of ``moments_from_inputs``.

    ``structure`` (``"measured"`` form): the roll row's normal-load tilt r n_b,y sum_i F_z,i, the
    body-y share of the normal loads over a body rolled on its suspension, which reaches the body
    in the physics core (its wheels slide along the body z axis) but not in a model whose
    unsprung bodies roll on their own and pass the lateral force through a roll-axis joint
    (CommonRoad's multibody). The model file cannot say which a car is: on the CommonRoad sine
    of tuning seed 101 (set 1) dropping the term moved I_x from +28 % to -11 % (issue 17, ident
    session), so its least-squares bias is reported in the sigma (``identifier``). The pitch
    row's r n_b,x sum F_z is not charged: I_y was covered on every drive it was identified on."""
    wx, wy, wz = inp.omega_radps
    dx, dy, dz = inp.omega_dot_radps2
    a = np.array([[dx, -wy * wz, wy * wz],
                  [wz * wx, dy, -wz * wx],
                  [-wx * wy, wx * wy, dz]])
    b = moments_from_inputs(vehicle, params, inp, cfg.moment_form)
    measured = (cfg.moment_form == "measured" and inp.specific_force_b_mps2 is not None
                and inp.vehicle_angles_rad is not None)  # M_x, M_y no longer use the tire stiffnesses
    db = np.zeros((3, 6)) if inp.moments_nm is not None else _moment_sensitivity(vehicle, inp, yaw_only=measured)
    if measured:
        fz = sum_from_zero(suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps))
        tilt = vehicle.tire.rolling_radius_m * road_normal_body(*inp.vehicle_angles_rad)[1] * fz
        structure = np.array([tilt, 0.0, 0.0])
    else:
        structure = None
    rows = _gate(a, cfg.inertia.excitation_min, abs(inp.xd_a_mps) >= cfg.min_speed_mps)
    rows, refused = suspension_gate(inp, cfg, rows, (0, 1))  # M_x, M_y hold the strut forces
    if suspension_stale(inp, cfg):
        # without the roll and pitch rows (stale, or no suspension: NaN) the yaw row's gyroscopic
        # term w_x w_y (I_y - I_x) would be all that moves I_x and I_y: it takes them at their
        # current values (b_3 less that term)
        b = b.copy()
        b[2] += wx * wy * (params.inertia_x_kgm2 - params.inertia_y_kgm2)
        a[2, 0] = a[2, 1] = 0.0
    return Regressor(a, b, rows, db, structure=structure, row_gates=refused)


def _moment_sensitivity(vehicle: Vehicle, inp: IdentInputs, yaw_only: bool = False) -> np.ndarray:
    """d(M_x, M_y, M_z)/d(C_lambda,1..4, C_alpha,f, C_alpha,r): the moments are linear in the
    tire stiffnesses; dM/dF_x,i = (0, -h, -y_i), dM/dF_y,i = (h - h_rc,i, 0, x_i) (h_rc,i the
    roll-centre height of the corner's axle, ``model.chassis``; 0 in the paper's model).
    ``yaw_only``: the rows of M_x and M_y are 0."""
    geometry = vehicle.geometry
    xy = corner_xy_array(geometry).tolist()
    h = geometry.h_cg_m
    dm_dfx = ([0.0] * 4, [-h] * 4, [-y for _, y in xy])  # 3 x 4
    dm_dfy = ([h - hr for hr in roll_centre_heights_m(vehicle).tolist()], [0.0] * 4, [x for x, _ in xy])
    lam_c, lam_s, al_s, al_c = [], [], [], []  # per wheel, as elementwise numpy would form them
    for d, lam, al in zip(inp.wheel_angle_rad, inp.slip_ratio, slip_angles_rad(vehicle, inp).tolist(), strict=True):
        c, s = math.cos(d), math.sin(d)
        lam_c.append(lam * c)
        lam_s.append(lam * s)
        al_s.append(-al * s / 2.0)
        al_c.append(al * c / 2.0)
    out = [[0.0] * 6, [0.0] * 6] if yaw_only else []
    for fx, fy in zip(dm_dfx[len(out):], dm_dfy[len(out):]):
        w = [fx[i] * al_s[i] + fy[i] * al_c[i] for i in range(4)]
        out.append([fx[i] * lam_c[i] + fy[i] * lam_s[i] for i in range(4)] + [w[0] + w[1], w[2] + w[3]])
    return np.array(out)


RegressorBuilder = Callable[[IdentInputs, Vehicle, IdentifiedParams, IdentConfig], Regressor]

REGRESSORS: dict[str, RegressorBuilder] = {
    "mass": lambda inp, v, p, c: mass_regressor(inp, v, c, p),
    "tracking": lambda inp, v, p, c: tracking_regressor(inp, v, c, p),
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
    return q * math.sqrt(tot / float((q * q).sum()))
