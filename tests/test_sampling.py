"""Sampling of the per-step truth (sim/sampling.py): seeded random streams, every sample picked
once whatever the blocks."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.sim.sampling import Block, Sampler, rng_for

MS = 1_000_000


def test_rng_streams_reproduce_and_are_independent():
    a, b = rng_for(7, "imu.noise").standard_normal(5), rng_for(7, "imu.noise").standard_normal(5)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, rng_for(7, "gnss.position").standard_normal(5))
    assert not np.allclose(a, rng_for(8, "imu.noise").standard_normal(5))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(rate=st.sampled_from([1000.0, 100.0, 5.0, 1.0, 300.0]),
       cuts=st.lists(st.integers(1, 700), min_size=1, max_size=8))
def test_sampler_picks_every_sample_once_whatever_the_blocks(rate, cuts):
    s = Sampler(rate, MS)
    n0, picked = 0, []
    for c in cuts:
        rows, ks = s.pick(Block.build(np.arange(n0, n0 + c), MS))
        picked += list(zip((rows + n0).tolist(), ks.tolist()))
        n0 += c
    ks = [k for _, k in picked]
    assert ks == list(range(len(ks)))
    period = round(1e9 / rate)
    assert all(n == (2 * k * period + MS) // (2 * MS) for n, k in picked)
    assert ks and (2 * (ks[-1] + 1) * period + MS) // (2 * MS) >= n0  # nothing left behind
