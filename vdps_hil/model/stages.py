"""The stages of the physics core's f(x, u, p, env) -> x_dot (paper eq 13-17), one function per
stage, composed by :func:`derivative_function` for both variants of :class:`vdps_hil.model.core.Model`
(the truth simulator's ``unsprung_dof=True`` and the paper's reduced model ``unsprung_dof=False``).

The order of one evaluation (symbols and the model's assumptions: :mod:`vdps_hil.model.core`)::

    body_attitude        C_g^v (eq 1), road normal n_b, gravity g_b, CG height over the road
    ackermann_angles     front road-wheel angles from the bicycle angle
    corner_loads         per corner: wheel-centre position and velocity, suspension deflection,
                         normal load (eq 14; with unsprung DOF: tire radial spring), C_alpha,i,
                         anti-roll bar forces (``model.chassis``, if the vehicle has bars)
    compliance_steer_angle   delta_c = -K_c (F_b,1 + F_b,2) (secant solve)
    tire_at_corner       road-plane tire axes, slips and tire forces (eq 15-16)
    corner_wrench        tire forces -> body force and moment about the CG; wheel spin (eq 13)
    effect_wrench        effects' body wrench at the air velocity
    body_accelerations   translation a = F/m + g_b, unsprung-mass moments, Euler's equations
    pose_rates           dp_g/dt = (C_g^v)^T v_b, d(euler)/dt = C_omega^-1 omega
    unsprung_accelerations  H_ddot_i (unsprung DOF only)

Every stage works on plain floats and tuples (no numpy): :func:`derivative_function` is called
some 10^4-10^5 times per simulated drive. Tuples passed between the stages:

* a **corner constant** (``CoreConstants.corners``, one per corner i = 0..3 FL FR RR RL):
  ``(i, x_i, y_i, m_u,i, C1, C2, C3, static compression, D_s, r_i, r_free,i, C_kappa,i,
  C_alpha,i, F_z0,i, m_u,i g)``;
* a **corner state** (``corner_loads``): ``(i, x_i, y_i, z_i, h_w,i, F_z,i, F_s,i, H_i,
  H_dot_i, v_w,i (3), r_i, C_kappa,i, C_alpha,i, F_z0,i)`` with z_i the wheel centre's body z,
  h_w,i its height over the road along n, F_s,i the suspension force;
* a **wrench** ``(F_x, F_y, F_z, M_x, M_y, M_z)`` in body axes about the sprung CG [N, N m].

The stages on floats and tuples alone (``spring_force_n``, ``ackermann_angles``, ``steer_angles``,
``body_attitude``, ``wheel_axes``, ``air_velocity_b``, ``pose_rates``) and the chassis laws they
call (``model.chassis``) are :func:`~vdps_hil.jit.inline`: the compiled core
(:mod:`vdps_hil.model.core_kernel`) calls these very functions; the others it mirrors operation
for operation (tested bit for bit equal to ``derivative_function``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from vdps_hil.jit import inline

from .chassis import anti_roll_forces_n, blend_ackermann, roll_centre_forces_n
from .frames import dcm_gv_elements


@inline
def spring_force_n(h_spring_m: float, c1: float, c2: float, c3: float) -> float:
    """Eq 14 spring: K_s H with K_s = C1 exp(C2 (H - C3)); H compression from free length [m].
    Negative H (extension past free length) gives tension, standing in for the rebound stop."""
    return c1 * math.exp(c2 * (h_spring_m - c3)) * h_spring_m


@inline
def ackermann_angles(delta_mean_rad: float, wheelbase_m: float, track_half_front_m: float) -> tuple[float, float]:
    """Front road-wheel angles (delta_1 FL, delta_2 FR) [rad] for a bicycle-model angle
    delta_m: tan delta_1,2 = L tan delta_m / (L -+ t_f tan delta_m) (full Ackermann)."""
    tm = math.tan(delta_mean_rad)
    return (math.atan2(wheelbase_m * tm, wheelbase_m - track_half_front_m * tm),
            math.atan2(wheelbase_m * tm, wheelbase_m + track_half_front_m * tm))


@inline
def steer_angles(delta_mean_rad: float, wheelbase_m: float, track_half_front_m: float,
                 ackermann_fraction: float) -> tuple[float, float]:
    """``ackermann_angles`` blended with parallel steer by the vehicle's Ackermann fraction
    (``chassis.blend_ackermann``; 1: full Ackermann, the angles unchanged)."""
    d1, d2 = ackermann_angles(delta_mean_rad, wheelbase_m, track_half_front_m)
    return blend_ackermann(delta_mean_rad, d1, d2, ackermann_fraction)


@dataclass(frozen=True, slots=True)
class CoreConstants:
    """What f needs that depends only on the model (built once by ``Model``; SI units).

    ``inertia``: (I_y - I_z)/I_x, (I_z - I_x)/I_y, (I_x - I_y)/I_z, 1/I_x, 1/I_y, 1/I_z;
    ``zw0``: body z of the wheel centres at design ride height [m]; ``r_load``: rolling radius
    of the rigid tire (reduced model) [m]; ``corner_masses``: (i, x_i, y_i, m_u,i) per corner;
    the effect hooks as tuples of bound methods; ``k_c``: summed compliance steer [rad/N];
    ``wind_effects``: the effects' own wind, ENU [m/s]; the chassis parts (``model.chassis``):
    ``ackermann_fraction`` [-], ``arb`` = (K_arb,f, K_arb,r [N m/rad], T_f, T_r [m]) or None,
    ``roll_centre`` = (h_rc,f, h_rc,r, T_f, T_r [m]) or None (None: the paper's model)."""

    unsprung_dof: bool
    g: float
    inv_m_tot: float
    inv_m_s: float
    inertia: tuple
    iw_inv: float
    tire_radial_stiffness: float
    wheelbase_m: float
    track_half_front_m: float
    steer_ratio: float
    zw0: float
    r_load: float
    v_floor: float
    brake_hold_radps: float
    corners: tuple
    corner_masses: tuple
    tire_fn: Callable
    stiffness_fns: tuple
    wrench_fns: tuple
    wheel_fns: tuple
    k_c: float
    wind_effects: tuple
    ackermann_fraction: float = 1.0
    arb: tuple | None = None
    roll_centre: tuple | None = None


@inline
def body_attitude(pos, euler, normal_g, g: float):
    """Eq 1 and the road plane at the body: ``((sin phi, cos phi, sin theta, cos theta), C, n_b,
    g_b, h_cg)`` with C = C_g^v (9 elements row by row), n_b = C n_g the road normal in body
    axes, g_b = C [0, 0, -g] and h_cg = n_g . p_g the CG height over the road plane (through
    the origin)."""
    pe, pn, pu = pos
    phi, theta, psi = euler
    sph, cph = math.sin(phi), math.cos(phi)
    sth, cth = math.sin(theta), math.cos(theta)
    sps, cps = math.sin(psi), math.cos(psi)
    c = dcm_gv_elements(sph, cph, sth, cth, sps, cps)
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c
    ng0, ng1, ng2 = normal_g
    n_b = (c00 * ng0 + c01 * ng1 + c02 * ng2, c10 * ng0 + c11 * ng1 + c12 * ng2,
           c20 * ng0 + c21 * ng1 + c22 * ng2)
    g_b = (-g * c02, -g * c12, -g * c22)
    return (sph, cph, sth, cth), c, n_b, g_b, pe * ng0 + pn * ng1 + pu * ng2


def corner_loads(k: CoreConstants, susp, susp_rate, h_cg: float, n_b, vel, rate) -> list:
    """Corner states: wheel-centre position and velocity, suspension deflection and normal load
    of each corner, then C_alpha,i *= each cornering_stiffness_factor(i, F_z,i, F_z0,i).

    With unsprung DOF (the truth simulator; ``susp``, ``susp_rate`` = H_i, H_dot_i): the wheel
    centre slides along the body z axis, the tire is a radial spring (lift-off: deflection <= 0
    gives F_z = 0), the suspension force is eq 14's spring law plus the damper::

        z_i = z_w0 + H_i,   h_w,i = h_cg + n_b . (x_i, y_i, z_i)
        F_z,i = k_t (r_free,i - h_w,i)  if positive, else 0
        F_s,i = K_s(H_s) H_s + D_s H_dot_i + F_arb,i,   H_s = static compression + H_i
        v_w,i = v_b + omega x r_w,i + H_dot_i e_z

    The paper's reduced model (``susp`` None; rigid tires, unsprung masses moving with the body):
    the deflection follows from the pose over the road plane, the load is eq 14 with its clamp::

        h_w,i = h_cg + n_b . (x_i, y_i, z_w0),   v_w,i = v_b + omega x r_w,i
        H_i = r - h_w,i,   H_dot_i = -n_b . v_w,i
        F_z,i = 0                                          if K_s(H_s) H_s + m_u g <= 0 (lifted)
              = max(0, K_s(H_s) H_s + D_s H_dot_i + m_u g)   otherwise;   F_s,i = F_z,i

    (with anti-roll bars F_arb,i of ``chassis.anti_roll_forces_n`` is added to K_s(H_s) H_s)."""
    nx, ny, nz = n_b
    vx, vy, vz = vel
    wx, wy, wz = rate
    dof, zw0, stiff_fns = k.unsprung_dof, k.zw0, k.stiffness_fns
    kt, r_load = k.tire_radial_stiffness, k.r_load
    farb = None if k.arb is None else _anti_roll(k, susp, h_cg, n_b)
    ck = []
    for (i, xi, yi, mu, c1, c2, c3, sc, ds, ri, rfree, ckap, calp, fz0, mug) in k.corners:
        if dof:
            H = susp[i]
            Hd = susp_rate[i]
            zi = zw0 + H
            hw = h_cg + nx * xi + ny * yi + nz * zi
            defl = rfree - hw
            fz = kt * defl if defl > 0.0 else 0.0
            fs = spring_force_n(sc + H, c1, c2, c3) + ds * Hd
            if farb is not None:
                fs += farb[i]
            vwx = vx + wy * zi - wz * yi
            vwy = vy + wz * xi - wx * zi
            vwz = vz + wx * yi - wy * xi + Hd
        else:
            zi = zw0
            hw = h_cg + nx * xi + ny * yi + nz * zi
            vwx = vx + wy * zi - wz * yi
            vwy = vy + wz * xi - wx * zi
            vwz = vz + wx * yi - wy * xi
            H = r_load - hw
            Hd = -(nx * vwx + ny * vwy + nz * vwz)
            fsp = spring_force_n(sc + H, c1, c2, c3)
            if farb is not None:
                fsp += farb[i]
            if fsp + mug <= 0.0:  # eq 14 clamp: lift-off
                fz = 0.0
            else:
                fz = fsp + ds * Hd + mug
                if fz < 0.0:
                    fz = 0.0
            fs = fz
        for sf in stiff_fns:
            calp = calp * sf(i, fz, fz0)
        ck.append((i, xi, yi, zi, hw, fz, fs, H, Hd, vwx, vwy, vwz, ri, ckap, calp, fz0))
    return ck


@inline
def wheel_axes(delta: float, n_b) -> tuple[float, float, float, float, float, float]:
    """Eq 15-16's wheel axes in the road plane, body axes: ``(e_l (3), e_t (3))`` with
    e_l = unit((cos d, sin d, 0) - ((cos d, sin d, 0) . n) n) and e_t = n x e_l."""
    nx, ny, nz = n_b
    cd, sd = math.cos(delta), math.sin(delta)
    hn = cd * nx + sd * ny
    lx, ly, lz = cd - hn * nx, sd - hn * ny, -hn * nz
    inv = 1.0 / math.sqrt(lx * lx + ly * ly + lz * lz)
    lx, ly, lz = lx * inv, ly * inv, lz * inv
    return lx, ly, lz, ny * lz - nz * ly, nz * lx - nx * lz, nx * ly - ny * lx


def _anti_roll(k: CoreConstants, susp, h_cg: float, n_b) -> tuple:
    """F_arb,i (``chassis.anti_roll_forces_n``) from the deflections: the states (unsprung DOF)
    or, in the reduced model, H_i = r - h_w,i of the pose over the road plane."""
    if susp is None:
        nx, ny, nz = n_b
        zw0, r = k.zw0, k.r_load
        susp = [r - (h_cg + nx * c[1] + ny * c[2] + nz * zw0) for c in k.corners]
    kf, kr, tf, tr = k.arb
    return anti_roll_forces_n(kf, kr, tf, tr, susp)


def tire_at_corner(c, delta: float, n_b, oms, v_floor: float, tire_fn):
    """Eq 15-16 at one corner state ``c`` with road-wheel angle ``delta``:
    ``(F_a, F_b, kappa, alpha, e_l (3), e_t (3))``::

        e_l = unit((cos d, sin d, 0) - ((cos d, sin d, 0) . n) n),  e_t = n x e_l
        v_l = v_w . e_l,  v_t = v_w . e_t,  den = max(|v_l|, v_floor)
        kappa = (r_i omega_i - v_l) / den,  alpha = -atan(v_t / den)
        F_a, F_b = tire_fn(F_z, F_z0, kappa, alpha, C_kappa, C_alpha)"""
    (i, xi, yi, zi, hw, fz, fs, H, Hd, vwx, vwy, vwz, ri, ckap, calp, fz0) = c
    lx, ly, lz, tx, ty, tz = wheel_axes(delta, n_b)
    vl = vwx * lx + vwy * ly + vwz * lz
    vt = vwx * tx + vwy * ty + vwz * tz
    den = vl if vl > 0.0 else -vl
    if den < v_floor:
        den = v_floor
    kap = (ri * oms[i] - vl) / den
    alp = -math.atan(vt / den)
    fa, fb = tire_fn(fz, fz0, kap, alp, ckap, calp)
    return fa, fb, kap, alp, lx, ly, lz, tx, ty, tz


def compliance_steer_angle(k_c: float, front, d1: float, d2: float, n_b, oms, v_floor: float, tire_fn) -> float:
    """Steering compliance: the angle delta_c added to both front wheels that solves
    delta_c = -K_c (F_b,1(d_1 + delta_c) + F_b,2(d_2 + delta_c)), by one secant step from
    delta_c = 0 (exact when the lateral forces are linear in the angle). ``front``: the corner
    states of the two front wheels."""
    c0, c1 = front

    def resid(dc):
        return dc + k_c * (tire_at_corner(c0, d1 + dc, n_b, oms, v_floor, tire_fn)[1]
                           + tire_at_corner(c1, d2 + dc, n_b, oms, v_floor, tire_fn)[1])

    r0 = resid(0.0)
    dc1 = -r0
    r1 = resid(dc1)
    den = r1 - r0
    return dc1 - r1 * dc1 / den if den != 0.0 else dc1


def corner_wrench(k: CoreConstants, ck, deltas, n_b, oms, u, record: bool):
    """The tires' wrench on the body and the wheel spins (eq 13, eq 16)::

        F_tire,i = F_a e_l + F_b e_t + F_z n             at the contact point r_c = r_w - h_w n
        body force  sum F_tire,i   (unsprung DOF: body z gets F_s,i, the tire's body-z force goes
                                    to the unsprung mass, and F_s,i acts at the strut)
        body moment sum r_c,i x F_tire,i (+ r_w,i x (F_s,i - F_tz,i) e_z with unsprung DOF)
        I_w omega_dot_i = T_i - B_i sat(omega_i / 2 rad/s) - r_i F_a,i + T_eff,i

    With roll centres (``model.chassis``) the linkage's vertical forces J_i
    (``chassis.roll_centre_forces_n``, from each axle's lateral tire force in body axes) act on
    the body along its z axis at the struts (and, with unsprung DOF, -J_i on the unsprung mass;
    in the reduced model they are part of the reported normal load).

    Returns (wrench, omega_dot (4), tire body-z forces (4), per-corner records or None, the
    roll-centre forces J (4) or None)."""
    dof, v_floor, tire_fn = k.unsprung_dof, k.v_floor, k.tire_fn
    wheel_fns, iw_inv, wbrake = k.wheel_fns, k.iw_inv, k.brake_hold_radps
    nx, ny, nz = n_b
    torques, brakes = u.wheel_torque_nm, u.brake_torque_nm
    Fx = Fy = Fz = Mx = My = Mz = 0.0
    wdots = [0.0, 0.0, 0.0, 0.0]
    fzt = [0.0, 0.0, 0.0, 0.0]
    rec = [] if record else None
    for c in ck:
        (i, xi, yi, zi, hw, fz, fs, H, Hd, vwx, vwy, vwz, ri, ckap, calp, fz0) = c
        fa, fb, kap, alp, lx, ly, lz, tx, ty, tz = tire_at_corner(c, deltas[i], n_b, oms, v_floor, tire_fn)
        ftx = fa * lx + fb * tx + fz * nx
        fty = fa * ly + fb * ty + fz * ny
        ftz = fa * lz + fb * tz + fz * nz
        # contact point r_c = r_w - hw n
        rcx, rcy, rcz = xi - hw * nx, yi - hw * ny, zi - hw * nz
        Mx += rcy * ftz - rcz * fty
        My += rcz * ftx - rcx * ftz
        Mz += rcx * fty - rcy * ftx
        Fx += ftx
        Fy += fty
        if dof:
            Fz += fs
            # spring/damper at the strut; the tire's body-z force goes into the unsprung mass
            Mx += yi * (fs - ftz)
            My -= xi * (fs - ftz)
            fzt[i] = ftz
        else:
            Fz += ftz
        om = oms[i]
        tq = torques[i]
        b = brakes[i]
        if b != 0.0:
            s = om / wbrake
            tq -= b * (1.0 if s > 1.0 else (-1.0 if s < -1.0 else s))
        teff = 0.0
        for wf in wheel_fns:
            teff += wf(i, om, fz, ri)
        wdots[i] = (tq - ri * fa + teff) * iw_inv
        if rec is not None:
            rec.append((fa, fb, fz, kap, alp, H, Hd, tq, teff, deltas[i], ri, hw, fs, ftx, fty, ftz))
    if k.roll_centre is None:
        return (Fx, Fy, Fz, Mx, My, Mz), wdots, fzt, rec, None
    jac = _roll_centre(k, ck, deltas, n_b, oms)
    for (i, xi, yi, *_), j in zip(ck, jac):
        Fz += j
        Mx += yi * j
        My -= xi * j
        if rec is not None and not dof:
            r = rec[i]
            rec[i] = (*r[0:2], r[2] + j, *r[3:])
    return (Fx, Fy, Fz, Mx, My, Mz), wdots, fzt, rec, jac


def _roll_centre(k: CoreConstants, ck, deltas, n_b, oms) -> tuple:
    """J_i of ``chassis.roll_centre_forces_n`` from the axles' lateral tire forces (body y of
    F_a e_l + F_b e_t; the tire law evaluated again at each corner: only vehicles with roll
    centres pay for it)."""
    fy = [0.0, 0.0]
    for c in ck:
        fa, fb, _k, _a, lx, ly, lz, tx, ty, tz = tire_at_corner(c, deltas[c[0]], n_b, oms, k.v_floor, k.tire_fn)
        fy[0 if c[0] < 2 else 1] += fa * ly + fb * ty
    hf, hr, tf, tr = k.roll_centre
    return roll_centre_forces_n(hf, hr, tf, tr, fy[0], fy[1])


@inline
def air_velocity_b(vel, c, wind_env, wind_effects) -> tuple[float, float, float]:
    """Air velocity relative to the body, body axes: v_b - C_g^v (w_env + w_effects)."""
    vx, vy, vz = vel
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c
    we0, we1, we2 = wind_env
    we0 += wind_effects[0]
    we1 += wind_effects[1]
    we2 += wind_effects[2]
    return (vx - (c00 * we0 + c01 * we1 + c02 * we2),
            vy - (c10 * we0 + c11 * we1 + c12 * we2),
            vz - (c20 * we0 + c21 * we1 + c22 * we2))


def effect_wrench(wrench_fns, wrench, vel, rate, air):
    """``wrench`` plus each effect's ``body_wrench(v_b, omega, v_air)`` (force [N] and moment
    [N m] about the sprung CG, body axes), added in the effects' order."""
    Fx, Fy, Fz, Mx, My, Mz = wrench
    for wf in wrench_fns:
        ex, ey, ez, emx, emy, emz = wf(vel, rate, air)
        Fx += ex
        Fy += ey
        Fz += ez
        Mx += emx
        My += emy
        Mz += emz
    return Fx, Fy, Fz, Mx, My, Mz


def body_accelerations(k: CoreConstants, wrench, g_b, ck, rate):
    """Eq 13's balances of the sprung body: ``(a, omega_dot, M)``::

        a = F / m + g_b               (m = m_tot; with unsprung DOF m_s on the body z axis)
        M += sum r_w,i x m_u,i (g_b - a)   (unsprung masses' weight and translational inertia
                                            at the wheel centres; z-part 0 with unsprung DOF)
        I_x dp/dt = (I_y - I_z) q r + M_x, ...   (principal axes)"""
    Fx, Fy, Fz, Mx, My, Mz = wrench
    gx, gy, gz = g_b
    wx, wy, wz = rate
    dof = k.unsprung_dof
    inv_m_tot = k.inv_m_tot
    ax_ = Fx * inv_m_tot + gx
    ay_ = Fy * inv_m_tot + gy
    if dof:
        az_ = Fz * k.inv_m_s + gz
    else:
        az_ = Fz * inv_m_tot + gz
    for (i, xi, yi, mu) in k.corner_masses:
        zi = ck[i][3]
        ux, uy = mu * (gx - ax_), mu * (gy - ay_)
        uz = 0.0 if dof else mu * (gz - az_)
        Mx += yi * uz - zi * uy
        My += zi * ux - xi * uz
        Mz += xi * uy - yi * ux
    Iyz, Izx, Ixy, inv_Ix, inv_Iy, inv_Iz = k.inertia
    dw = (Iyz * wy * wz + Mx * inv_Ix, Izx * wz * wx + My * inv_Iy, Ixy * wx * wy + Mz * inv_Iz)
    return (ax_, ay_, az_), dw, (Mx, My, Mz)


@inline
def pose_rates(trig, c, vel, rate) -> tuple[float, float, float, float, float, float]:
    """dp_g/dt = (C_g^v)^T v_b and d(phi, theta, psi)/dt = C_omega^-1 omega
    (``frames.c_omega_inv``, consistent with eq 1)."""
    sph, cph, sth, cth = trig
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c
    vx, vy, vz = vel
    wx, wy, wz = rate
    tth = sth / cth
    return (c00 * vx + c10 * vy + c20 * vz, c01 * vx + c11 * vy + c21 * vz, c02 * vx + c12 * vy + c22 * vz,
            wx - tth * sph * wy - tth * cph * wz, -cph * wy + sph * wz, (sph * wy + cph * wz) / cth)


def unsprung_accelerations(k: CoreConstants, ck, fzt, acc, dw, rate, gz: float, jac=None) -> list[float]:
    """H_ddot_i of the unsprung masses (unsprung DOF only), from their balance along body z::

        m_u (a_z + (omega_dot x r_w)_z + (omega x (omega x r_w))_z + H_ddot) = F_tz' - F_s - J + m_u g_z

    (J_i the roll-centre forces of ``corner_wrench``, None: zero)."""
    wx, wy, wz = rate
    dwx, dwy, _ = dw
    az_ = acc[2]
    ww = wx * wx + wy * wy + wz * wz
    hdd = []
    for (i, xi, yi, mu) in k.corner_masses:
        zi = ck[i][3]
        acc_z = az_ + (dwx * yi - dwy * xi) + (wz * (wx * xi + wy * yi + wz * zi) - zi * ww)
        f_link = ck[i][6] if jac is None else ck[i][6] + jac[i]
        hdd.append((fzt[i] - f_link) / mu + gz - acc_z)
    return hdd


def derivative_function(k: CoreConstants) -> Callable:
    """``f(x, u, env, out=None) -> x_dot``: the stages above in order (module docstring).
    ``out``: optional dict filled with the diagnostics ``Model.evaluate`` names."""
    dof, g, v_floor, tire_fn, k_c = k.unsprung_dof, k.g, k.v_floor, k.tire_fn, k.k_c
    steer = (k.steer_ratio, k.wheelbase_m, k.track_half_front_m, k.ackermann_fraction)
    wrench_fns, wind_effects = k.wrench_fns, k.wind_effects

    def f(x, u, env, out=None):
        """x_dot = f(x, u, env). ``out``: optional dict filled with named diagnostics."""
        (pe, pn, pu, phi, theta, psi, vx, vy, vz, wx, wy, wz, om1, om2, om3, om4) = x[0:16]
        vel, rate, oms = (vx, vy, vz), (wx, wy, wz), (om1, om2, om3, om4)
        trig, c, n_b, g_b, h_cg = body_attitude((pe, pn, pu), (phi, theta, psi), env.normal_g, g)
        ratio, wheelbase, t_f, e_a = steer
        d1, d2 = steer_angles(u.steer_wheel_angle_rad / ratio, wheelbase, t_f, e_a)
        susp, susp_rate = (x[16:20], x[20:24]) if dof else (None, None)
        ck = corner_loads(k, susp, susp_rate, h_cg, n_b, vel, rate)
        dcomp = compliance_steer_angle(k_c, ck[0:2], d1, d2, n_b, oms, v_floor, tire_fn) if k_c != 0.0 else 0.0
        deltas = (d1 + dcomp, d2 + dcomp, 0.0, 0.0)
        wrench, wdots, fzt, rec, jac = corner_wrench(k, ck, deltas, n_b, oms, u, out is not None)
        if wrench_fns:
            air = air_velocity_b(vel, c, env.wind_enu_mps, wind_effects)
            wrench = effect_wrench(wrench_fns, wrench, vel, rate, air)
        acc, dw, moment = body_accelerations(k, wrench, g_b, ck, rate)
        ax_, ay_, az_ = acc
        xd = [*pose_rates(trig, c, vel, rate),
              ax_ - (wy * vz - wz * vy), ay_ - (wz * vx - wx * vz), az_ - (wx * vy - wy * vx),
              *dw, *wdots]
        if dof:
            xd.extend(x[20:24])
            xd.extend(unsprung_accelerations(k, ck, fzt, acc, dw, rate, g_b[2], jac))
        if out is not None:
            out["_rec"] = rec
            out["_acc_b"] = acc
            out["_g_b"] = g_b
            out["_force_b"] = wrench[0:3]
            out["_moment_b"] = moment
            out["_normal_b"] = n_b
            out["_height_cg"] = h_cg
            if out.get("_want_air", True):
                out["_air_b"] = air_velocity_b(vel, c, env.wind_enu_mps, wind_effects)
        return xd

    return f


__all__ = ["CoreConstants", "ackermann_angles", "steer_angles", "air_velocity_b", "body_accelerations", "body_attitude",
           "compliance_steer_angle", "corner_loads", "corner_wrench",
           "derivative_function", "effect_wrench", "pose_rates", "spring_force_n", "tire_at_corner",
           "unsprung_accelerations"]
