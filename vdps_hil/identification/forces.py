"""Forces and moments of the identification model (the spring law of eq 14 per corner is
``model.spring_law``): the tire
forces of eq 15-17 and the body moments of eq 23's b_4 (``moments_from_inputs``), from estimated
quantities (``inputs.IdentInputs``) and a model vehicle.

Moments M_x, M_y, M_z of eq 23's b_4 (the paper gives them only as "functions of the forces,
attitude and geometry [25]"). We use the physics core's definition (``vdps_hil/model/core.py``,
truth variant ``unsprung_dof=True``), checked against it in ``tests/test_problems.py`` and
``tests/test_forces.py``: forces on the sprung body about its CG, vehicle frame, corner i at
(x_i, y_i) from ``Geometry.corner_xy_m()``:

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

  Chassis parts of the model file (``model.chassis``): the strut forces F_s,i include the
  anti-roll bars' F_arb,i (``model.spring_law``); roll centres move each axle's lateral force
  lever from h_cg to h_cg - h_rc,axle, i.e. M_x -= h_rc,f F_y,f + h_rc,r F_y,r (the linkage's
  vertical force pair, ``chassis.roll_centre_forces_n``; no M_y, M_z).

  ``moment_form = "measured"`` (default in ``configs/identification/default.toml``): the tire
  forces enter M_x and M_y only through their sums, which the accelerometer measures: in body
  axes sum_i F_tire,i = m f_b (f_b the specific force at the CG, body axes; F_tire includes the
  normal loads' components F_z,i n_b, n_b the road normal in body axes, from the estimated
  road-relative roll and pitch)::

      M_x = sum_i y_i F_s,i + (h_cg - H_bar) m f_b,y - r n_b,y sum_i F_z,i + sum_i z_w,i m_u,i f_b,y
      M_y = -sum_i x_i F_s,i - (h_cg - H_bar) m f_b,x + r n_b,x sum_i F_z,i - sum_i z_w,i m_u,i f_b,x
      M_z = as "stiffness" (the yaw moment needs the split between the axles)

  (F_z,i = eq 14's normal load, H_bar the mean deflection, z_w,i = -(h_cg - r) + H_i; the
  physics core's moments to first order in the road-relative angles and the deflections). With
  roll centres M_x -= (h_rc,f l_r + h_rc,r l_f) / L m f_b,y (the axles' share of the measured
  lateral force at a steady yaw rate, F_y,f = m f_b,y l_r / L). Why:
  the roll moment is the small difference of two large ones (the struts' y_i F_s,i and the
  tires' h_cg sum F_y): with F_y from C_alpha alpha (eq 15) a 5 % stiffness error or the Magic
  Formula's saturation, and the omitted F_z n_b,y term (body roll over the road tilts the normal
  loads), moved I_x by +16..+40 % on the paper's scenario; with the measured sums and the
  simulator's deflections I_x came to -0.4 % (linear-tire truth). It needs
  ``IdentInputs.specific_force_b_mps2`` and ``vehicle_angles_rad``; without them the stiffness
  form is used.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.identification.inputs import IdentInputs
from vdps_hil.model.core import SLIP_SPEED_FLOOR_MPS
from vdps_hil.model.spring_law import suspension_forces_n
from vdps_hil.model.params import Geometry, IdentifiedParams, Vehicle


_ARRAYS: dict[tuple, tuple] = {}  # (what, id(vehicle or geometry)) -> (the object, the array)


def corner_xy_array(geometry: Geometry) -> np.ndarray:
    """``np.array(geometry.corner_xy_m())`` (4 x 2) [m], made once per geometry (read-only)."""
    hit = _ARRAYS.get(("xy", id(geometry)))
    if hit is None or hit[0] is not geometry:
        hit = _remember("xy", geometry, np.array(geometry.corner_xy_m()))
    return hit[1]


def unsprung_masses_kg(vehicle: Vehicle) -> np.ndarray:
    """m_u,i per corner [kg], made once per vehicle (read-only)."""
    hit = _ARRAYS.get(("m_u", id(vehicle)))
    if hit is None or hit[0] is not vehicle:
        hit = _remember("m_u", vehicle, np.array([vehicle.axle(i).unsprung_mass_kg for i in range(4)]))
    return hit[1]


def roll_centre_heights_m(vehicle: Vehicle) -> np.ndarray:
    """h_rc,i per corner [m] (``model.chassis``; 0 in the paper's model), made once per vehicle
    (read-only)."""
    hit = _ARRAYS.get(("h_rc", id(vehicle)))
    if hit is None or hit[0] is not vehicle:
        hit = _remember("h_rc", vehicle, np.array([vehicle.chassis.roll_centre_height_m(i) for i in range(4)]))
    return hit[1]


def _remember(what: str, owner, arr: np.ndarray) -> tuple:
    """Keep ``arr`` for ``owner`` (a frozen vehicle file or its geometry: per-input callers read
    the same constants at 100 Hz)."""
    if len(_ARRAYS) > 32:
        _ARRAYS.clear()
    arr.flags.writeable = False
    hit = _ARRAYS[(what, id(owner))] = (owner, arr)
    return hit


def slip_angles_rad(vehicle: Vehicle, inp: IdentInputs) -> np.ndarray:
    """The slip angles the model's wheels see: ``inp.slip_angle_rad`` (the rigid kinematics of
    ``model.core``) with the body roll rate's share 1 - c_r removed (``model.chassis``, wheel
    roll coupling): alpha_i + (1 - c_r) p (h_cg - r) cos d_i / max(|v_l,i|, v_floor) [rad] with
    the wheel's rolling speed v_l,i = (xd_a - psid y_i) cos d_i + (yd_a + psid x_i) sin d_i. The
    same array when c_r = 1 (the paper's model) or the roll rate is not measured. (The last
    result is kept: each regressor of one input asks for it.)"""
    last = _LAST_SLIP[0]  # one tuple, read and replaced whole (threads may share the module)
    if last[0] is inp and last[1] is vehicle:
        return last[2].copy()
    al = _slip_angles(vehicle, inp)
    _LAST_SLIP[0] = (inp, vehicle, al.copy())
    return al


_LAST_SLIP: list = [(None, None, None)]  # (inputs, vehicle, slip angles) of the last ``slip_angles_rad``


def _slip_angles(vehicle: Vehicle, inp: IdentInputs) -> np.ndarray:
    al = np.asarray(inp.slip_angle_rad, dtype=float)
    share = 1.0 - vehicle.chassis.wheel_roll_coupling
    p = inp.omega_radps[0]
    if share == 0.0 or not math.isfinite(p):
        return al
    lever = vehicle.geometry.h_cg_m - vehicle.tire.rolling_radius_m
    xy = corner_xy_array(vehicle.geometry)
    d = np.asarray(inp.wheel_angle_rad, dtype=float)
    r = inp.omega_radps[2] if math.isfinite(inp.omega_radps[2]) else 0.0
    v_l = (inp.xd_a_mps - r * xy[:, 1]) * np.cos(d) + (inp.yd_a_mps + r * xy[:, 0]) * np.sin(d)
    return al + share * p * lever * np.cos(d) / np.maximum(np.abs(v_l), SLIP_SPEED_FLOOR_MPS)


def tire_forces_wheel_n(slip_ratio, slip_angle_rad, params: IdentifiedParams) -> tuple[np.ndarray, np.ndarray]:
    """Eq 15 with eq 17's equal sides: F_a,i = C_lambda,i lambda_i, F_b,i = C_alpha,axle/2
    alpha_i [N], wheel frame (a forward along the wheel, b to its left)."""
    fa, fb = _wheel_forces(params, _floats(slip_ratio), _floats(slip_angle_rad))
    return np.array(fa), np.array(fb)


def tire_forces_body_n(f_a_n, f_b_n, wheel_angle_rad) -> tuple[np.ndarray, np.ndarray]:
    """Eq 16 per wheel: wheel-frame forces rotated by the wheel angle into the vehicle frame."""
    fx, fy = _body_forces(_floats(f_a_n), _floats(f_b_n), _floats(wheel_angle_rad))
    return np.array(fx), np.array(fy)


def body_moments_nm(geometry: Geometry, f_susp_body_n, f_x_n, f_y_n) -> np.ndarray:
    """(M_x, M_y, M_z) about the CG, vehicle frame, of the strut and tire forces:
    sum_i r_i x F_i with r_i = (x_i, y_i, -h_cg) and F_i = (F_x,i, F_y,i, F_s,i)."""
    return np.array(_body_moments(geometry, _floats(f_susp_body_n), _floats(f_x_n), _floats(f_y_n)))


def unsprung_inertia_moments_nm(vehicle: Vehicle, inp: IdentInputs) -> np.ndarray:
    """(M_x, M_y, M_z) of the unsprung masses' horizontal weight and inertia (d'Alembert force
    m_u,i (g - a) at the wheel centre r_w,i = (x_i, y_i, -(h_cg - r) + H_i)), as the physics
    core applies them to the sprung body. a - g in the aux frame is (xdd_a - yd_a psid_v - G_x,
    ydd_a + xd_a psid_v - G_y) (eq 13's left-hand sides over m)."""
    return np.array(_unsprung_moments(vehicle, inp))


# The float cores of the functions above: per wheel in plain floats (4 values each, where numpy's
# per-call cost exceeds the arithmetic), the same operations in the same order as elementwise
# numpy, sums from 0.0 in wheel order as numpy's for 4 values: the results are bit-identical.
def _floats(v) -> list[float]:
    return np.asarray(v, dtype=float).tolist()


def sum_from_zero(values) -> float:
    """``float(np.sum(values))`` for a few values (numpy adds fewer than 8 in order, from 0.0), in
    floats."""
    total = 0.0
    for v in _floats(values):
        total += v
    return total


def _wheel_forces(params: IdentifiedParams, slip_ratio, slip_angle_rad) -> tuple[list, list]:
    c_f = params.cornering_stiffness_front_nprad / 2.0
    c_r = params.cornering_stiffness_rear_nprad / 2.0
    return ([c * lam for c, lam in zip(params.tracking_stiffness_n, slip_ratio, strict=True)],
            [c * al for c, al in zip((c_f, c_f, c_r, c_r), slip_angle_rad, strict=True)])


def _body_forces(fa, fb, wheel_angle_rad) -> tuple[list, list]:
    fx, fy = [], []
    for a, b, d in zip(fa, fb, wheel_angle_rad, strict=True):
        c, s = math.cos(d), math.sin(d)
        fx.append(a * c - b * s)
        fy.append(a * s + b * c)
    return fx, fy


def _body_moments(geometry: Geometry, fs, fx, fy) -> list[float]:
    h = geometry.h_cg_m
    mx = my = mz = 0.0
    for (x, y), s, a, b in zip(corner_xy_array(geometry).tolist(), fs, fx, fy, strict=True):
        mx += y * s + h * b
        my += -x * s - h * a
        mz += x * b - y * a
    return [mx, my, mz]


def _unsprung_moments(vehicle: Vehicle, inp: IdentInputs) -> list[float]:
    geo = vehicle.geometry
    zw0 = -(geo.h_cg_m - vehicle.tire.rolling_radius_m)
    psid = inp.psi_v_dot_radps
    ax = inp.xdd_a_mps2 - inp.yd_a_mps * psid - inp.gravity_aux_mps2[0]
    ay = inp.ydd_a_mps2 + inp.xd_a_mps * psid - inp.gravity_aux_mps2[1]
    mx = my = mz = 0.0
    for (x, y), mu, hh in zip(corner_xy_array(geo).tolist(), unsprung_masses_kg(vehicle).tolist(),
                              inp.susp_deflection_m, strict=True):
        zw = zw0 + hh
        ux, uy = -mu * ax, -mu * ay
        mx += -zw * uy
        my += zw * ux
        mz += x * uy - y * ux
    return [mx, my, mz]


def moments_from_inputs(vehicle: Vehicle, params: IdentifiedParams, inp: IdentInputs,
                        form: str = "stiffness") -> np.ndarray:
    """b_4 of eq 23: strut forces (eq 14), tire forces (eq 15-17 with ``params``) and the
    unsprung masses' horizontal weight and inertia; ``form = "measured"`` takes M_x, M_y from
    the measured specific force (module docstring) when the inputs carry it."""
    if inp.moments_nm is not None:
        return np.array(inp.moments_nm)
    fs = suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps, include_unsprung_weight=False)
    fa, fb = _wheel_forces(params, inp.slip_ratio, slip_angles_rad(vehicle, inp).tolist())
    fx, fy = _body_forces(fa, fb, inp.wheel_angle_rad)
    m = [b + u for b, u in zip(_body_moments(vehicle.geometry, fs.tolist(), fx, fy), _unsprung_moments(vehicle, inp))]
    ch = vehicle.chassis
    if ch.has_roll_centres:
        m[0] -= ch.roll_centre_height_front_m * (fy[0] + fy[1]) + ch.roll_centre_height_rear_m * (fy[2] + fy[3])
    if form == "measured" and inp.specific_force_b_mps2 is not None and inp.vehicle_angles_rad is not None:
        m[0], m[1] = measured_roll_pitch_moments_nm(vehicle, params.mass_kg, inp, fs)
    return np.array(m)


