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
    # Keys are the layout names used by vdps_hil.codecs.nmea (ParsedSentence.sentence).
    # has_roll: the layout carries a measured roll in its standard installation (an INS, or a
    # two-antenna receiver whose single baseline runs along the vehicle and so measures pitch).
    "PASHR": AttitudeSign(
        sentence="PASHR",
        pitch_to_paper=1.0,
        roll_to_paper=1.0,
        has_roll=True,
        source=(
            "OxTS RT3000 v4 User Manual, Appendix B 'Using the orientation measurements': heading, "
            "pitch, roll are consecutive rotations taking the NED navigation frame to the OxTS "
            "vehicle frame (Table 20 'Vehicle frame definition': x forward, y right, z down), "
            "V_n = Rz(heading) Ry(pitch) Rx(roll) V_b, so positive pitch is nose up and positive "
            "roll is right side down; the bare $PASHR (time, heading, T, roll, pitch, heave, "
            "roll/pitch/heading accuracy, GNSS quality, INS status) prints these angles. Same "
            "layout and Tait-Bryan angles in the Applanix POS MV V5 Installation and Operation "
            "Guide, Table 20 '$PASHR Sentence Format' (vessel frame x fore, y starboard, z down, "
            "POS MV V4 User Guide 'Right-Hand Orthogonal System') and NovAtel OEM7 log PASHR "
            "(signs always printed). Cross-check on the real OxTS file rst39.nmea: roll goes "
            "negative while the car turns right at about 18 deg/s (body rolls out of the turn, "
            "left side down) and positive again as the turn ends."
        ),
    ),
    "PASHR,HPR": AttitudeSign(
        sentence="PASHR,HPR",
        pitch_to_paper=1.0,
        roll_to_paper=1.0,
        has_roll=False,
        source=(
            "Spectra Geospatial SP90m Product Manual, 'HPR: True Heading' ($PASHR,HPR,time, "
            "heading, pitch, roll, carrier RMS, baseline RMS, ambiguity, mode, antenna setup, "
            "PDOP; 'delivers either pitch OR roll angles, not both at the same time, depending "
            "on how the antennas are installed'); Spectra Precision ProFlex 800 Reference "
            "Manual, web-server 'Heading' page (heading is the direction Antenna 2 -> Antenna 1; "
            "Antenna 1 ahead for heading+pitch, on the right for heading+roll). No sign "
            "definition of pitch or roll found in these manuals: ASSUMED pitch positive when "
            "the forward antenna is higher (nose up) and roll positive right side down "
            "(aerospace/NMEA sense); verify once on a tilted vehicle. has_roll False: the "
            "standard along-track baseline measures pitch only."
        ),
    ),
    "HPR": AttitudeSign(
        sentence="HPR",
        pitch_to_paper=1.0,
        roll_to_paper=1.0,
        has_roll=False,
        source=(
            "Unicore N4 High Precision Commands and Logs reference book, GPHPR/GNHPR (utc, "
            "heading, pitch, roll, QF, SatNo, age, stnID) and Unicore Reference Commands Manual "
            "section 1.4 'Heading Configuration' (heading = angle clockwise from true north to "
            "the base -> rover baseline); same layout in the ComNav OEM Board Reference Manual "
            "4.3.1.2.6 'GPHPR Parameters of Attitude Angles'. No vendor definition of the "
            "pitch/roll signs found: ASSUMED pitch = elevation of the base -> rover baseline "
            "with the rover antenna ahead (positive nose up) and roll positive right side down. "
            "has_roll False: two antennas measure heading and pitch only."
        ),
    ),
    "PTNL,AVR": AttitudeSign(
        sentence="PTNL,AVR",
        pitch_to_paper=1.0,
        roll_to_paper=1.0,
        has_roll=False,
        source=(
            "Trimble R750 / SPSx51 NMEA-0183 output, 'PTNL,AVR - Time, yaw, tilt/roll, range "
            "for moving baseline RTK' (yaw,Yaw,tilt,Tilt,roll,Roll,range,quality,PDOP,sats; the "
            "examples fill either the Tilt or the Roll slot). Trimble does not state the signs: "
            "ASSUMED yaw clockwise from true north like a heading, tilt = elevation of the "
            "moving-base -> rover vector with the rover antenna ahead (pitch, positive nose "
            "up), roll positive right side down. has_roll False: the standard installation "
            "fills the Tilt slot; a sentence whose labelled Roll slot is filled is decoded as "
            "roll (ParsedSentence.has_roll)."
        ),
    ),
}

