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


def test_the_cache_directory_holds_when_numba_was_imported_first():
    code = ("import os, numba; import numba.core.config as c; from vdps_hil import jit\n"
            "print(c.CACHE_DIR == os.environ['NUMBA_CACHE_DIR'] != '')")
    env = dict(os.environ)
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True"]


def test_warm_runs_every_kernel_module_and_then_nothing_compiles():
    """``--warm`` runs every kernel module's ``warm()``; after it every signature the simulator
    (truth and reduced model, Heun and RK4, per step and in chunks, with the recorder) and the
    predictor (ROS2 and Heun, held and driven) call is in the cache it fills: no cache miss in a
    fresh process."""
    out = subprocess.run([sys.executable, "-m", "vdps_hil.jit", "--warm"], capture_output=True, text=True)
    assert out.returncode == 0 and f"compiled kernels of {len(jit.KERNEL_MODULES)} modules" in out.stdout
    if not jit.ENABLED:  # VDPS_JIT=0: nothing is compiled, nothing cached
        return
    code = """
import numpy as np
from vdps_hil.model.core import Inputs
from vdps_hil.model.params import load_vehicle
from vdps_hil.prediction.config import PredictorConfig
from vdps_hil.prediction.initial_state import InputTrajectory
from vdps_hil.prediction.predictor import Predictor
from vdps_hil.experiments.truth_init import initial_state_from_truth
from vdps_hil.sim.sampling import StepRecorder
from vdps_hil.sim.scenarios import load_scenario
from vdps_hil.sim.simulator import Simulator
for kw in ({}, {"integrator": "rk4"}, {"unsprung_dof": False}):
    sim = Simulator(scenario=load_scenario("paper"), **kw)
    StepRecorder(sim)
    sim.step_to(0.05)
    sim.add_step_hook(lambda s: None)
    sim.step_to(0.1)
init = initial_state_from_truth(sim.snapshot())
veh = load_vehicle("sedan-model")
traj = InputTrajectory(np.array([0.0, 1.0]), np.zeros(2), np.full((2, 4), 50.0), np.zeros((2, 4)))
for cfg in (PredictorConfig(horizon_s=1.0), PredictorConfig(integrator="rk2", step_s=0.001, horizon_s=0.1)):
    Predictor(veh, cfg).predict(init)
    Predictor(veh, cfg).predict(init, traj)
    Predictor(veh, cfg, fast=False).predict(init)
import gc
from numba.core.registry import CPUDispatcher
ds = [d for d in gc.get_objects() if isinstance(d, CPUDispatcher) and d.__module__.startswith("vdps_hil")]
print(sum(sum(d.stats.cache_misses.values()) for d in ds), *sorted(d.__name__ for d in ds if d.stats.cache_hits))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    misses, *loaded = out.stdout.split()
    assert misses == "0" and loaded == ["core_rhs", "record_row", "reduced_loop", "rk_step", "truth_steps"]


def test_kernel_groups_keep_each_module_with_the_kernel_modules_it_imports():
    """``--warm`` compiles the groups in separate processes: a module that imports another kernel
    module (its kernels call that module's kernels) must be in the same group, so no kernel's
    cache index is written by two processes at once. Read from the modules' own import lines."""
    import re
    from pathlib import Path

    root = Path(jit.__file__).resolve().parent.parent
    group_of = {m: k for k, g in enumerate(jit.KERNEL_GROUPS) for m in g}
    assert sorted(group_of) == sorted(jit.KERNEL_MODULES) and len(group_of) == len(jit.KERNEL_MODULES)
    for mod, k in group_of.items():
        src = (root / Path(*mod.split("."))).with_suffix(".py").read_text()
        imported = set(re.findall(r"^\s*from (vdps_hil(?:\.\w+)+) import", src, re.M))
        imported |= {f"{pkg}.{name}" for pkg, names in re.findall(r"^\s*from (vdps_hil(?:\.\w+)*) import ([\w, ]+)", src, re.M)
                     for name in (n.strip() for n in names.split(","))}
        for other in imported & set(group_of):
            assert group_of[other] == k, (mod, other)
