"""CommonRoad's multibody model as this project uses it: the package's right-hand side, re-bound
with three stated changes, its two admitted parameter sets and their truth figures.

Source: ``vehicle_dynamics_mb`` of the PyPI package ``commonroad-vehicle-models`` 3.0.2
(M. Althoff, G. Wuersching, *CommonRoad: Vehicle Models*, 2020; TU Munich). Its code is called,
never copied: :func:`mb_rhs` re-binds the package's own function objects (``types.FunctionType``
over their ``__code__``) to a copy of their module globals in which the tire functions are
replaced, so the package's modules stay untouched for any other user in the process.

The package's model (read from its source)
------------------------------------------
29 states: x1, x2 position in a global plane; x3 front road-wheel angle delta; x4 = u, x11 = v
(velocity of the sprung CG in the yaw frame); x5 yaw psi, x6 yaw rate; x7, x8 roll phi and its
rate; x9, x10 pitch theta and its rate; x12, x13 sprung-mass vertical position and velocity;
x14-x18 front unsprung mass (roll, roll rate, lateral velocity, vertical position, velocity),
x19-x23 the rear one; x24-x27 wheel spins LF RF LR RR; x28, x29 lateral compliance of the two
roll-axis joints. Inputs u1 = d delta/dt, u2 = longitudinal acceleration (``mb_inputs``).

* **Axes**: SAE: body x forward, y right, z down. Yaw rate positive = turning right (seen from
  above); the global plane (x1, x2) has x2 to the right of x1; z positions grow downwards
  (gravity enters as +g). Roll positive = right side down, pitch positive = nose up (the same
  physical senses as ``vdps_hil.conventions``); road-wheel angle positive = steered right.
* **Gravity** g = 9.81 m/s^2 (hard-coded in the package; ours is 9.80665): the truth backend's
  specific force uses the package's g, so the IMU at rest reads 9.81 m/s^2.
* **Road**: flat, level, rigid. **No wheel lift-off**: the normal load is the tire spring
  K_zt x (deflection) without a clamp at zero, so it goes negative when a wheel would lift; the
  tire formulas are then outside their range (the backend stops there, ``truth_cr``).
* **Low speed**: below |u| = 0.1 m/s the planar states follow a kinematic single-track model
  (slip set to zero); above, the slip ratio 1 - R_w omega / u_w has no floor, so the wheel-spin
  mode stiffens as 1/u (``truth_cr`` sub-steps for it).
* **Wheel torques**: from u2 only: T = m R_w u2, split front/rear by T_se (drive) or T_sb
  (brake), equally left/right (``mb_inputs`` computes the same split for the truth record).

Changes made here (each switchable for tests; the defaults are what the truth backend uses)
-------------------------------------------------------------------------------------------
1. **Smoothed camber sign** (``sign_width_rad``). ``formula_lateral`` writes the camber terms
   as S_Hy = sign(gamma)(p_hy1 + p_hy3 |gamma|), S_Vy = sign(gamma) F_z (p_vy1 + p_vy3 |gamma|):
   as the camber crosses zero the lateral force jumps by 2 F_z (p_ky1 p_hy1 + p_vy1) = -0.043 F_z
   (158 N on a 3.7 kN front tire of set 1), so straight ahead (gamma = roll + camber gain x
   travel ~ 0) the tires chatter: set 1 at 25 m/s with a 1e-6 rad roll disturbance, each tire's
   force swings between -160 and +160 N and the lateral acceleration by +-0.36 m/s^2 on a
   straight road (smoothed: below 1e-4 m/s^2). We use sign(gamma) ~ tanh(gamma / w) with
   w = ``CAMBER_SIGN_WIDTH_RAD`` = 0.01 rad: the camber slope at zero camber is then
   F_z (p_ky1 p_hy1 + p_vy1) / w = -2.1 F_z per rad, 0.10 of the cornering stiffness
   |p_ky1| F_z = 21.9 F_z per rad (a camber stiffness of about a tenth of the cornering
   stiffness is the usual order for radial car tires); beyond |gamma| = 3 w the package's values
   are kept to 0.5 %.
2. **Mirrored combined slip** (``mirror_combined``). The package's combined-slip functions are
   not mirror-symmetric: ``formula_lateral_comb`` has the slip-induced side force
   S_Vy,kappa = mu_y F_z (r_vy1 + r_vy3 gamma) cos(atan(r_vy4 alpha)) sin(r_vy5 atan(r_vy6 kappa))
   whose r_vy1 part does not change sign with alpha and gamma, and a weighting
   B_y,kappa = r_by1 cos(atan(r_by2 (alpha - r_by3))) shifted by r_by3; ``formula_longitudinal_comb``
   is shifted by r_hx1 in alpha. The same functions act on the left and the right tires, so a
   left turn is not the mirror image of a right turn, and braking or driving straight ahead
   (kappa != 0, alpha = gamma = 0) makes all four tires push the same way. Measured on set 1
   from 25 m/s (RK2, 1 ms; ``tests/test_cr_model.py`` checks the sense of each): a 0.38 g
   straight-line brake drifts 0.064 m sideways and yaws 0.14 deg in 2 s, a 0.2 g drive from
   20 m/s 0.13 m; a 1 Hz, 25 deg steering-wheel sine started to the left or to the right
   differs from its mirror image by 0.069 m in lateral position and 0.083 deg in yaw within
   4 s. A vehicle with its tires mounted mirror-wise has F_y,R(kappa, alpha, gamma) =
   -F_y,L(kappa, -alpha, -gamma) and F_x,R(kappa, alpha) = F_x,L(kappa, -alpha); we use for
   every tire the mirror-symmetric part of the package's functions::

       F_y = (F_y,comb(kappa, alpha, gamma, F0_y) - F_y,comb(kappa, -alpha, -gamma, -F0_y)) / 2
       F_x = (F_x,comb(kappa, alpha, F0_x) + F_x,comb(kappa, -alpha, F0_x)) / 2

   (the pure-slip functions are already odd in (alpha, gamma) once the sign is smooth). This
   drops the ply-steer-like offset r_vy1 and the r_by3 and r_hx1 shifts, keeps everything else;
   at kappa = 0 the lateral force is unchanged. Cost: eight extra tire-function calls per
   evaluation (about 15 % of its time).
3. **A probe** (``probe=True``): the tire functions record their inputs and outputs, so the
   truth snapshot reports exactly the slips, loads and forces the model used (order of the calls
   in the package: LF, RF, LR, RR for each of the four functions).
4. **Without saturation, on request** (``lateral_law="linear"``; the truth backend's
   ``commonroad-mb:N:linear-lateral``, never the default): the pure-slip lateral law replaced by
   its slope at zero slip (:func:`linear_lateral`), everything else as above. The same vehicle
   and maneuver with and without the tires' saturation: the part of the model's prediction error
   that saturation causes is the difference of the two drives' errors (as "hidden minus nothing
   hidden" on our own simulator).

Parameter sets
--------------
Only sets 1 (Ford Escort) and 3 (VW Vanagon) are used in this project (``ADMITTED_SETS``). The
other multibody set the package ships is kept out of the project as an acceptance check:
:func:`load_parameters` refuses it before reading anything. The parameters are loaded with the
package's ``setup_vehicle_parameters`` (YAML through OmegaConf) and cached per process.

Truth figures (:func:`truth_figures`): what a study compares identified parameters with. They
are truth: only ``sim`` and ``experiments`` may read them (the layer rule keeps the estimator
out). Derivations, with the package's symbols:

* total mass m: the package's MASS, the mass of its longitudinal equation; m_s + m_uf + m_ur
  (m_uf, m_ur are per axle) agrees with it to 1e-3 kg.
* static tire loads (level road, at rest): F_z0,front = (m_s g b / (a + b) + m_uf g) / 2,
  F_z0,rear = (m_s g a / (a + b) + m_ur g) / 2 (the package's own static load, ``init_mb``).
* cornering stiffness per axle: the Magic Formula slope at alpha = 0 is B C D = K_y =
  |p_ky1| F_z per tire (the package simplifies K_y0 to p_ky1 F_z), so an axle has
  C_alpha = |p_ky1| (F_z,left + F_z,right): linear in the axle load, hence independent of the
  lateral load transfer; at the static load C_alpha,f = |p_ky1| 2 F_z0,front.
* tracking (longitudinal slip) stiffness per tire: K_x = p_kx1 F_z (B C D of the longitudinal
  formula), at the static load.
* inertias: I_x = I_Phi_s (sprung mass, roll, about the sprung CG), I_y = I_y_s, and
  I_z = the package's I_z (``inertia_z_kgm2``). The package's yaw equation is
  I_z dr/dt = sum_i (x_i F_y,i - y_i F_x,i) (its sumN: the tire forces' moment about the sprung
  CG; I_xz_s = 0 in both sets), which is eq 23's yaw row with this project's moments
  (``identification.forces``): its unsprung masses translate with the body (the core's
  d'Alembert force m_u,i (g - a) at the wheel centre uses the CG acceleration, no dr/dt x r_i
  term), so they add no yaw inertia of their own, and the parameter eq 23 identifies is the
  package's I_z itself. (Until issue 17's second session the figure was
  I_z - sum m_u,i (x_i^2 + y_i^2), 17 % (set 1) below it; fitted on the truth of a drive,
  tire-force moment about the sprung CG against dr/dt, cr-sine-accel set 1 seed 102 gave
  1541 kg m^2 for the package's 1538.9: ``tests/test_cr_model.py`` checks the balance.)
  ``inertia_z_unsprung_kgm2`` = sum m_u,i (x_i^2 + y_i^2) stays as a further figure.
* static ride: tire deflections F_z0 / K_zt, the sprung CG at h_s - z_s,0 above the road with
  z_s,0 = (b z_uf,0 + a z_ur,0) / (a + b) (springs at their preload, the body pitched by
  (z_ur,0 - z_uf,0) / (a + b)).

Not CommonRoad parameters, stated here (``ASSUMED``): the steering ratio (16, a passenger-car
overall ratio; the package steers the road wheels directly) and the sensor mounting (IMU at the
sprung CG, GNSS antenna 0.3 m ahead and above the CG at roof height).

Symbols: m, m_s, m_uf, m_ur [kg]; a, b CG to front / rear axle [m]; T_f, T_r track widths [m];
h_s sprung CG height [m]; R_w wheel radius [m]; K_zt tire vertical rate [N/m]; K_sf, K_sr spring
rates, K_sdf, K_sdr damping rates per corner [N/m], [N s/m]; K_tsf, K_tsr auxiliary roll
stiffness per axle [N m/rad] (negative = resisting roll); F_z normal load [N]; kappa slip ratio
(SAE, positive driving), alpha slip angle, gamma camber [rad].
"""

