"""Print the CAN bus load of dbc/vdps.dbc at the Table 1 rates (1 Mbit/s, classic CAN).

    .venv/bin/python tools/busload.py            # both profiles
    .venv/bin/python tools/busload.py --seconds 5

For each message: ID, DLC, rate and frame length C with no stuff bits, typical (stuff bits
counted exactly on frames carrying a synthetic 90 km/h drive like the paper's scenario:
wheel spin 25 m/s / r with 1 Hz steering and torque inputs, Table 1 noise) and worst case
(Davis et al. 2007); then U = sum f C / R for profiles ``table1`` (suspension 1 Hz) and
``table1-susp1k`` (suspension 1 kHz). Figures are quoted in vdps_hil/codecs/can_busload.py.
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from vdps_hil.codecs.can_busload import RATE_PROFILES, bus_load, frame_bits, frame_bits_stuffed
from vdps_hil.codecs.can_dbc import (
    STEER, SUSPENSION, WARNING, WHEEL_SPEED_FRONT, WHEEL_SPEED_REAR, WHEEL_TORQUE_FRONT, WHEEL_TORQUE_REAR,
    load_dbc,
)
from vdps_hil.codecs.can_encode import (
    encode_steer, encode_suspension, encode_warning, encode_wheel_speeds, encode_wheel_torques,
)
from vdps_hil.model.params import load_vehicle


def representative_frames(seconds: float, seed: int = 0) -> dict[str, list]:
    """Frames of a synthetic 90 km/h drive with 1 Hz steering/torque inputs (deterministic)."""
    rng = np.random.default_rng(seed)
    radius_m = load_vehicle("sedan-model").tire.rolling_radius_m
    speed_mps = 90.0 / 3.6
    rates = RATE_PROFILES["table1-susp1k"]
    out: dict[str, list] = {name: [] for name in rates}
    for name, f_hz in rates.items():
        n = int(round(seconds * f_hz))
        t = np.arange(n) / f_hz
        s1 = np.sin(2 * math.pi * 1.0 * t)
        for k in range(n):
            t_ns = int(round(t[k] * 1e9))
            if name in (WHEEL_SPEED_FRONT, WHEEL_SPEED_REAR):
                w = speed_mps / radius_m * (1 + 0.01 * s1[k] * np.array([1, -1, -1, 1]))
                w = w + rng.normal(0.0, math.radians(2.0), 4)  # Table 1: 2 deg/s
                front, rear = encode_wheel_speeds(w, k, t_ns=t_ns)
                out[name].append(front if name == WHEEL_SPEED_FRONT else rear)
            elif name == SUSPENSION:
                h = 0.01 * s1[k] * np.array([-1, 1, 1, -1]) + rng.normal(0.0, 0.001, 4)  # 1 mm
                out[name].append(encode_suspension(h, k, t_ns=t_ns))
            elif name in (WHEEL_TORQUE_FRONT, WHEEL_TORQUE_REAR):
                tq = 300.0 + 200.0 * s1[k] + rng.normal(0.0, 5.0, 4)
                front, rear = encode_wheel_torques(tq, k, t_ns=t_ns)
                out[name].append(front if name == WHEEL_TORQUE_FRONT else rear)
            elif name == STEER:
                out[name].append(encode_steer(0.5 * s1[k] + rng.normal(0, 0.002), k, t_ns=t_ns))
            elif name == WARNING:
                out[name].append(encode_warning(0, None, 0.03 * s1[k], 0.2 * s1[k], 0, k,
                                                t_ns=t_ns))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=2.0, help="length of the synthetic drive")
    args = ap.parse_args(argv)
    dbc = load_dbc()
    frames = representative_frames(args.seconds)
    typical = {name: float(np.mean([frame_bits_stuffed(m.arbitration_id, bytes(m.data))
                                 for m in msgs])) for name, msgs in frames.items()}
    print(f"bus {dbc.path.name}: classic CAN, 11-bit IDs, {dbc.bitrate_bps / 1e6:g} Mbit/s")
    print(f"{'ID':>6} {'message':<22} {'DLC':>3} {'C none':>7} {'C typ':>7} {'C worst':>7}  "
          + "  ".join(f"{p + ' Hz':>16}" for p in RATE_PROFILES))
    for name, spec in sorted(dbc.messages.items(), key=lambda kv: kv[1].frame_id):
        rates = "  ".join(f"{RATE_PROFILES[p][name]:>16g}" for p in RATE_PROFILES)
        print(f"{spec.frame_id:#06x} {name:<22} {spec.dlc:>3} {frame_bits(spec.dlc, stuffing='none'):>7}"
              f" {typical[name]:>7.1f} {frame_bits(spec.dlc):>7}  {rates}")
    print()
    for profile, rates in RATE_PROFILES.items():
        none = bus_load(rates, stuffing="none")["total"]
        typ = bus_load(rates, bits_per_frame=typical)["total"]
        worst = bus_load(rates, stuffing="worst")["total"]
        print(f"bus load {profile:<14} no stuffing {100 * none:6.2f} %   typical {100 * typ:6.2f} %"
              f"   worst case {100 * worst:6.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
