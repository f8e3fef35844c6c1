"""The one door to numba (``vdps_hil.jit``): a kernel compiles, keeps its Python reference,
and runs as plain Python with ``VDPS_JIT=0``; its cache lives inside the environment."""

import os
import subprocess
import sys

import numpy as np

from vdps_hil import jit


def test_a_kernel_equals_its_python_reference():
    @jit.kernel()
    def dot3(a, b):
        s = 0.0
        for i in range(3):
            s += a[i] * b[i]
        return s

    a, b = np.array([1.0, 2.0, 3.0]), np.array([0.5, -1.0, 4.0])
    assert dot3(a, b) == dot3.py_func(a, b) == 10.5
    assert (type(dot3).__name__ == "CPUDispatcher") == jit.ENABLED


def test_jit_off_runs_the_reference_and_the_cache_is_in_the_environment(tmp_path):
    code = ("import os, sys; from vdps_hil import jit\n"
            "f = jit.kernel()(lambda x: x + 1)\n"
            "print(jit.ENABLED, f is f.py_func, os.environ['NUMBA_CACHE_DIR'].startswith(sys.prefix))")
    env = dict(os.environ, VDPS_JIT="0")
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["False", "True", "True"]


def test_warm_runs_every_kernel_module():
    out = subprocess.run([sys.executable, "-m", "vdps_hil.jit", "--warm"], capture_output=True, text=True)
    assert out.returncode == 0 and f"compiled kernels of {len(jit.KERNEL_MODULES)} modules" in out.stdout