from __future__ import annotations

import functools
import hashlib
import math
import types
from dataclasses import dataclass
from importlib import metadata, resources
from typing import Any, Callable

from vdps_hil.model.params import Axle, Geometry, IdentifiedParams, Mounting, Tire, Vehicle

from .truth_backends import TruthBackendError

__all__ = ["ADMITTED_SETS", "RESERVED_SET", "CAMBER_SIGN_WIDTH_RAD", "CR_GRAVITY_MPS2", "ASSUMED",
           "CrParameterError", "load_parameters", "parameter_sha256", "mb_rhs", "TireProbe",
           "truth_figures", "truth_vehicle", "package_version", "LATERAL_LAWS", "linear_lateral"]

ADMITTED_SETS = (1, 3)
"""CommonRoad vehicle parameter sets used in this project (1: Ford Escort, 3: VW Vanagon)."""
RESERVED_SET = 2
"""Kept out of the project as an acceptance check: refused by :func:`load_parameters`."""
CAMBER_SIGN_WIDTH_RAD = 0.01
"""w of sign(gamma) ~ tanh(gamma / w) in the lateral camber terms [rad] (module docstring)."""
LATERAL_LAWS = ("pacejka", "linear")
"""The pure-slip lateral tire laws of :func:`tire_functions`: the package's Magic Formula (the
truth), or its slope at zero slip (``linear_lateral``: the truth without saturation)."""
CR_GRAVITY_MPS2 = 9.81
"""The package's gravity (hard-coded in ``vehicle_dynamics_mb``) [m/s^2]."""
ASSUMED = {"steer_ratio": 16.0,
           "imu_lever_arm_m": (0.0, 0.0, 0.0),
           "imu_rotation_rpy_rad": (0.0, 0.0, 0.0),
           "gnss_attitude_baseline_m": 1.5}
