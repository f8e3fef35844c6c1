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
