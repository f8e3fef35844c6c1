"""Reading the GNSS and chassis samples of the estimator pipeline: catalogue fields
(``vdps_hil.bus.samples``) -> checked quantities, with the pipeline's defaults where a sample
carries no sigma of its own (IMU samples: ``imu_input``).

``gnss_fix``: lat/lon/alt plus the geoid separation (0 when absent) -> height above the
ellipsoid -> ENU about the origin (the given one, or the first valid fix); a fix with a latitude
or longitude out of range, a non-finite value or a fix quality <= 0 is refused.
``attitude_sigmas``: the per-axis sigmas of a multi-antenna attitude.
``suspension_deflections``, ``wheel_torques``: the four corners (order FL FR RR RL);
``wheel_speeds``: the wheels a sample carries (a CAN frame carries two of the four).
"""

from __future__ import annotations

import math

from vdps_hil.bus.samples import wheel_fields
from vdps_hil.geodesy import EnuOrigin

_SUSP = wheel_fields("susp_deflection_m")
_WS_INDEX = {n: i for i, n in enumerate(wheel_fields("wheel_speed_radps"))}
_WT = wheel_fields("wheel_torque_nm")
_NAN = math.nan


def gnss_fix(fields, origin: EnuOrigin | None, sigma_h_m: float, sigma_v_m: float):
    """(origin, enu [m], sigma_h [m], sigma_v [m]) of a ``gnss_pos`` sample, or None when refused
    (module docstring); the origin is ``origin`` or, when None, this fix."""
    g = fields.get
    lat, lon, alt = g("gnss_lat_deg", _NAN), g("gnss_lon_deg", _NAN), g("gnss_alt_m", _NAN)
    sep = g("gnss_geoid_sep_m", 0.0)
    q = g("gnss_fix_quality", 1.0)
    if not math.isfinite(sep):
        sep = 0.0
    if not (math.isfinite(lat + lon + alt) and abs(lat) <= 90.0 and abs(lon) <= 180.0) or not (q > 0):
        return None
    h = alt + sep
    if origin is None:
        origin = EnuOrigin(lat, lon, h)
    enu = origin.to_enu(lat, lon, h)
    sh = g("gnss_pos_sigma_h_m", sigma_h_m)
    sv = g("gnss_pos_sigma_v_m", sigma_v_m)
    if not (sh > 0 and math.isfinite(sh)):
        sh = sigma_h_m
    if not (sv > 0 and math.isfinite(sv)):
        sv = sigma_v_m
    return origin, enu, sh, sv


def attitude_sigmas(fields, default_rad: float) -> list[float]:
    """[sigma_roll, sigma_pitch, sigma_yaw] [rad] of a ``gnss_att`` sample (``default_rad`` where
    a sigma is absent, not positive or not finite)."""
    g = fields.get
    sig = []
    for name in ("gnss_roll_sigma_rad", "gnss_pitch_sigma_rad", "gnss_yaw_sigma_rad"):
        v = g(name, default_rad)
        sig.append(v if (v > 0 and math.isfinite(v)) else default_rad)
    return sig


def suspension_deflections(fields) -> list[float] | None:
    """The four deflections H_i [m] (compression positive), or None unless all are finite."""
    g = fields.get
    h = [g(n, _NAN) for n in _SUSP]
    return h if math.isfinite(sum(h)) else None


def wheel_speeds(fields) -> tuple[list[int], list[float]]:
    """(wheel indices, wheel speeds [rad/s]) of the wheels the sample carries (values unchecked)."""
    idx, vals = [], []
    for name, v in fields.items():
        i = _WS_INDEX.get(name)
        if i is not None:
            idx.append(i)
            vals.append(v)
    return idx, vals


def wheel_torques(fields) -> list[float] | None:
    """The four wheel torques [N m] (NaN where absent), or None when none is finite."""
    g = fields.get
    vals = [g(n, _NAN) for n in _WT]
    return vals if any(math.isfinite(v) for v in vals) else None
