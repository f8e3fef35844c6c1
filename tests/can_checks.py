"""Shared checks of the vdps chassis CAN codec tests (tests/test_can_*.py): the layout the
``codecs.can_dbc`` docstring claims, written out again (LAYOUT), an independent bit-level
unpacker and a bit-by-bit CRC-8/SAE-J1850.
"""

from __future__ import annotations


# name: (id, dlc, cycle ms, {signal: (start, length, signed, scale, minimum, maximum, unit)})
LAYOUT = {
    "VDPS_Warning": (0x080, 8, 20, {
        "warning_crc": (0, 8, False, 1, 0, 255, ""),
        "warning_counter": (8, 4, False, 1, 0, 15, ""),
        "warning_level": (12, 2, False, 1, 0, 3, ""),
        "warning_status": (14, 2, False, 1, 0, 3, ""),
        "warning_time_to_rollover_s": (16, 16, False, 0.001, 0, 65.535, "s"),
        "warning_peak_roll_rad": (32, 16, True, 0.0001, -3.1416, 3.1416, "rad"),
        "warning_ltr": (48, 16, True, 0.0001, -1, 1, ""),
    }),
    "VDPS_WheelSpeedFront": (0x100, 5, 1, {
        "wheel_speed_radps_1": (0, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "wheel_speed_radps_2": (16, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "seq_counter": (32, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_WheelSpeedRear": (0x101, 5, 1, {
        "wheel_speed_radps_3": (0, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "wheel_speed_radps_4": (16, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "seq_counter": (32, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_Suspension": (0x110, 8, 1, {
        **{f"susp_deflection_m_{i + 1}": (14 * i, 14, True, 2e-5, -0.16384, 0.16382, "m")
           for i in range(4)},
        "seq_counter": (56, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_WheelTorque": (0x120, 8, 10, {
        **{f"wheel_torque_nm_{i + 1}": (14 * i, 14, True, 1, -8192, 8191, "N m") for i in range(4)},
        "seq_counter": (56, 8, False, 1, 0, 255, ""),
    }),
    "VDPS_SteerAngle": (0x130, 3, 10, {
        "steer_wheel_angle_rad": (0, 16, True, 0.001, -12.567, 12.567, "rad"),
        "seq_counter": (16, 8, False, 1, 0, 255, ""),
    }),
}


KINDS = {"VDPS_Warning": "warning", "VDPS_WheelSpeedFront": "wheel_speed",
         "VDPS_WheelSpeedRear": "wheel_speed", "VDPS_Suspension": "suspension",
         "VDPS_WheelTorque": "wheel_torque", "VDPS_SteerAngle": "steer"}


COUNTER_NAMES = ("seq_counter", "warning_counter")
FP_EPS = 1e-9  # floating-point slack on top of half a resolution step


def unpack_independent(name: str, data: bytes) -> dict[str, int]:
    """Raw integers of every signal by plain bit arithmetic on the little-endian payload."""
    v = int.from_bytes(data, "little")
    out = {}
    for sig, (start, length, signed, *_rest) in LAYOUT[name][3].items():
        raw = (v >> start) & ((1 << length) - 1)
        if signed and raw >= 1 << (length - 1):
            raw -= 1 << length
        out[sig] = raw
    return out


def crc8_bitwise(data: bytes) -> int:
    """CRC-8/SAE-J1850 written bit by bit from its definition (independent of the table)."""
    reg = 0xFF
    for byte in data:
        for i in range(7, -1, -1):
            top = ((reg >> 7) & 1) ^ ((byte >> i) & 1)
            reg = (reg << 1) & 0xFF
            if top:
                reg ^= 0x1D
    return reg ^ 0xFF


def value_fields(name):
    return [s for s in LAYOUT[name][3] if s not in COUNTER_NAMES and s != "warning_crc"]
