"""Chassis parts every real car has and the paper's eq 13-16 model leaves out: anti-roll bars
(auxiliary roll stiffness), roll-centre heights, and the steering geometry (Ackermann fraction;
the steering ratio is ``Geometry.steer_ratio``). A vehicle file states them in an optional
``[chassis]`` table; without it (or with a part at its default) the model is the paper's: no
anti-roll bar, roll centres on the ground, full Ackermann -- bit for bit the model without this
module. A part that is *unknown* for a car is left out of its file; its effect on the motion is
then a model mismatch the identifier reports (``identification.mismatch``) and the workbench can
recommend as the ``roll_stiffness`` effect (``model.effects.chassis``), not a silent error in
I_x.

Symbols, units, frames (vehicle frame x forward, y left, z up; corners 1..4 = FL FR RR RL;
suspension deflection H_i from design ride height, compression positive)::

    K_arb,f, K_arb,r [N m/rad]  auxiliary (anti-roll bar) roll stiffness of the front / rear axle
    T_f, T_r         [m]        track widths (2 x ``Geometry.track_half_*``): the struts sit at
                                the wheels (y_i = +-T/2)
    h_rc,f, h_rc,r   [m]        roll-centre heights above the ground at design ride height
    F_y,axle         [N]        the axle's lateral tire force (body y)
    e_A              [-]        Ackermann fraction: 1 full Ackermann, 0 parallel steer

Anti-roll bar (Gillespie 1992, *Fundamentals of Vehicle Dynamics*, ch. 8 "Roll stiffness": a
suspension's roll stiffness is K_phi = K_s s^2 / 2 for springs of rate K_s at a lateral spacing
s, and an anti-roll bar adds its own K_phi,arb; Milliken & Milliken 1995, *Race Car Vehicle
Dynamics*, ch. 16, the anti-roll bar as a roll rate in parallel with the springs' roll rate).
With the axle's relative roll phi_a = (H_right - H_left) / T (body over axle, right side down
positive) the bar's moment on the body is -K_arb phi_a, i.e. a pair of opposite vertical forces
at the struts::

    F_arb,i = K_arb,axle (H_i - H_j) / T_axle^2       [N]   (j: the other corner of the axle)

(sum over the axle: zero, so eq 20's vertical balance is unchanged; roll moment
sum_i y_i F_arb,i = -K_arb phi_a). :func:`anti_roll_forces_n`.

Roll centre (Gillespie 1992, ch. 8 "Roll centers" and "lateral load transfer": the lateral
force of an axle reaches the sprung body through the linkage at the roll centre; the load
transfer is Delta F_z = F_y h_rc / t + K_phi phi / t). Here the tire forces act at the contact
points (the paper's model, h_rc = 0); a roll centre at h_rc adds the linkage's vertical force
pair::

    J_i = -sgn(y_i) F_y,axle h_rc,axle / T_axle         [N]   (outer wheel loaded)

which moves the lateral force's roll lever on the sprung body from h_cg to h_cg - h_rc
(sum_i y_i J_i = -F_y h_rc). :func:`roll_centre_forces_n`.

Ackermann steering (Gillespie 1992, ch. 6 "Low-speed turning": tan delta_o,i = L /
(R +- T_f / 2); Milliken & Milliken 1995, ch. 19, "percent Ackermann"; Rajamani 2012,
*Vehicle Dynamics and Control*, section 2.3, the bicycle angle delta_m): from the bicycle-model
angle delta_m = delta_sw / steering ratio, full Ackermann is
tan delta_1,2 = L tan delta_m / (L -+ (T_f / 2) tan delta_m) (``stages.ackermann_angles``); a
fraction e_A blends it with parallel steer: delta_i = delta_m + e_A (delta_i,Ackermann - delta_m).

Wheel roll coupling c_r (the slip kinematics): the paper's rigid model moves each wheel centre
with the body, so a body roll rate p adds p (h_cg - r) to the wheels' lateral velocity (and to
the slip angle, ``model.core``'s v_w = v_b + omega x r_w). A real wheel is carried by its
linkage, which moves laterally with the roll centre (Gillespie 1992, ch. 8: the body rolls
about the roll axis; the wheels do not roll with it), and CommonRoad's multibody model computes
its slip angles from the sprung CG's lateral velocity (its v + a r, not its unsprung masses'
motion): no roll term at all. c_r in [0, 1] keeps that share of the rigid roll term::

    alpha_i' = alpha_i + (1 - c_r) p (h_cg - r) cos d_i / max(|v_l,i|, v_floor)   [rad]

(v_l,i the wheel's rolling speed; first order in the roll term;
``identification.forces.slip_angles_rad``). c_r = 1: the
paper's model.
"""

