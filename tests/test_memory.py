"""``workbench.memory``: handing freed heap pages back leaves every live value as it was, and is
a no-op where the C library has no ``malloc_trim``."""

import numpy as np

from vdps_hil.workbench import memory


def test_release_keeps_live_arrays_and_frees_nothing_referenced():
    rng = np.random.default_rng(5)
    keep = rng.normal(size=(1000, 14))
    copy = keep.copy()
    junk = [np.ones(200_000) for _ in range(5)]
    del junk
    memory.release_freed_memory()
    np.testing.assert_array_equal(keep, copy)


def test_release_is_a_no_op_without_malloc_trim(monkeypatch):
    monkeypatch.setattr(memory, "_TRIM", False)
    assert memory.release_freed_memory() is None
