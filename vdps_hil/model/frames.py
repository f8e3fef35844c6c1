"""Frames and kinematics of the paper, eq 1-5 and C_omega of eq 7.

Symbols (paper section 2), all angles in radians::

    phi_g, theta_g, psi_g   absolute roll, pitch, yaw      (global -> vehicle, yaw-pitch-roll)
    theta_r, phi_r, psi_r   road grade, bank, curve        (global -> road, pitch-roll-yaw)
    psi_v, theta_v, phi_v   vehicle yaw, pitch, roll        (road -> vehicle, yaw-pitch-roll)

Sign conventions are in ``vdps_hil.conventions`` (pitch nose-up positive, roll right-side-down
positive, yaw CCW from East). ``C_a^b`` maps coordinates in frame a to coordinates in frame b.
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.jit import inline


def rot_x(phi: float) -> np.ndarray:
    """R(x, phi) of eq 1."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def rot_y(theta: float) -> np.ndarray:
    """R(y, theta) of eq 1 as printed (positive theta = nose up)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(psi: float) -> np.ndarray:
    """R(z, psi) of eq 1."""
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def dcm_global_to_vehicle(phi_g: float, theta_g: float, psi_g: float) -> np.ndarray:
    """C_g^v = R(x, phi_g) R(y, theta_g) R(z, psi_g), eq 1, as the product of the three rotations.

    Equal to :func:`dcm_gv` to rounding only (the 3 x 3 products round differently from the
    closed form, by an ulp in some elements); the callers of each keep theirs so that every
    output stays bit-identical."""
    return rot_x(phi_g) @ rot_y(theta_g) @ rot_z(psi_g)


@inline
def dcm_gv_elements(sf, cf, st, ct, sp, cp):
    """The nine elements of C_g^v (eq 1, closed form), row by row, from the sines and cosines
    of the Euler angles (sf, cf = sin, cos phi_g; st, ct of theta_g; sp, cp of psi_g)::

        C_g^v = [[ ct cp,                 ct sp,                 st    ],
                 [-cf sp - sf st cp,      cf cp - sf st sp,      sf ct ],
                 [ sf sp - cf st cp,     -sf cp - cf st sp,      cf ct ]]

    The one place this formula is written: on floats it is the scalar form (the physics core,
    the EKF's kinematics), on numpy arrays the element-wise vectorised form
    (:func:`dcm_gv_batch`); the same IEEE operations in both; compiled kernels call it too
    (:func:`~vdps_hil.jit.inline`)."""
    return (ct * cp, ct * sp, st,
            -cf * sp - sf * st * cp, cf * cp - sf * st * sp, sf * ct,
            sf * sp - cf * st * cp, -sf * cp - cf * st * sp, cf * ct)


def dcm_gv(phi: float, theta: float, psi: float) -> np.ndarray:
    """C_g^v of eq 1 as a 3 x 3 array, closed form (:func:`dcm_gv_elements`; cheaper than the
    three products of :func:`dcm_global_to_vehicle`)."""
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = dcm_gv_elements(
        math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta), math.sin(psi), math.cos(psi))
    return np.array([[c00, c01, c02], [c10, c11, c12], [c20, c21, c22]])


def dcm_gv_batch(phi, theta, psi) -> np.ndarray:
    """C_g^v = R(x, phi) R(y, theta) R(z, psi) (eq 1) for arrays of angles: (N, 3, 3), closed
    form (:func:`dcm_gv_elements` on the arrays' sines and cosines)."""
    e = dcm_gv_elements(np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta), np.sin(psi), np.cos(psi))
    c = np.empty((np.size(phi), 3, 3))
    for k in range(9):
        c[:, k // 3, k % 3] = e[k]
    return c


def dcm_global_to_road(phi_r: float, theta_r: float, psi_r: float = 0.0) -> np.ndarray:
    """C_g^r = R(z, psi_r) R(x, phi_r) R(y, theta_r), eq 2 (psi_r = 0 in the paper)."""
    return rot_z(psi_r) @ rot_x(phi_r) @ rot_y(theta_r)


def dcm_road_to_vehicle(phi_v: float, theta_v: float, psi_v: float) -> np.ndarray:
    """C_r^v = R(x, phi_v) R(y, theta_v) R(z, psi_v), eq 3."""
    return rot_x(phi_v) @ rot_y(theta_v) @ rot_z(psi_v)


def dcm_road_to_aux(psi_v: float) -> np.ndarray:
    """C_r^a = R(z, psi_v): the aux frame is the road frame yawed by psi_v (section 2)."""
    return rot_z(psi_v)


def euler_ypr_from_dcm(c: np.ndarray) -> tuple[float, float, float]:
    """Inverse of C = R(x, phi) R(y, theta) R(z, psi): returns (phi, theta, psi).

    Valid for |theta| < pi/2. C[0,2] = sin(theta), C[1,2] = sin(phi)cos(theta),
    C[2,2] = cos(phi)cos(theta), C[0,1] = cos(theta)sin(psi), C[0,0] = cos(theta)cos(psi)."""
    theta = math.asin(max(-1.0, min(1.0, float(c[0, 2]))))
    phi = math.atan2(float(c[1, 2]), float(c[2, 2]))
    psi = math.atan2(float(c[0, 1]), float(c[0, 0]))
    return phi, theta, psi


def road_angles_from_dcm(c: np.ndarray) -> tuple[float, float, float]:
    """Inverse of C = R(z, psi_r) R(x, phi_r) R(y, theta_r): returns (phi_r, theta_r, psi_r).

    Valid for |phi_r| < pi/2. Row 3 of C is [-cos(phi)sin(theta), -sin(phi), cos(phi)cos(theta)];
    C[0,1] = sin(psi)cos(phi), C[1,1] = cos(psi)cos(phi)."""
    phi = math.asin(max(-1.0, min(1.0, -float(c[2, 1]))))
    theta = math.atan2(-float(c[2, 0]), float(c[2, 2]))
    psi = math.atan2(float(c[0, 1]), float(c[1, 1]))
    return phi, theta, psi


def compose_absolute(phi_v: float, theta_v: float, psi_v: float,
                     phi_r: float, theta_r: float, psi_r: float = 0.0) -> tuple[float, float, float]:
    """Eq 4: C_g^v = C_r^v C_g^r. Returns the absolute angles (phi_g, theta_g, psi_g)."""
    c = dcm_road_to_vehicle(phi_v, theta_v, psi_v) @ dcm_global_to_road(phi_r, theta_r, psi_r)
    return euler_ypr_from_dcm(c)


def decompose_vehicle(phi_g: float, theta_g: float, psi_g: float,
                      phi_r: float, theta_r: float, psi_r: float = 0.0) -> tuple[float, float, float]:
    """Eq 4 solved for the vehicle angles: C_r^v = C_g^v (C_g^r)^T -> (phi_v, theta_v, psi_v)."""
    c = dcm_global_to_vehicle(phi_g, theta_g, psi_g) @ dcm_global_to_road(phi_r, theta_r, psi_r).T
    return euler_ypr_from_dcm(c)


def decompose_road(phi_g: float, theta_g: float, psi_g: float,
                   phi_v: float, theta_v: float, psi_v: float) -> tuple[float, float, float]:
    """Eq 4 solved for the road angles: C_g^r = (C_r^v)^T C_g^v -> (phi_r, theta_r, psi_r)."""
    c = dcm_road_to_vehicle(phi_v, theta_v, psi_v).T @ dcm_global_to_vehicle(phi_g, theta_g, psi_g)
    return road_angles_from_dcm(c)


def decompose_vehicle_batch(euler_g_rad, bank_rad: float, grade_rad: float) -> np.ndarray:
    """Eq 4 vectorised: absolute angles (N, 3) -> road-relative (phi_v, theta_v, psi_v) (N, 3),
    C_r^v = C_g^v (C_g^r)^T with psi_r = 0 (:func:`dcm_gv_batch`)."""
    e = np.atleast_2d(np.asarray(euler_g_rad, dtype=float))
    c = dcm_gv_batch(e[:, 0], e[:, 1], e[:, 2])
    cr = c @ dcm_global_to_road(bank_rad, grade_rad).T
    return np.stack([np.arctan2(cr[:, 1, 2], cr[:, 2, 2]),
                     np.arcsin(np.clip(cr[:, 0, 2], -1.0, 1.0)),
                     np.arctan2(cr[:, 0, 1], cr[:, 0, 0])], axis=1)


def c_omega(phi: float, theta: float) -> np.ndarray:
    """C_omega of eq 7, consistent with eq 1 as printed: omega_body = C_omega @ [phi', theta', psi'].

    Derivation: omega = e_x phi' + R(x,phi) (-e_y) theta' + R(x,phi) R(y,theta) e_z psi'
    (R(y, theta) of eq 1 is a rotation by -theta about +y). The paper prints the matrix of the
    opposite pitch sign; see ``vdps_hil.conventions``."""
    cp, sp = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    return np.array([[1.0, 0.0, st], [0.0, -cp, ct * sp], [0.0, sp, ct * cp]])


def c_omega_inv(phi: float, theta: float) -> np.ndarray:
    """Inverse of ``c_omega``: [phi', theta', psi'] = C_omega^-1 @ omega_body (singular at
    |theta| = pi/2)."""
    cp, sp = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    return np.array([
        [1.0, -st * sp / ct, -st * cp / ct],
        [0.0, -cp, sp],
        [0.0, sp / ct, cp / ct],
    ])


def skew(v) -> np.ndarray:
    """[v x] such that skew(a) @ b = a x b."""
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def suspension_to_road_attitude(h_m, l_f_m: float, l_r_m: float,
                                t_f_half_m: float, t_r_half_m: float) -> tuple[float, float, float]:
    """Eq 5: suspension deflections H_1..4 [m] (compression positive, order FL FR RR RL) ->
    (z_r [m], theta_v [rad], phi_v [rad]) relative to the road plane.

    z_r = (-l_r (H1 + H2) - l_f (H3 + H4)) / (2 l_f + 2 l_r)
    theta_v = asin((-H1 - H2 + H3 + H4) / (2 l_f + 2 l_r))     (nose up positive; see conventions)
    phi_v = asin((-H1 + H2 + H3 - H4) / ((2 t_f + 2 t_r) cos theta_v))
    """
    h1, h2, h3, h4 = (float(h) for h in h_m)
    wb2 = 2.0 * l_f_m + 2.0 * l_r_m
    z_r = (-l_r_m * (h1 + h2) - l_f_m * (h3 + h4)) / wb2
    theta_v = math.asin(max(-1.0, min(1.0, (-h1 - h2 + h3 + h4) / wb2)))
    phi_v = math.asin(max(-1.0, min(1.0, (-h1 + h2 + h3 - h4)
                                    / ((2.0 * t_f_half_m + 2.0 * t_r_half_m) * math.cos(theta_v)))))
    return z_r, theta_v, phi_v


def gravity_in_aux(phi_r: float, theta_r: float, psi_v: float, g_mps2: float) -> np.ndarray:
    """[G_x, G_y, G_z] of eq 13: R(z, psi_v) R(x, phi_r) R(y, theta_r) [0, 0, -g]."""
    return rot_z(psi_v) @ rot_x(phi_r) @ rot_y(theta_r) @ np.array([0.0, 0.0, -g_mps2])