"""Figures that are not CommonRoad parameters (module docstring); the GNSS lever arm is per set
(``_GNSS_LEVER_ARM_M``)."""
_GNSS_LEVER_ARM_M = {1: (0.30, 0.0, 0.80), 3: (0.30, 0.0, 1.10)}
"""Roof antenna: 0.3 m ahead of the CG, at about the roof (Escort ~1.4 m, Vanagon ~1.95 m high)."""
_NAMES = {1: "Ford Escort", 3: "VW Vanagon"}


class CrParameterError(TruthBackendError):
    """A parameter set that cannot be used (one-line message)."""


def package_version() -> str:
    """The installed commonroad-vehicle-models version."""
    try:
        return metadata.version("commonroad-vehicle-models")
    except metadata.PackageNotFoundError:  # pragma: no cover - the package is a dependency
        return "not installed"


def _check_set(set_id: Any) -> int:
    if isinstance(set_id, bool) or not isinstance(set_id, int):
        raise CrParameterError(f"CommonRoad parameter set must be an integer, got {set_id!r}")
    if set_id == RESERVED_SET:
        raise CrParameterError(f"CommonRoad parameter set {RESERVED_SET} is reserved as the "
                               f"acceptance check and is not used in this project (use 1 or 3)")
    if set_id not in ADMITTED_SETS:
        raise CrParameterError(f"CommonRoad parameter set {set_id} is not one of this project's "
                               f"multibody sets (1 or 3)")
    return set_id


