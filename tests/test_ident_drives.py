"""The cached IdentInputs of a drive (experiments.ident_drives): the npz columns round-trip every
field (optional ones None where absent), the cache is read without pickle, and a cached drive is
not simulated again."""

import dataclasses

import numpy as np

from ident_forward import forward
from vdps_hil.experiments.ident_drives import (CACHE_VERSION, DriveKey, cache_path, drive_inputs,
                                               inputs_from_arrays, inputs_to_arrays)


def _inputs(n=20):
    rng = np.random.default_rng(5)
    out = []
    for k in range(n):
        inp = forward(rng, k)
        if k % 2:  # the optional fields present in some inputs only
            inp = dataclasses.replace(inp, lateral_velocity_sigma_mps=0.01 * k, vehicle_angles_rad=(0.01, -0.02))
        out.append(inp)
    return out


def test_arrays_round_trip_every_field():
    inputs = _inputs()
    back = inputs_from_arrays(inputs_to_arrays(inputs))
    assert back == inputs


def test_a_cached_drive_is_read_back_without_pickle_and_not_simulated(tmp_path):
    inputs = _inputs()
    key = DriveKey("no-such-scenario", "ours", "sedan-model", 3)  # simulating it would fail
    path = cache_path(tmp_path, key)
    np.savez_compressed(path, cache_version=np.array(CACHE_VERSION), **inputs_to_arrays(inputs))
    with np.load(path, allow_pickle=False) as z:
        assert all(z[k].dtype != object for k in z.files)
    assert drive_inputs(key, tmp_path) == inputs
