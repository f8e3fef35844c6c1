"""Tests of vdps_hil.bus.samples (the bus sample)."""

from __future__ import annotations

import math
import pickle

import pytest

from vdps_hil.bus.samples import Sample


def test_pickle_round_trip_keeps_every_attribute():
    """``vdps replay --jobs 2`` sends samples between processes as pickles (its constructor
    call): every attribute comes back, NaN fields stay NaN, the validation still runs."""
    s = Sample(123_456_789, "can.vdps", "wheel_speed", {"wheel_speed_radps_1": 31.5, "wheel_speed_radps_2": math.nan},
               wall_time_ns=1_700_000_000_000_000_000, valid=False)
    r = pickle.loads(pickle.dumps([s, s], protocol=5))
    assert r[0] is r[1]  # one object pickled once
    b = r[0]
    assert (b.t_ns, b.source, b.kind, b.wall_time_ns, b.valid) == (s.t_ns, s.source, s.kind, s.wall_time_ns, False)
    assert b.fields["wheel_speed_radps_1"] == 31.5 and math.isnan(b.fields["wheel_speed_radps_2"])
    assert Sample(1, "imu", "imu") == pickle.loads(pickle.dumps(Sample(1, "imu", "imu")))
    with pytest.raises(TypeError):
        Sample(1.5, "imu", "imu")  # float time refused


def test_the_hand_written_constructor_keeps_the_dataclass_contract():
    """``Sample.__init__`` sets the slots directly (speed); what the generated one gave holds:
    positional and keyword calls, a new ``fields`` dict per sample by default, an explicit value
    kept as given, t_ns checked, frozen, ``replace``, pickling, equality and the field list."""
    import dataclasses

    a, b = Sample(1, "can.vdps", "steer"), Sample(t_ns=1, source="can.vdps", kind="steer")
    assert a == b and a.fields == {} and a.fields is not b.fields and (a.wall_time_ns, a.valid) == (0, True)
    f = {"steer_wheel_angle_rad": 0.5}
    c = Sample(2, "can.vdps", "steer", f, 7, False)
    assert c.fields is f and (c.t_ns, c.source, c.kind, c.wall_time_ns, c.valid) == (2, "can.vdps", "steer", 7, False)
    assert Sample(3, "x", "y", fields=None).fields is None
    with pytest.raises(TypeError, match="t_ns must be int"):
        Sample(1.0, "x", "y")
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.t_ns = 5
    assert dataclasses.replace(c, t_ns=9) == Sample(9, "can.vdps", "steer", f, 7, False)
    assert pickle.loads(pickle.dumps(c)) == c
    assert [x.name for x in dataclasses.fields(Sample)] == ["t_ns", "source", "kind", "fields", "wall_time_ns",
                                                            "valid"]
