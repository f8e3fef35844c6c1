"""Helpers of the compiled-kernel tests: run kernels as plain Python in a fresh interpreter
(``VDPS_JIT=0``: every kernel, also the ones a kernel calls, is its Python form) so a test can
hold the compiled kernels bit-equal to it."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys

import numpy as np

_RUNNER = """
import pickle, sys, importlib
calls = pickle.loads(sys.stdin.buffer.read())
out = []
for mod, name, args in calls:
    fn = getattr(importlib.import_module(mod), name)
    res = fn(*args)
    out.append((res, args))
sys.stdout.buffer.write(pickle.dumps(out))
"""


def run_pure_python(calls: list[tuple[str, str, tuple]]) -> list[tuple[object, tuple]]:
    """``calls``: (module, function, args) run in order with ``VDPS_JIT=0``; per call (the
    return value, the arguments after the call: kernels write into their array arguments)."""
    env = dict(os.environ, VDPS_JIT="0")
    r = subprocess.run([sys.executable, "-c", _RUNNER], input=pickle.dumps(calls), env=env,
                       capture_output=True, check=True)
    return pickle.loads(r.stdout)


def run_compiled(calls: list[tuple[str, str, tuple]]) -> list[tuple[object, tuple]]:
    """The same calls in this process (compiled when ``jit.ENABLED``), on copies of the args."""
    import copy
    import importlib

    out = []
    for mod, name, args in calls:
        args = copy.deepcopy(args)
        out.append((getattr(importlib.import_module(mod), name)(*args), args))
    return out


def same_bits(a, b) -> bool:
    """Equal value for value, NaN equal to NaN, -0.0 equal to 0.0 (nested tuples and arrays)."""
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(same_bits(x, y) for x, y in zip(a, b))
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))
