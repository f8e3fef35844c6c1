"""The spring law of eq 14 per corner of a vehicle: the suspension forces the identifier (eq 14,
eq 23's moments) and the suspension conditioning of the Figure-2 node both use.

    F_z,i = K_s,i(H_i) H_i + D_s,i Hd_i + F_arb,i + m_u,i g   (eq 14; K_s(H) H = ``stages.spring_force_n``)

F_arb,i = K_arb (H_i - H_j) / T^2: the anti-roll bar of the corner's axle, if the vehicle file
has one (``model.chassis.anti_roll_forces_n``; the deflections from design ride height).

==========  =====  ===================================================================
symbol      unit   meaning
==========  =====  ===================================================================
H_i         m      spring compression from its free length = static compression + the
                   measured deflection (from design ride height, compression positive)
Hd_i        m/s    deflection rate
K_s, D_s    -      the corner's spring law (``Axle.spring_c*``) and damper [N s/m]
m_u,i       kg     unsprung mass of the corner
==========  =====  ===================================================================
"""

from __future__ import annotations

import math

import numpy as np

from vdps_hil.model.chassis import anti_roll_forces_n
from vdps_hil.model.params import Vehicle
from vdps_hil.model.stages import spring_force_n
from vdps_hil.units import GRAVITY_MPS2

__all__ = ["spring_compression_m", "suspension_forces_n"]


def spring_compression_m(vehicle: Vehicle, susp_deflection_m) -> np.ndarray:
    """H of eq 14 (compression from the spring's free length) = static + deflection [m]."""
    static = np.array([vehicle.axle(i).static_compression_m for i in range(4)])
    return static + np.asarray(susp_deflection_m, dtype=float)


_CONSTANTS: dict[int, tuple] = {}  # id(vehicle) -> (vehicle, its corners' constants)
_MEMO: dict[tuple, np.ndarray] = {}  # the last results by (id(vehicle), deflections, rates, weight)
_LAST: list = [(None, None, None, None, None)]  # (vehicle, deflection and rate tuples, loads, struts) last made


def _corner_constants(vehicle: Vehicle) -> tuple:
    """Per corner (static compression, C1, C2, C3, damper, m_u g) and the anti-roll bars'
    (K_f, K_r, T_f, T_r) or None: read once per vehicle (a frozen file)."""
    hit = _CONSTANTS.get(id(vehicle))
    if hit is not None and hit[0] is vehicle:
        return hit[1]
    corners = tuple((ax.static_compression_m, ax.spring_c1_npm, ax.spring_c2_per_m, ax.spring_c3_m, ax.damper_nspm,
                     ax.unsprung_mass_kg * GRAVITY_MPS2) for ax in (vehicle.axle(i) for i in range(4)))
    ch, geo = vehicle.chassis, vehicle.geometry
    arb = ((ch.anti_roll_stiffness_front_nmprad, ch.anti_roll_stiffness_rear_nmprad, 2.0 * geo.track_half_front_m,
            2.0 * geo.track_half_rear_m) if ch.has_anti_roll_bars else None)
    if len(_CONSTANTS) > 16:
        _CONSTANTS.clear()
    _MEMO.clear()  # results are kept by id: none may outlive its vehicle's entry
    _CONSTANTS[id(vehicle)] = (vehicle, (corners, arb))
    return corners, arb


def suspension_forces_n(vehicle: Vehicle, susp_deflection_m, susp_rate_mps,
                        include_unsprung_weight: bool = True) -> np.ndarray:
    """Per corner [N], the spring law of eq 14 (``model.stages.spring_force_n``):

    * with the unsprung weight: F_z,spring,i = K_s H + D_s Hd + m_u g, the normal load of the
      paper's reduced model, with eq 14's clamp as the physics core applies it (lift-off when
      K_s H + m_u g <= 0, and never negative);
    * without: the strut force K_s H + D_s Hd acting on the sprung body (no clamp: tension past
      the free length stands in for the rebound stop, as in the core).

    The identifier asks for the same corners several times per input (its deflections and rates
    are tuples, the same objects): with and without the weight made at once, the last few results
    kept (the last by the tuples' identity) and a copy returned."""
    last = _LAST[0]  # one tuple, read and replaced whole
    if last[1] is susp_deflection_m and last[2] is susp_rate_mps and last[0] is vehicle:
        return (last[3] if include_unsprung_weight else last[4]).copy()
    key = None
    if type(susp_deflection_m) is tuple and type(susp_rate_mps) is tuple:
        key = (id(vehicle), susp_deflection_m, susp_rate_mps)
        hit = _MEMO.get(key + (bool(include_unsprung_weight),))
        if hit is not None and _CONSTANTS.get(id(vehicle), (None,))[0] is vehicle:
            return hit.copy()
    loads, struts = _forces(vehicle, susp_deflection_m, susp_rate_mps)
    if key is not None:
        if len(_MEMO) > 16:
            _MEMO.clear()
        _MEMO[key + (True,)], _MEMO[key + (False,)] = np.array(loads), np.array(struts)
        _LAST[0] = (vehicle, susp_deflection_m, susp_rate_mps, _MEMO[key + (True,)], _MEMO[key + (False,)])
    return np.array(loads if include_unsprung_weight else struts)


def _forces(vehicle: Vehicle, susp_deflection_m, susp_rate_mps) -> tuple[list[float], list[float]]:
    """(with the unsprung weight, without) per corner (``suspension_forces_n``)."""
    corners, arb = _corner_constants(vehicle)
    defl = [float(v) for v in susp_deflection_m]
    hd = [float(v) for v in susp_rate_mps]
    farb = None if arb is None else anti_roll_forces_n(*arb, defl)
    loads, struts = [math.nan] * 4, [math.nan] * 4
    for i in range(4):
        static, c1, c2, c3, damper, mug = corners[i]
        hs = static + defl[i]
        if not (math.isfinite(hs) and math.isfinite(hd[i])):
            continue
        fsp = spring_force_n(min(hs, 10.0), c1, c2, c3)
        if farb is not None:
            fsp += farb[i]
        struts[i] = fsp + damper * hd[i]
        loads[i] = 0.0 if fsp + mug <= 0.0 else max(fsp + damper * hd[i] + mug, 0.0)
    return loads, struts
