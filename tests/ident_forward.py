"""Synthetic identification inputs for the identification tests (a helper module, not a test).

The synthetic data are built from eq 13-17 by an independent forward model written here
(vector cross products, rotation matrices, the vector Euler equation I wd + w x I w = M), not
by inverting the regressors under test: ``forward`` gives one consistent ``IdentInputs`` from
random excitation and the "true" parameters ``TRUE`` of the ``MODEL`` vehicle."""

import dataclasses
import math

import numpy as np

from vdps_hil.identification.config import PROBLEM_NAMES, load_ident_config
from vdps_hil.identification.inputs import IdentInputs, gravity_aux_mps2
from vdps_hil.model.params import PARAM_NAMES, load_vehicle
from vdps_hil.units import GRAVITY_MPS2

MODEL = load_vehicle("sedan-model", "model")
# "True" parameters of the synthetic vehicle (test inputs, of the order of a mid-size sedan)
TRUE = dataclasses.replace(
    MODEL.params, mass_kg=1600.0, inertia_x_kgm2=550.0, inertia_y_kgm2=2400.0, inertia_z_kgm2=2700.0,
    tracking_stiffness_1_n=80000.0, tracking_stiffness_2_n=85000.0, tracking_stiffness_3_n=75000.0,
    tracking_stiffness_4_n=90000.0, cornering_stiffness_front_nprad=120000.0,
    cornering_stiffness_rear_nprad=170000.0)
G = GRAVITY_MPS2


def weak_prior_config(**general):
    cfg = load_ident_config()
    probs = {n: dataclasses.replace(cfg.problem(n), prior_rel_sigma=1e6) for n in PROBLEM_NAMES}
    return dataclasses.replace(cfg, **probs, **general)


def _cross(a, b) -> np.ndarray:
    """a x b of two 3-vectors: np.cross's products and differences, in Python floats (np.cross's
    own overhead per call was most of this module's time in the tests)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def forward(rng, k, true=TRUE, ackermann=True, pitch_scale=1.0, **override):
    """One consistent IdentInputs from random excitation and eq 13-17 with ``true``."""
    geo, r, iw = MODEL.geometry, MODEL.tire.rolling_radius_m, MODEL.tire.wheel_inertia_kgm2
    speed = rng.uniform(10.0, 30.0)
    yd, psid = rng.normal(0.0, 0.5), rng.normal(0.0, 0.2)
    g_aux = gravity_aux_mps2(rng.normal(0, 0.03), rng.normal(0, 0.03), rng.uniform(-math.pi, math.pi))
    h = rng.normal(0.0, 0.02, 4)
    hd = rng.normal(0.0, 0.1, 4)
    slip = rng.choice([-1.0, 1.0], 4) * rng.uniform(0.006, 0.05, 4)
    alpha = rng.normal(0.0, 0.03, 4)
    steer = rng.normal(0.0, 0.05)
    delta = np.array([steer * 1.08, steer * 0.93, 0.0, 0.0] if ackermann else [steer, steer, 0.0, 0.0])
    torque = rng.normal(0.0, 300.0, 4)
    omega = rng.normal(0.0, 0.3, 3) * np.array([1.0, pitch_scale, 1.0])
    vals = dict(slip=slip, alpha=alpha, delta=delta, h=h, hd=hd, omega=omega, speed=speed)
    vals.update(override)
    slip, alpha, delta, h, hd, omega, speed = (vals[n] for n in ("slip", "alpha", "delta", "h", "hd", "omega", "speed"))

    c_l = np.array(true.tracking_stiffness_n)
    c_a = np.array([true.cornering_stiffness_front_nprad] * 2 + [true.cornering_stiffness_rear_nprad] * 2) / 2
    f_wheel = np.stack([c_l * slip, c_a * alpha], axis=1)  # (F_a, F_b) per wheel
    f_body = np.array([[[math.cos(d), -math.sin(d)], [math.sin(d), math.cos(d)]] @ f for d, f in zip(delta, f_wheel)])
    wheel_acc = (torque - r * f_wheel[:, 0]) / iw
    m = true.mass_kg
    xdd = f_body[:, 0].sum() / m + g_aux[0] + yd * psid
    ydd = f_body[:, 1].sum() / m + g_aux[1] - speed * psid
    fz_body, fz_total = np.zeros(4), np.zeros(4)
    for i in range(4):
        ax = MODEL.front if i < 2 else MODEL.rear
        hs = ax.static_compression_m + h[i]
        k_s = ax.spring_c1_npm * math.exp(ax.spring_c2_per_m * (hs - ax.spring_c3_m))
        fz_body[i] = k_s * hs + ax.damper_nspm * hd[i]
        fz_total[i] = fz_body[i] + ax.unsprung_mass_kg * G
    # the struts carry the sprung mass (the physics core, eq 20's "sprung" form): m_s (zdd - G_z) = sum F_s
    zdd = fz_body.sum() / (m - MODEL.unsprung_mass_total_kg) + g_aux[2]
    moment = np.zeros(3)
    a_minus_g = np.array([f_body[:, 0].sum() / m, f_body[:, 1].sum() / m, 0.0])  # horizontal
    for i, ((x, y), fb, fz) in enumerate(zip(geo.corner_xy_m(), f_body, fz_body)):
        moment += _cross([x, y, -geo.h_cg_m], [fb[0], fb[1], fz])  # strut + tire forces
        mu = (MODEL.front if i < 2 else MODEL.rear).unsprung_mass_kg  # unsprung d'Alembert force
        moment += _cross([x, y, -(geo.h_cg_m - r) + h[i]], -mu * a_minus_g)
    inertia = np.diag([true.inertia_x_kgm2, true.inertia_y_kgm2, true.inertia_z_kgm2])
    omega_dot = np.linalg.solve(inertia, moment - _cross(omega, inertia @ omega))
    return IdentInputs(
        t_ns=int(k * 10_000_000), xdd_a_mps2=xdd, ydd_a_mps2=ydd, zdd_a_mps2=zdd, xd_a_mps=speed,
        yd_a_mps=yd, psi_v_dot_radps=psid, gravity_aux_mps2=g_aux, omega_radps=tuple(omega),
        omega_dot_radps2=tuple(omega_dot), susp_deflection_m=tuple(h), susp_rate_mps=tuple(hd),
        wheel_speed_radps=tuple(speed * (1 + slip) / r), wheel_accel_radps2=tuple(wheel_acc),
        wheel_torque_nm=tuple(torque), slip_ratio=tuple(slip), slip_angle_rad=tuple(alpha),
        wheel_angle_rad=tuple(delta))


def rel_err(params, true=TRUE):
    return {n: getattr(params, n) / getattr(true, n) - 1.0 for n in PARAM_NAMES}
