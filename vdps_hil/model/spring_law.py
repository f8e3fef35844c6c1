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
    ch = vehicle.chassis
    farb = None
    if ch.has_anti_roll_bars:
        geo = vehicle.geometry
        farb = anti_roll_forces_n(ch.anti_roll_stiffness_front_nmprad, ch.anti_roll_stiffness_rear_nmprad,
                                  2.0 * geo.track_half_front_m, 2.0 * geo.track_half_rear_m,
                                  np.asarray(susp_deflection_m, dtype=float))
    out = np.empty(4)
    for i in range(4):
        ax = vehicle.axle(i)
        hs = float(h[i])
        if not (math.isfinite(hs) and math.isfinite(hd[i])):
            out[i] = math.nan
            continue
        fsp = spring_force_n(min(hs, 10.0), ax.spring_c1_npm, ax.spring_c2_per_m, ax.spring_c3_m)
        if farb is not None:
            fsp += float(farb[i])
        if not include_unsprung_weight:
            out[i] = fsp + ax.damper_nspm * hd[i]
            continue
        mug = ax.unsprung_mass_kg * GRAVITY_MPS2
        out[i] = 0.0 if fsp + mug <= 0.0 else max(fsp + ax.damper_nspm * hd[i] + mug, 0.0)
    return out