@functools.lru_cache(maxsize=None)
def load_parameters(set_id: int):
    """The package's parameter object of set 1 or 3 (cached; read-only by convention)."""
    set_id = _check_set(set_id)
    try:
        from vehiclemodels.vehicle_parameters import setup_vehicle_parameters
    except ImportError as e:  # pragma: no cover - the package is a dependency
        raise CrParameterError(f"commonroad-vehicle-models is not installed ({e})") from None
    return setup_vehicle_parameters(vehicle_id=set_id)


def parameter_sha256(set_id: int) -> str:
    """SHA-256 of the package's YAML file of the set (the truth vehicle's content hash)."""
    set_id = _check_set(set_id)
    data = resources.files("vehiclemodels.parameters").joinpath(f"parameters_vehicle{set_id}.yaml").read_bytes()
    return hashlib.sha256(data).hexdigest()


# ---------------------------------------------------------------------------------------------
# the package's right-hand side, re-bound
# ---------------------------------------------------------------------------------------------
def _rebind(fn: Callable, **replace: Any) -> Callable:
    """``fn``'s code object over a copy of its module globals with some names replaced (each
    must be a global the function reads: a package version that renamed it is refused)."""
    missing = [n for n in replace if n not in fn.__code__.co_names]
    if missing:
        raise CrParameterError(f"commonroad-vehicle-models {package_version()}: {fn.__name__} no longer "
                               f"reads {', '.join(missing)}; this backend is written for 3.0.2")
    g = dict(fn.__globals__)
    g.update(replace)
    return types.FunctionType(fn.__code__, g, fn.__name__, fn.__defaults__, fn.__closure__)


class TireProbe:
    """Records the tire-function calls of one right-hand-side evaluation: ``calls[name]`` is a
    list of (args, result) in call order (LF, RF, LR, RR). ``clear()`` before an evaluation."""

    NAMES = ("formula_longitudinal", "formula_lateral", "formula_longitudinal_comb", "formula_lateral_comb")

    def __init__(self):
        self.calls: dict[str, list] = {n: [] for n in self.NAMES}

    def clear(self) -> None:
        for v in self.calls.values():
            v.clear()

    def wrap(self, name: str, fn: Callable) -> Callable:
        log = self.calls[name]

        def recorded(*args):
            r = fn(*args)
            log.append((args, r))
            return r
        return recorded


