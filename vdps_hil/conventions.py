"""The conventions every part of vdps-hil agrees on. Mirrored in README section "Conventions".

Frames
------
* **Global frame {g}**: East-North-Up (ENU), metres. Origin: the scenario's reference point in
  simulation, the first valid GNSS fix for real data (``origin_from_first_fix``).
* **Road frame {r}** (paper section 2): rotated from {g} by the road grade theta_r and bank
  phi_r (order pitch-roll-yaw, eq 2); road curve angle psi_r = 0 (paper's assumption).
* **Vehicle frame {v}**: fixed at the sprung-mass centre of gravity, axes as ISO 8855:
  x forward, y left, z up.
* **Aux frame {a}**: road frame rotated about its z axis by psi_v so x_a is aligned with x_v
  (paper section 2); translational motion of eq 13 is written in it.

Rotation matrices (paper eq 1, printed signs kept literally)::

    R(x, phi)   = [[1, 0, 0], [0, c, s], [0, -s, c]]
    R(y, theta) = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    R(z, psi)   = [[c, s, 0], [-s, c, 0], [0, 0, 1]]

``C_a^b`` maps coordinates of a vector in frame a to coordinates in frame b (rows of C_g^v are
the vehicle axes written in the global frame).

Angle signs (what a positive angle means physically)
----------------------------------------------------
* yaw psi: counter-clockwise seen from above, zero when x_v points East.
* pitch theta: **nose up positive** (eq 1 as printed; equal to aerospace/NMEA pitch, and the
  negative of the ISO 8855 pitch angle). A road grade theta_r < 0 is downhill; the paper's
  scenario grade of -2 deg is downhill.
* roll phi: **right side down positive** (right-hand rotation about x forward; equals the ISO
  8855 and aerospace/NMEA roll sense). A road bank phi_r > 0 has its right edge low.

Where the paper disagrees with itself (listed, with what we implement):

* eq 7's C_omega is printed for the opposite pitch sign (ISO pitch). With eq 1 as printed the
  consistent matrix is ``C_omega = [[1, 0, sin(theta)], [0, -cos(phi), cos(theta) sin(phi)],
  [0, sin(phi), cos(theta) cos(phi)]]`` (derived and tested in ``model.frames``).
* eq 5's theta_v^sus uses (H1 + H2 - H3 - H4) with H compression positive (z_r^sus of eq 5 is
  only consistent with compression positive), which gives nose-down positive; we use
  theta_v = asin((-H1 - H2 + H3 + H4) / (2 l_f + 2 l_r)) to keep nose-up positive.
* eq 7's state list prints "theta 9r" for theta_r.

Wheels and corners
------------------
Index 1 front-left, 2 front-right, 3 rear-right, 4 rear-left (clockwise seen from above, paper
section 3.1.2). In code arrays are 0-based: ``WHEELS = ("fl", "fr", "rr", "rl")``.

Suspension: ``susp_deflection_m`` is measured from design ride height (static, nominal load),
**compression positive**. The spring law of eq 14 uses the compression from the spring's free
length: H_spring = static_compression_m + susp_deflection_m (the model file gives the static
compression per axle).

Time
----
Integer nanoseconds everywhere: ``t_ns`` (monotonic, orders samples), ``wall_time_ns`` (UTC, MCAP
``log_time``). Simulation time starts at t_ns = 0.

GNSS angles to paper angles
---------------------------
NMEA headings are degrees clockwise from true north; paper yaw psi = pi/2 - heading (wrapped to
[-pi, pi)). Vendor pitch/roll sign definitions are in ``ATTITUDE_SIGN`` (see the citations there
and ``codecs.nmea``): they map a sentence's printed pitch/roll to the paper's nose-up pitch and
right-side-down roll.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

WHEELS: tuple[str, ...] = ("fl", "fr", "rr", "rl")
"""Wheel/corner order 1..4 of the paper (clockwise from front-left), 0-based in arrays."""

FRONT = (0, 1)
REAR = (2, 3)
LEFT = (0, 3)
RIGHT = (1, 2)
WHEEL_SIDE_SIGN = (1.0, -1.0, -1.0, 1.0)
"""+1 for left wheels (y > 0 in ISO 8855), -1 for right wheels."""
WHEEL_AXLE_SIGN = (1.0, 1.0, -1.0, -1.0)
"""+1 for front wheels (x > 0), -1 for rear."""


def heading_to_yaw(heading_deg: float) -> float:
    """NMEA true heading [deg, clockwise from north, 0..360) -> paper yaw psi [rad, CCW from
    East, wrapped to [-pi, pi))."""
    psi = math.radians(90.0 - heading_deg)
    return (psi + math.pi) % (2.0 * math.pi) - math.pi


def yaw_to_heading(yaw_rad: float) -> float:
    """Paper yaw psi [rad] -> NMEA true heading [deg, 0 <= h < 360]."""
    h = (90.0 - math.degrees(yaw_rad)) % 360.0
    return 0.0 if h >= 360.0 else h


@dataclass(frozen=True)
class AttitudeSign:
    """Multipliers taking a sentence's printed pitch/roll to the paper's angles.

    ``pitch_to_paper`` multiplies the printed pitch to give nose-up-positive theta;
    ``roll_to_paper`` multiplies the printed roll to give right-side-down-positive phi.
    ``has_roll`` is False where the sentence carries no roll (a tilt slot, or none)."""

    sentence: str
    pitch_to_paper: float
    roll_to_paper: float
    has_roll: bool
    source: str


ATTITUDE_SIGN: dict[str, AttitudeSign] = {
    # One entry per attitude sentence layout, each citing the vendor's sign definition.
}

