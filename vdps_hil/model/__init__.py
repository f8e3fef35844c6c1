"""Vehicle model: frames and kinematics (eq 1-5, 7), parameters, the physics core and effects.

Depends on nothing of ours but ``vdps_hil.units`` and ``vdps_hil.conventions``."""