from __future__ import annotations

from dataclasses import dataclass

from vdps_hil.jit import inline

__all__ = ["Chassis", "PAPER_CHASSIS", "anti_roll_forces_n", "blend_ackermann", "roll_centre_forces_n"]


@dataclass(frozen=True)
class Chassis:
    """The chassis parts of a vehicle file's optional ``[chassis]`` table (module docstring);
    the defaults are the paper's model."""

    anti_roll_stiffness_front_nmprad: float = 0.0  # K_arb,f: auxiliary roll stiffness, front axle [N m/rad]
    anti_roll_stiffness_rear_nmprad: float = 0.0  # K_arb,r [N m/rad]
    roll_centre_height_front_m: float = 0.0  # h_rc,f above the ground at design ride height [m]
    roll_centre_height_rear_m: float = 0.0  # h_rc,r [m]
    ackermann_fraction: float = 1.0  # e_A: 1 full Ackermann, 0 parallel steer [-]
    wheel_roll_coupling: float = 1.0  # c_r: share of the body's roll rate in the wheels' slip velocity [-]

    def __post_init__(self):
        for name in ("anti_roll_stiffness_front_nmprad", "anti_roll_stiffness_rear_nmprad"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must not be negative (it is a stiffness resisting roll)")
        if not 0.0 <= self.wheel_roll_coupling <= 1.0:
            raise ValueError(f"wheel_roll_coupling must be within [0, 1], got {self.wheel_roll_coupling!r}")
        if not -1.0 <= self.ackermann_fraction <= 2.0:
            raise ValueError(f"ackermann_fraction must be within [-1, 2], got {self.ackermann_fraction!r}")

    @property
    def is_paper(self) -> bool:
        """True when every part is at its default (the paper's eq 13-16)."""
        return self == PAPER_CHASSIS

    @property
    def has_anti_roll_bars(self) -> bool:
        return self.anti_roll_stiffness_front_nmprad != 0.0 or self.anti_roll_stiffness_rear_nmprad != 0.0

    @property
    def has_roll_centres(self) -> bool:
        return self.roll_centre_height_front_m != 0.0 or self.roll_centre_height_rear_m != 0.0

    def anti_roll_stiffness_nmprad(self, corner: int) -> float:
        """K_arb of the axle of corner 0..3 (FL FR RR RL)."""
        return self.anti_roll_stiffness_front_nmprad if corner < 2 else self.anti_roll_stiffness_rear_nmprad

    def roll_centre_height_m(self, corner: int) -> float:
        return self.roll_centre_height_front_m if corner < 2 else self.roll_centre_height_rear_m


PAPER_CHASSIS = Chassis()
"""The paper's model: no anti-roll bars, roll centres on the ground, full Ackermann."""

_OTHER = (1, 0, 3, 2)  # the other corner of the axle (FL <-> FR, RR <-> RL)


@inline
def anti_roll_forces_n(k_front_nmprad: float, k_rear_nmprad: float, track_front_m: float,
                       track_rear_m: float, deflection_m) -> tuple[float, float, float, float]:
    """F_arb,i = K_arb,axle (H_i - H_j) / T_axle^2 [N] per corner, upward on the body at the
    strut (module docstring)."""
    kf = k_front_nmprad / (track_front_m * track_front_m)
    kr = k_rear_nmprad / (track_rear_m * track_rear_m)
    h = deflection_m
    return (kf * (h[0] - h[1]), kf * (h[1] - h[0]), kr * (h[2] - h[3]), kr * (h[3] - h[2]))


@inline
def roll_centre_forces_n(h_front_m: float, h_rear_m: float, track_front_m: float, track_rear_m: float,
                         fy_front_n: float, fy_rear_n: float) -> tuple[float, float, float, float]:
    """J_i = -sgn(y_i) F_y,axle h_rc,axle / T_axle [N] per corner (FL and RL are on the left,
    y > 0), upward on the body at the strut (module docstring)."""
    jf = fy_front_n * h_front_m / track_front_m
    jr = fy_rear_n * h_rear_m / track_rear_m
    return (-jf, jf, jr, -jr)


@inline
def blend_ackermann(delta_mean_rad: float, delta_1_rad: float, delta_2_rad: float,
                    fraction: float) -> tuple[float, float]:
    """delta_i = delta_m + e_A (delta_i,Ackermann - delta_m) (module docstring)."""
    if fraction == 1.0:
        return delta_1_rad, delta_2_rad
    return (delta_mean_rad + fraction * (delta_1_rad - delta_mean_rad),
            delta_mean_rad + fraction * (delta_2_rad - delta_mean_rad))