def linear_lateral(sign: Callable[[float], float]) -> Callable:
    """The pure-slip lateral law with the Magic Formula replaced by its slope at zero slip,
    camber shifts and friction as the package has them (``sign``: its sign function, or the
    smoothed one)::

        F_y = K_y (alpha + S_Hy) + S_Vy,   K_y = p_ky1 F_z (= B C D, the formula's slope at 0)
        S_Hy = sign(gamma) (p_hy1 + p_hy3 |gamma|),  S_Vy = sign(gamma) F_z (p_vy1 + p_vy3 |gamma|)
        mu_y = p_dy1 (1 - p_dy3 gamma^2)            (returned as the package's function does)

    Pacejka, *Tire and Vehicle Dynamics* (3rd ed.), ch. 4 (the Magic Formula): the formula's
    slope at the origin is B C D. The truth ``commonroad-mb:N:linear-lateral`` uses it: the same vehicle without tire
    saturation (what a drive's prediction error owes to saturation is measured against it)."""

    def lateral(alpha, gamma, F_z, p):
        s = sign(gamma)
        s_hy = s * (p.p_hy1 + p.p_hy3 * abs(gamma))
        s_vy = s * F_z * (p.p_vy1 + p.p_vy3 * abs(gamma))
        return [F_z * p.p_ky1 * (alpha + s_hy) + s_vy, p.p_dy1 * (1.0 - p.p_dy3 * gamma ** 2)]

    return lateral


def tire_functions(sign_width_rad: float = CAMBER_SIGN_WIDTH_RAD, mirror_combined: bool = True,
                   probe: TireProbe | None = None, lateral_law: str = "pacejka") -> types.SimpleNamespace:
    """The four tire functions the re-bound model calls (module docstring, changes 1-3).
    ``sign_width_rad = 0`` keeps the package's sign(); ``mirror_combined = False`` keeps its
    combined-slip functions; ``lateral_law = "linear"``: the pure-slip lateral law of
    :func:`linear_lateral` instead of the package's Magic Formula."""
    import vehiclemodels.utils.tire_model as tm

    if lateral_law not in LATERAL_LAWS:
        raise CrParameterError(f"unknown lateral tire law {lateral_law!r} (known: {', '.join(LATERAL_LAWS)})")
    if sign_width_rad > 0.0:
        w = float(sign_width_rad)
        tanh = math.tanh
        smooth = lambda g: tanh(g / w)  # noqa: E731
        lateral = _rebind(tm.formula_lateral, sign=smooth)
    else:
        smooth = tm.sign
        lateral = tm.formula_lateral
    if lateral_law == "linear":
        lateral = linear_lateral(smooth)
    long_comb, lat_comb = tm.formula_longitudinal_comb, tm.formula_lateral_comb
    if mirror_combined:
        def long_comb_m(kappa, alpha, f0x, p, _f=tm.formula_longitudinal_comb):
            return 0.5 * (_f(kappa, alpha, f0x, p) + _f(kappa, -alpha, f0x, p))

        def lat_comb_m(kappa, alpha, gamma, mu_y, fz, f0y, p, _f=tm.formula_lateral_comb):
            return 0.5 * (_f(kappa, alpha, gamma, mu_y, fz, f0y, p) - _f(kappa, -alpha, -gamma, mu_y, fz, -f0y, p))
        long_comb, lat_comb = long_comb_m, lat_comb_m
    fns = {"formula_longitudinal": tm.formula_longitudinal, "formula_lateral": lateral,
           "formula_longitudinal_comb": long_comb, "formula_lateral_comb": lat_comb}
    if probe is not None:
        fns = {n: probe.wrap(n, f) for n, f in fns.items()}
    return types.SimpleNamespace(**fns)


