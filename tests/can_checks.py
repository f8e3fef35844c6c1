"""Shared checks of the vdps chassis CAN codec tests (tests/test_can_*.py): the layout the
``codecs.can_dbc`` docstring claims, written out again (LAYOUT), an independent bit-level
unpacker and a bit-by-bit CRC-8/SAE-J1850.
"""

from __future__ import annotations

from cantools.database.can import Message, Signal
from cantools.database.conversion import BaseConversion
from hypothesis import strategies as st


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
    "VDPS_WheelSpeedFront": (0x100, 6, 1, {
        "e2e_crc": (0, 8, False, 1, 0, 255, ""),
        "seq_counter": (8, 4, False, 1, 0, 15, ""),
        "wheel_speed_radps_1": (16, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "wheel_speed_radps_2": (32, 16, True, 0.01, -327.68, 327.67, "rad/s"),
    }),
    "VDPS_WheelSpeedRear": (0x101, 6, 1, {
        "e2e_crc": (0, 8, False, 1, 0, 255, ""),
        "seq_counter": (8, 4, False, 1, 0, 15, ""),
        "wheel_speed_radps_3": (16, 16, True, 0.01, -327.68, 327.67, "rad/s"),
        "wheel_speed_radps_4": (32, 16, True, 0.01, -327.68, 327.67, "rad/s"),
    }),
    "VDPS_Suspension": (0x110, 8, 1, {
        "e2e_crc": (0, 8, False, 1, 0, 255, ""),
        "seq_counter": (8, 4, False, 1, 0, 15, ""),
        **{f"susp_deflection_m_{i + 1}": (12 + 13 * i, 13, True, 4e-5, -0.16384, 0.1638, "m")
           for i in range(4)},
    }),
    "VDPS_WheelTorqueFront": (0x120, 5, 10, {
        "e2e_crc": (0, 8, False, 1, 0, 255, ""),
        "seq_counter": (8, 4, False, 1, 0, 15, ""),
        **{f"wheel_torque_nm_{i + 1}": (12 + 14 * i, 14, True, 1, -8192, 8191, "N m") for i in range(2)},
    }),
    "VDPS_WheelTorqueRear": (0x121, 5, 10, {
        "e2e_crc": (0, 8, False, 1, 0, 255, ""),
        "seq_counter": (8, 4, False, 1, 0, 15, ""),
        **{f"wheel_torque_nm_{i + 3}": (12 + 14 * i, 14, True, 1, -8192, 8191, "N m") for i in range(2)},
    }),
    "VDPS_SteerAngle": (0x130, 4, 10, {
        "e2e_crc": (0, 8, False, 1, 0, 255, ""),
        "seq_counter": (8, 4, False, 1, 0, 15, ""),
        "steer_wheel_angle_rad": (16, 16, True, 0.001, -12.567, 12.567, "rad"),
    }),
}


KINDS = {"VDPS_Warning": "warning", "VDPS_WheelSpeedFront": "wheel_speed",
         "VDPS_WheelSpeedRear": "wheel_speed", "VDPS_Suspension": "suspension",
         "VDPS_WheelTorqueFront": "wheel_torque", "VDPS_WheelTorqueRear": "wheel_torque",
         "VDPS_SteerAngle": "steer"}


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
    return [s for s in LAYOUT[name][3] if s not in COUNTER_NAMES and not s.endswith("_crc")]


def e2e_crc_bitwise(frame_id: int, data: bytes) -> int:
    """The E2E CRC of a layout-2 sensor frame from its definition: CRC-8/SAE-J1850 (bit by bit)
    over the data ID = CAN ID (low, high byte) and bytes 1..DLC-1."""
    return crc8_bitwise(bytes((frame_id & 0xFF, frame_id >> 8)) + bytes(data[1:]))


def sample_key(s) -> tuple:
    """A decoded sample as comparable data, bit for bit: every field's value as its float hex (or
    repr), in the sample's field order, with the types of the values."""
    return (s.t_ns, s.source, s.kind, tuple((n, type(v).__name__, v.hex() if isinstance(v, float) else repr(v))
                                            for n, v in s.fields.items()), s.wall_time_ns, s.valid)


def recording_frames(path) -> list[tuple[int, int, bytes, bool]]:
    """The typed frames ``(t_ns, id, payload, is_extended_id)`` of every ``/raw/can/`` record of a
    recording, in the order a replay decodes them."""
    import json

    from vdps_hil.record.reader import RecordingReader

    with RecordingReader(path) as r:
        docs = [(rec.t_ns, json.loads(rec.data)) for rec in r.iter_records(prefixes=("/raw/can/",))]
    return [(t, d["arbitration_id"], bytes.fromhex(d["data_hex"]), d["is_extended_id"]) for t, d in docs]


def _layout(draw, length_bytes: int, big: bool) -> list[tuple[int, int, bool]]:
    """Non-overlapping signals (sequential start bit, length, signed) filling part of a payload."""
    total = 8 * length_bytes
    pos, out = 0, []
    while pos < total and len(out) < 6:
        pos += draw(st.integers(0, 6))
        if pos >= total:
            break
        n = draw(st.integers(1, min(32, total - pos)))
        out.append((pos, n, draw(st.booleans())))
        pos += n
    return out


@st.composite
def messages(draw):
    """A random compilable cantools message (1-8 bytes, one byte order, scale 0.5, offset -1)."""
    length = draw(st.integers(1, 8))
    big = draw(st.booleans())
    sigs = []
    for k, (pos, n, signed) in enumerate(_layout(draw, length, big)):
        if big:  # pos = network bit of the MSB -> DBC (sawtooth) start bit of the MSB
            start = 8 * (pos // 8) + 7 - pos % 8
        else:
            start = pos
        sigs.append(Signal(f"s{k}", start, n, "big_endian" if big else "little_endian", signed,
                           conversion=BaseConversion.factory(scale=0.5, offset=-1.0)))
    if not sigs:
        sigs.append(Signal("s0", 0 if not big else 7, 1, "big_endian" if big else "little_endian", False))
    return Message(0x123, "M", length, sigs, strict=True)
