"""Frame lengths on the wire and the bus load of the vdps chassis bus (Table 1 rates,
1 Mbit/s).

Frame length of a classic CAN frame with an 11-bit ID and n data bytes (SOF..CRC = 34 + 8n
bits are subject to stuffing, then CRC delimiter, ACK, EOF and 3 bits of intermission)::

    C_none  = 47 + 8 n                                   (no stuff bits)
    C_worst = 47 + 8 n + floor((34 + 8 n - 1) / 4)       (Davis, Burns, Bril, Lukkien 2007,
                                                          Real-Time Systems 35(3), eq. 2)
    U = sum_i f_i C_i / R

Typical: stuff bits counted exactly (:func:`frame_bits_stuffed`, CRC-15 included) on frames
carrying a 90 km/h drive of the paper's scenario (``tools/busload.py`` prints the table).
Warning frames sent on a level change add at most a few frames per event (not included).

===========================  ==============  =====================  =========  ==============
message (DLC n)              rate            C none / typ / worst   U table1   U table1-susp1k
                                             [bit]                  (worst)    (worst)
===========================  ==============  =====================  =========  ==============
0x080 VDPS_Warning (8)       50 Hz           111 / 120.6 / 135      0.68 %     0.68 %
0x100 VDPS_WheelSpeedFront   1000 Hz         95 / 101.2 / 115       11.50 %    11.50 %
0x101 VDPS_WheelSpeedRear    1000 Hz         95 / 100.1 / 115       11.50 %    11.50 %
0x110 VDPS_Suspension (8)    1 Hz / 1000 Hz  111 / 116.9 / 135      0.01 %     13.50 %
0x120 VDPS_WheelTorqueFront  100 Hz          87 / 91.0 / 105        1.05 %     1.05 %
0x121 VDPS_WheelTorqueRear   100 Hz          87 / 89.9 / 105        1.05 %     1.05 %
0x130 VDPS_SteerAngle (4)    100 Hz          79 / 82.9 / 95         0.95 %     0.95 %
total, worst case                                                   26.74 %    40.23 %
total, typical (stuffed)                                            23.38 %    35.06 %
total, no stuff bits                                                22.10 %    33.18 %
===========================  ==============  =====================  =========  ==============

Layout 2 (E2E CRC and 4-bit counter in every sensor frame, torques in two frames) costs 2.85
points of worst-case load over layout 1 (23.89 % / 37.38 %). With the suspension at 1 kHz the
worst case (every frame maximally stuffed) is 40.2 %, the typical load 35 %, leaving room for an
IMU cluster or a car's own traffic on the same 1 Mbit/s bus.

================  =====================================  ============
symbol            meaning                                unit
================  =====================================  ============
n                 data length code (payload bytes)       byte
C                 frame length on the wire               bit
f                 message rate                           Hz
R                 bit rate (1 Mbit/s)                    bit/s
U                 bus load                               1
================  =====================================  ============
"""

from __future__ import annotations

from typing import Iterable, Mapping

from vdps_hil.codecs.can_dbc import (
    STEER, SUSPENSION, WARNING, WHEEL_SPEED_FRONT, WHEEL_SPEED_REAR, WHEEL_TORQUE_FRONT, WHEEL_TORQUE_REAR,
    VdpsDbc, load_dbc,
)

RATE_PROFILES: dict[str, dict[str, float]] = {
    "table1": {WARNING: 50.0, WHEEL_SPEED_FRONT: 1000.0, WHEEL_SPEED_REAR: 1000.0,
               SUSPENSION: 1.0, WHEEL_TORQUE_FRONT: 100.0, WHEEL_TORQUE_REAR: 100.0, STEER: 100.0},
    "table1-susp1k": {WARNING: 50.0, WHEEL_SPEED_FRONT: 1000.0, WHEEL_SPEED_REAR: 1000.0,
                      SUSPENSION: 1000.0, WHEEL_TORQUE_FRONT: 100.0, WHEEL_TORQUE_REAR: 100.0,
                      STEER: 100.0},
}
"""Message rates [Hz] of the two sensor profiles (Table 1; torque, steer, warning our choice)."""


# ---------------------------------------------------------------------------------------------
# Frame length and bus load
# ---------------------------------------------------------------------------------------------
def frame_bits(dlc: int, *, stuffing: str = "worst") -> int:
    """Bits on the wire of a classic CAN frame with an 11-bit ID and ``dlc`` data bytes,
    interframe space included: ``stuffing="none"`` -> 47 + 8 n, ``"worst"`` -> plus
    floor((34 + 8 n - 1) / 4) stuff bits."""
    if not 0 <= dlc <= 8:
        raise ValueError(f"classic CAN DLC must be 0..8, got {dlc}")
    base = 47 + 8 * dlc
    if stuffing == "none":
        return base
    if stuffing == "worst":
        return base + (34 + 8 * dlc - 1) // 4
    raise ValueError(f"stuffing must be 'none' or 'worst', got {stuffing!r}")


def _can_crc15(bits: Iterable[int]) -> int:
    reg = 0
    for b in bits:
        nxt = b ^ ((reg >> 14) & 1)
        reg = (reg << 1) & 0x7FFF
        if nxt:
            reg ^= 0x4599
    return reg


def frame_bits_stuffed(arbitration_id: int, data: bytes) -> int:
    """Exact bits on the wire (stuff bits counted, interframe space included) of a classic data
    frame with an 11-bit ID: SOF, ID, RTR, IDE, r0, DLC, data and CRC-15 (poly 0x4599) are
    stuffed (a complementary bit after 5 equal bits, the stuff bit starting the next run)."""
    if not 0 <= arbitration_id < 0x800 or len(data) > 8:
        raise ValueError("frame_bits_stuffed: 11-bit ID and at most 8 data bytes")
    bits = [0] + [(arbitration_id >> (10 - i)) & 1 for i in range(11)] + [0, 0, 0]
    bits += [(len(data) >> (3 - i)) & 1 for i in range(4)]
    for byte in data:
        bits += [(byte >> (7 - i)) & 1 for i in range(8)]
    crc = _can_crc15(bits)
    bits += [(crc >> (14 - i)) & 1 for i in range(15)]
    stuff, run, prev = 0, 0, None
    for b in bits:
        if b == prev:
            run += 1
        else:
            prev, run = b, 1
        if run == 5:
            stuff += 1
            prev, run = 1 - b, 1  # the stuff bit (complement) starts the next run
    return len(bits) + 10 + 3 + stuff


def bus_load(rates_hz: Mapping[str, float], *, stuffing: str = "worst",
             dbc: VdpsDbc | None = None, bits_per_frame: Mapping[str, float] | None = None
             ) -> dict[str, float]:
    """Bus load U = sum f_i C_i / R per message and ``"total"`` (fractions of 1).

    ``bits_per_frame`` (message -> C) overrides the formula, e.g. with measured stuffed lengths.
    """
    dbc = dbc or load_dbc()
    out = {}
    for name, f in rates_hz.items():
        c = (bits_per_frame[name] if bits_per_frame is not None
             else frame_bits(dbc.messages[name].dlc, stuffing=stuffing))
        out[name] = f * c / dbc.bitrate_bps
    out["total"] = sum(out.values())
    return out