def mb_rhs(sign_width_rad: float = CAMBER_SIGN_WIDTH_RAD, mirror_combined: bool = True,
           probe: TireProbe | None = None, lateral_law: str = "pacejka") -> Callable:
    """``f(x, u, p) -> x_dot``: the package's ``vehicle_dynamics_mb`` calling the tire functions
    of :func:`tire_functions`. With ``sign_width_rad = 0`` and ``mirror_combined = False`` it is
    the package's function exactly (tested bit for bit). The package may set negative wheel
    spins in ``x`` to zero: pass a copy."""
    from vehiclemodels import vehicle_dynamics_mb as mb

    return _rebind(mb.vehicle_dynamics_mb,
                   tireModel=tire_functions(sign_width_rad, mirror_combined, probe, lateral_law))


# ---------------------------------------------------------------------------------------------
# truth figures
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StaticRide:
    """Static equilibrium on a level road at rest (package symbols; z down, from the package's
    zero: tire just touching, spring at its preload)."""

    tire_load_front_n: float  # F_z0 per front tire
    tire_load_rear_n: float  # F_z0 per rear tire
    z_unsprung_front_m: float  # x17 = tire deflection
    z_unsprung_rear_m: float  # x22
    z_sprung_m: float  # x12
    pitch_rad: float  # x9 (nose up +)


def static_ride(p) -> StaticRide:
    """:class:`StaticRide` of a parameter object (module docstring, "static ride")."""
    g, L = CR_GRAVITY_MPS2, p.a + p.b
    fzf = 0.5 * (p.m_s * g * p.b / L + p.m_uf * g)
    fzr = 0.5 * (p.m_s * g * p.a / L + p.m_ur * g)
    zf, zr = fzf / p.K_zt, fzr / p.K_zt
    return StaticRide(fzf, fzr, zf, zr, (p.b * zf + p.a * zr) / L, (zr - zf) / L)


def truth_figures(set_id: int) -> dict[str, float]:
    """The truth figures of a CommonRoad vehicle (module docstring): every identified parameter
    under its ``IdentifiedParams`` name plus the figures a study needs. TRUTH: for sim/ and
    experiments/ only."""
    p = load_parameters(set_id)
    ride = static_ride(p)
    kx, ky = p.tire.p_kx1, abs(p.tire.p_ky1)
    loads = (ride.tire_load_front_n, ride.tire_load_front_n, ride.tire_load_rear_n, ride.tire_load_rear_n)
    corners = ((p.a, p.T_f / 2), (p.a, p.T_f / 2), (-p.b, p.T_r / 2), (-p.b, p.T_r / 2))
    m_u = (p.m_uf / 2, p.m_uf / 2, p.m_ur / 2, p.m_ur / 2)
    iz_unsprung = sum(mu * (x * x + y * y) for mu, (x, y) in zip(m_u, corners))
    fig = {
        "mass_kg": p.m,
        "inertia_x_kgm2": p.I_Phi_s,
        "inertia_y_kgm2": p.I_y_s,
        "inertia_z_kgm2": p.I_z,
        **{f"tracking_stiffness_{i + 1}_n": kx * loads[i] for i in range(4)},
        "cornering_stiffness_front_nprad": ky * 2.0 * ride.tire_load_front_n,
        "cornering_stiffness_rear_nprad": ky * 2.0 * ride.tire_load_rear_n,
        # further figures
        "inertia_z_total_kgm2": p.I_z,
        "inertia_z_unsprung_kgm2": iz_unsprung,
        "inertia_xz_kgm2": p.I_xz_s,
        "sprung_mass_kg": p.m_s,
        "mass_sum_of_bodies_kg": p.m_s + p.m_uf + p.m_ur,
        "unsprung_mass_front_axle_kg": p.m_uf,
        "unsprung_mass_rear_axle_kg": p.m_ur,
        "cornering_stiffness_per_load_nprad_per_n": ky,
        "tracking_stiffness_per_load": kx,
        **{f"static_load_n_{i + 1}": loads[i] for i in range(4)},
        "l_f_m": p.a, "l_r_m": p.b, "track_front_m": p.T_f, "track_rear_m": p.T_r,
        "h_sprung_cg_design_m": p.h_s, "h_cg_total_m": p.h_cg,
        "h_sprung_cg_static_m": p.h_s - ride.z_sprung_m,
        "static_pitch_rad": ride.pitch_rad,
        "roll_axis_height_front_m": p.h_raf, "roll_axis_height_rear_m": p.h_rar,
        "aux_roll_stiffness_front_nmprad": 0.0 - p.K_tsf, "aux_roll_stiffness_rear_nmprad": 0.0 - p.K_tsr,
        "spring_rate_front_npm": p.K_sf, "spring_rate_rear_npm": p.K_sr,
        "damping_front_nspm": p.K_sdf, "damping_rear_nspm": p.K_sdr,
        "tire_vertical_stiffness_npm": p.K_zt, "wheel_radius_m": p.R_w, "wheel_inertia_kgm2": p.I_y_w,
        "camber_gain_front_radpm": p.D_f, "camber_gain_rear_radpm": p.D_r,
        "lateral_compliance_mpn": p.K_lt,
        "peak_friction_lateral": p.tire.p_dy1, "peak_friction_longitudinal": p.tire.p_dx1,
        "brake_split_front": p.T_sb, "drive_split_front": p.T_se,
        "steer_angle_max_rad": p.steering.max, "steer_rate_max_radps": p.steering.v_max,
        "accel_max_mps2": p.longitudinal.a_max, "accel_switch_speed_mps": p.longitudinal.v_switch,
        "steer_ratio": ASSUMED["steer_ratio"],
    }
    return fig


