"""The ``/est/`` layout of a replay's output recording: each output of the Figure 2 node
(``pipeline``) as ``(topic, t_ns, values, sigmas)`` documents (``est_docs``) and written to a
``RecordingWriter`` (``write_output``), the same for ``vdps replay``, ``vdps log --pipeline`` and
the bench.

==========================  =================================================================
output                      topic
==========================  =================================================================
``Estimate``                ``/est/state``: the 12 states of eq 7 and the vehicle angles of
                            eq 4, with sigmas
``Innovation``              ``/est/innovation/<kind>``: innovation, NIS, gate, status code
``FilteredSignals``         ``/est/filtered``: the alpha-beta outputs
``IdentReport``             ``/est/ident``: parameters with sigmas, identifiability, converged,
                            ``status_<param>`` (``PARAM_STATUS``)
``PredictionReport``        ``/est/prediction``: TTR, peak LTR, peak roll
``CanFrame``                ``/est/can/<bus>`` (vdps.RawCan.v1, direction tx)
==========================  =================================================================
"""

from __future__ import annotations

import math

from vdps_hil.estimation.estimates import Estimate, FilteredSignals, Innovation
from vdps_hil.estimation.states import STATE_NAMES
from vdps_hil.identification.status import CAUSES, IDENTIFIED
from vdps_hil.pipeline.outputs import CanFrame, IdentReport, PredictionReport

__all__ = ["INNOVATION_STATUS", "PARAM_STATUS", "est_docs", "write_output"]

INNOVATION_STATUS = ("accepted", "gated", "nan", "too_old", "disabled", "not_initialized")
"""``status_code`` of ``/est/innovation/<kind>`` messages: index in this tuple."""

PARAM_STATUS = (IDENTIFIED, *CAUSES)
"""``status_<param>`` of ``/est/ident`` messages: index in this tuple (0: identified)."""

_STATE_KEYS = (*STATE_NAMES, "phi_v_rad", "theta_v_rad", "psi_v_rad")
"""Keys of /est/state: the 12 states of eq 7 and the vehicle angles of eq 4."""
_INNOVATION_KEYS = tuple(f"innovation_{i}" for i in range(8))
_FILTERED_SIZES = (3, 3, 4, 4, 4, 4, 4)
_FILTERED_KEYS = (*(f"{stem}_{a}" for stem in ("angular_rate_radps", "angular_accel_radps2") for a in "xyz"),
                  *(f"{stem}_{i}" for stem in ("wheel_speed_radps", "wheel_accel_radps2", "susp_deflection_m",
                                               "susp_rate_mps", "wheel_torque_nm") for i in range(1, 5)),
                  "steer_wheel_angle_rad")
"""Keys of /est/filtered in the order the general loop of ``est_docs`` writes them."""


def est_docs(o) -> list[tuple[str, int, dict, dict | None]]:
    """(topic, t_ns, values, sigmas) documents of one system output for ``/est/``."""
    if isinstance(o, Estimate):
        names = _STATE_KEYS
        vals = dict(zip(names, (*o.x, *o.vehicle_angles_rad)))
        sig = dict(zip(names, (*o.sigma, *o.vehicle_angles_sigma_rad)))
        return [("/est/state", o.t_ns, vals, sig)]
    if isinstance(o, Innovation):
        vals = {"nis": o.nis, "dof": float(o.dof), "gate": o.gate,
                "status_code": float(INNOVATION_STATUS.index(o.status)) if o.status in INNOVATION_STATUS else -1.0,
                "accepted": 1.0 if o.status == "accepted" else 0.0, "delayed": 1.0 if o.delayed else 0.0}
        sig = {}
        for i, (v, s) in enumerate(zip(o.innovation, o.innovation_sigma)):
            k = _INNOVATION_KEYS[i] if i < len(_INNOVATION_KEYS) else f"innovation_{i}"
            vals[k] = v
            sig[k] = s
        return [(f"/est/innovation/{o.kind}", o.t_ns, vals, sig)]
    if isinstance(o, FilteredSignals):
        groups = (o.angular_rate_radps, o.angular_accel_radps2, o.wheel_speed_radps, o.wheel_accel_radps2,
                  o.susp_deflection_m, o.susp_rate_mps, o.wheel_torque_nm)
        if tuple(len(g) for g in groups) == _FILTERED_SIZES:  # the keys below, precomputed
            return [("/est/filtered", o.t_ns, dict(zip(_FILTERED_KEYS, (*groups[0], *groups[1], *groups[2],
                     *groups[3], *groups[4], *groups[5], *groups[6], o.steer_wheel_angle_rad))), None)]
        vals = {}
        for stem, v in (("angular_rate_radps", o.angular_rate_radps), ("angular_accel_radps2", o.angular_accel_radps2)):
            vals.update({f"{stem}_{a}": x for a, x in zip("xyz", v)})
        for stem, v in (("wheel_speed_radps", o.wheel_speed_radps), ("wheel_accel_radps2", o.wheel_accel_radps2),
                        ("susp_deflection_m", o.susp_deflection_m), ("susp_rate_mps", o.susp_rate_mps),
                        ("wheel_torque_nm", o.wheel_torque_nm)):
            vals.update({f"{stem}_{i}": x for i, x in enumerate(v, 1)})
        vals["steer_wheel_angle_rad"] = o.steer_wheel_angle_rad
        return [("/est/filtered", o.t_ns, vals, None)]
    if isinstance(o, IdentReport):
        vals = dict(o.params)
        vals.update({f"identifiability_{k}": v for k, v in o.identifiability.items()})
        vals.update({f"converged_{k}": 1.0 if v else 0.0 for k, v in o.converged.items()})
        vals.update({f"updates_{k}": float(v) for k, v in o.updates.items()})
        vals.update({f"status_{k}": float(PARAM_STATUS.index(v)) for k, v in (o.param_status or {}).items()})
        return [("/est/ident", o.t_ns, vals, dict(o.sigmas))]
    if isinstance(o, PredictionReport):
        nan = math.nan
        vals = {"time_to_point_of_no_return_s": nan if o.time_to_point_of_no_return_s is None
                else o.time_to_point_of_no_return_s,
                "time_to_tip_up_s": nan if o.time_to_tip_up_s is None else o.time_to_tip_up_s,
                "peak_ltr": o.peak_ltr, "peak_roll_rad": o.peak_roll_rad, "horizon_s": o.horizon_s}
        return [("/est/prediction", o.t0_ns, vals, None)]
    return []


def write_output(o, writer) -> None:
    """One system output into a RecordingWriter in the ``vdps replay`` layout: a ``CanFrame`` on
    ``/est/can/<bus>`` (vdps.RawCan.v1, tx), the others by ``est_docs``."""
    from vdps_hil.record import schemas as S

    if isinstance(o, CanFrame):
        doc = S.raw_can_doc(o.t_ns, o.arbitration_id, o.data, direction="tx")
        writer.write_json(f"/est/can/{o.bus}", S.RAW_CAN, o.t_ns, doc, channel_metadata={"bus": o.bus})
        return
    for topic, t, vals, sig in est_docs(o):
        writer.write_estimate(topic, t, vals, sig)
