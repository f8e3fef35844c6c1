"""Re-export of :mod:`vdps_hil.model.rollover`, where rollover is defined once for the whole
project (the predictor uses the same definitions and must not import ``sim``)."""

from vdps_hil.model.rollover import (SPIN_OUT_SIDESLIP_RAD, TIP_UP_LOAD_FRACTION,  # noqa: F401
                                     TIP_UP_MIN_DURATION_S, RolloverAssessment, RolloverEvent,
                                     RolloverMonitor, assess, classify_outcome,
                                     static_tip_angle_rad, with_static_stability_factor)