def truth_vehicle(set_id: int) -> Vehicle:
    """A ``Vehicle`` (kind "truth") holding the CommonRoad vehicle's figures in this project's
    schema, for the closed-loop driver (wheelbase, steering ratio, mass, understeer) and the
    sensor models (mounting). TRUTH: sim/ only. Springs are linear (C2 = 0) at the package's
    rates; the auxiliary roll stiffness, roll-axis heights and camber gains have no place in
    the schema (issue 17, point 2)."""
    p = load_parameters(set_id)
    fig = truth_figures(set_id)
    g, L = CR_GRAVITY_MPS2, p.a + p.b
    pre_f = p.m_s * g * p.b / (2 * L) / p.K_sf  # spring compression at the preload [m]
    pre_r = p.m_s * g * p.a / (2 * L) / p.K_sr
    geo = Geometry(l_f_m=p.a, l_r_m=p.b, track_half_front_m=p.T_f / 2, track_half_rear_m=p.T_r / 2,
                   h_cg_m=fig["h_sprung_cg_static_m"], steer_ratio=ASSUMED["steer_ratio"])
    front = Axle(spring_c1_npm=p.K_sf, spring_c2_per_m=0.0, spring_c3_m=pre_f, static_compression_m=pre_f,
                 damper_nspm=p.K_sdf, unsprung_mass_kg=p.m_uf / 2)
    rear = Axle(spring_c1_npm=p.K_sr, spring_c2_per_m=0.0, spring_c3_m=pre_r, static_compression_m=pre_r,
                damper_nspm=p.K_sdr, unsprung_mass_kg=p.m_ur / 2)
    tire = Tire(rolling_radius_m=p.R_w, wheel_inertia_kgm2=p.I_y_w, vertical_stiffness_npm=p.K_zt)
    mount = Mounting(imu_lever_arm_m=ASSUMED["imu_lever_arm_m"], imu_rotation_rpy_rad=ASSUMED["imu_rotation_rpy_rad"],
                     gnss_lever_arm_m=_GNSS_LEVER_ARM_M[set_id],
                     gnss_attitude_baseline_m=ASSUMED["gnss_attitude_baseline_m"])
    params = IdentifiedParams(**{k: fig[k] for k in IdentifiedParams.__dataclass_fields__})
    return Vehicle(name=f"commonroad-mb-{set_id}", kind="truth",
                   description=f"CommonRoad multibody vehicle {set_id} ({_NAMES[set_id]}), "
                               f"commonroad-vehicle-models {package_version()}",
                   geometry=geo, front=front, rear=rear, tire=tire, mounting=mount, params=params,
                   effects={}, source_sha256=parameter_sha256(set_id))
