"""Shared checks of the IMU codec tests (tests/test_imu_*.py): an Xbus message built from the
protocol rule, independent of the codec, and a sample's IMU fields in order.
"""

from __future__ import annotations

from vdps_hil.codecs.imu_decoder import F_FIELDS, W_FIELDS


def xbus(mid: int, data: bytes) -> bytes:
    """An Xbus message built here from the protocol rule, independent of the codec."""
    body = bytes([0xFF, mid, len(data)]) + data
    return b"\xfa" + body + bytes([(-sum(body)) & 0xFF])


def fields_of(sample):
    return [sample.fields[k] for k in (*F_FIELDS, *W_FIELDS)]