def road_normal_body(phi_v_rad: float, theta_v_rad: float) -> np.ndarray:
    """n_b = C_r^v e_z: the road normal in body axes from the road-relative roll and pitch
    (eq 3-4 with psi_v = 0; body parallel to the road: (0, 0, 1))."""
    sp, cp, st, ct = math.sin(phi_v_rad), math.cos(phi_v_rad), math.sin(theta_v_rad), math.cos(theta_v_rad)
    return np.array([st, sp * ct, cp * ct])


def measured_roll_pitch_moments_nm(vehicle: Vehicle, mass_kg: float, inp: IdentInputs, strut_n=None
                                   ) -> tuple[float, float]:
    """(M_x, M_y) of the ``"measured"`` moment form (module docstring) [N m]."""
    geo = vehicle.geometry
    h, r = geo.h_cg_m, vehicle.tire.rolling_radius_m
    fs = (suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps, include_unsprung_weight=False)
          if strut_n is None else strut_n)
    fz = sum_from_zero(suspension_forces_n(vehicle, inp.susp_deflection_m, inp.susp_rate_mps))
    # in floats, numpy's order (the float cores' rule above)
    hh = _floats(inp.susp_deflection_m)
    sx = sy = szm = hsum = 0.0
    for (x, y), s, mu, hi in zip(corner_xy_array(geo).tolist(), _floats(fs), unsprung_masses_kg(vehicle).tolist(), hh,
                                 strict=True):
        sx += x * s
        sy += y * s
        szm += (-(h - r) + hi) * mu
        hsum += hi
    n = road_normal_body(*inp.vehicle_angles_rad)
    f = inp.specific_force_b_mps2
    lever = h - hsum / len(hh)
    ch = vehicle.chassis
    if ch.has_roll_centres:
        lever -= (ch.roll_centre_height_front_m * geo.l_r_m + ch.roll_centre_height_rear_m * geo.l_f_m) / geo.wheelbase_m
    mx = float(sy + lever * mass_kg * f[1] - r * n[1] * fz + szm * f[1])
    my = float(-sx - lever * mass_kg * f[0] + r * n[0] * fz - szm * f[0])
    return mx, my
