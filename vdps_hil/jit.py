"""Compiled kernels: one door to numba for every per-sample hot path.

A kernel is a plain Python function decorated with :func:`kernel`; the Python function stays
the reference (``f.py_func``), and the tests check the compiled one equal to it (tolerance
stated per kernel: 1e-12 relative, or bit-exact where the operations are the same). Live,
replay and the bench all call the same compiled code, so their outputs stay bit-identical to
each other.

Compilation and its cache
-------------------------
* numba compiles a kernel the first time it is called with a new signature (or, with explicit
  signatures, at import) and writes the machine code to its cache; later processes load it in
  milliseconds. The cache lives inside the virtual environment
  (``<sys.prefix>/var/cache/vdps-hil/numba``), never in the working directory; set
  ``NUMBA_CACHE_DIR`` to put it elsewhere.
* ``make setup`` warms the cache (``python -m vdps_hil.jit --warm``: imports every module in
  :data:`KERNEL_MODULES` and runs its ``warm()``, the groups of :data:`KERNEL_GROUPS` in two
  processes on two or more cores), so no command a user runs pays the compile.
* ``VDPS_JIT=0`` in the environment turns compilation off: every kernel runs as its Python
  reference (for debugging, and for the equality tests' reference side).
* numba keys a cached kernel on its own source file only, not on the files of the functions it
  calls (a known numba limitation: a changed callee in another module would leave the caller's
  stale machine code in use). So the cache directory carries a key, a hash of the source files
  of :data:`KERNEL_MODULES` and :data:`KERNEL_SOURCES` (the modules whose :func:`inline`
  functions kernels call): any change to one of them starts a fresh cache; ``--warm`` removes
  the directories of other keys.

Two decorators: :func:`kernel` (a compiled function, callable from Python and from other
kernels) and :func:`inline` (a plain Python function that kernels may also call, compiled into
them: numba's ``register_jitable``; from Python it runs as written, so it is its own reference).

Layer 0 (imports nothing of ours), so every package may use it.
"""

from __future__ import annotations

import importlib
import os
import sys
import time
from typing import Callable

__all__ = ["ENABLED", "KERNEL_GROUPS", "KERNEL_MODULES", "KERNEL_SOURCES", "cache_key", "inline", "kernel", "warm",
           "warm_parallel"]

ENABLED = os.environ.get("VDPS_JIT", "1").strip().lower() not in ("0", "false", "no", "off")
"""False when ``VDPS_JIT=0``: kernels run as plain Python."""

KERNEL_GROUPS: tuple[tuple[str, ...], ...] = (
    ("vdps_hil.model.reduced", "vdps_hil.model.core_kernel", "vdps_hil.prediction.integration_kernel",
     "vdps_hil.sim.step_kernel", "vdps_hil.workbench.row_kernel"),
    ("vdps_hil.estimation.ekf_kernels", "vdps_hil.estimation.ekf_update_kernels",
     "vdps_hil.identification.rls_kernels", "vdps_hil.identification.mismatch_kernels"),
)
"""Modules that define kernels and a ``warm()`` that compiles them with representative
arguments (``python -m vdps_hil.jit --warm``), in groups: a module whose kernels call another
module's kernels is in that module's group (the physics core's users; the estimator's), so
``--warm`` can compile the groups in separate processes without two of them writing the same
kernel's cache index. A module adds itself here by name, in this file, when it gains kernels."""

KERNEL_MODULES: list[str] = [m for g in KERNEL_GROUPS for m in g]
"""Every kernel module, the groups in order."""

KERNEL_SOURCES: list[str] = [
    "vdps_hil.model.frames", "vdps_hil.model.stages", "vdps_hil.model.chassis", "vdps_hil.model.effects.tires",
    "vdps_hil.model.effects.aero", "vdps_hil.model.effects.rolling",
]
"""Modules without kernels of their own whose :func:`inline` functions kernels call: part of
the cache key (module docstring)."""

_CACHE_BASE = os.path.join(sys.prefix, "var", "cache", "vdps-hil", "numba")


def cache_key() -> str:
    """Hash of the source files of :data:`KERNEL_MODULES` and :data:`KERNEL_SOURCES` (12 hex)."""
    import hashlib

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    h = hashlib.sha256()
    for name in sorted(set(KERNEL_MODULES) | set(KERNEL_SOURCES)):
        path = os.path.join(root, *name.split(".")) + ".py"
        h.update(name.encode())
        try:
            with open(path, "rb") as fh:
                h.update(fh.read())
        except OSError:
            h.update(b"missing")
    return h.hexdigest()[:12]


os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(_CACHE_BASE, cache_key()))
if "numba.core.config" in sys.modules:  # numba imported first: it read its cache directory already
    sys.modules["numba.core.config"].CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]


def kernel(*signatures, **options) -> Callable:
    """Decorator: compile ``fn`` with numba in nopython mode (cached, GIL released, numpy error
    model); ``fn.py_func`` is the Python reference. Without numba or with ``VDPS_JIT=0`` the
    function is returned as it is (``py_func`` set to itself)."""

    def wrap(fn: Callable) -> Callable:
        if ENABLED:
            import numba

            opts = {"cache": True, "nogil": True, "error_model": "numpy"}
            opts.update(options)
            return numba.njit(*signatures, **opts)(fn)
        fn.py_func = fn
        return fn

    return wrap


def inline(fn: Callable) -> Callable:
    """Decorator: ``fn`` stays a plain Python function (its own reference) that kernels may call;
    compiled into each kernel that calls it (numba's ``register_jitable``). Its module belongs in
    :data:`KERNEL_SOURCES` (or :data:`KERNEL_MODULES`)."""
    if ENABLED:
        from numba.extending import register_jitable

        register_jitable(fn)
    return fn


def _prune_cache() -> None:
    """Remove cache directories of other keys under the default cache base."""
    import shutil

    here = os.environ["NUMBA_CACHE_DIR"]
    if os.path.dirname(here) != _CACHE_BASE or not os.path.isdir(_CACHE_BASE):
        return
    for name in os.listdir(_CACHE_BASE):
        path = os.path.join(_CACHE_BASE, name)
        if path != here and os.path.isdir(path):
            shutil.rmtree(path, ignore_errors=True)


def warm(verbose: bool = False, skip: tuple[str, ...] = (), modules=None) -> dict[str, float]:
    """Import every kernel module (or those of ``modules``) but those whose name starts with one
    of ``skip`` and run its ``warm()``; returns seconds per module."""
    out = {}
    for name in (KERNEL_MODULES if modules is None else modules):
        if name.startswith(skip):
            continue
        t0 = time.perf_counter()
        mod = importlib.import_module(name)
        getattr(mod, "warm", lambda: None)()
        out[name] = time.perf_counter() - t0
        if verbose:
            print(f"{name}: {out[name]:.2f} s", file=sys.stderr)
    return out


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def warm_parallel(verbose: bool = False) -> tuple[dict[str, float], float]:
    """:func:`warm` with the groups of :data:`KERNEL_GROUPS` split over two processes when this
    process may use two cores or more (the second a ``python -P -m vdps_hil.jit --warm-group N``
    child): (seconds per module, wall seconds). A failing child fails the warm."""
    import subprocess

    t0 = time.perf_counter()
    if _cores() < 2 or len(KERNEL_GROUPS) < 2 or not ENABLED:
        return warm(verbose), time.perf_counter() - t0
    children = [subprocess.Popen([sys.executable, "-P", "-m", "vdps_hil.jit", "--warm-group", str(k)],
                                 stdout=subprocess.PIPE, text=True) for k in range(1, len(KERNEL_GROUPS))]
    took = warm(verbose, modules=KERNEL_GROUPS[0])
    for k, child in enumerate(children, start=1):
        out, _ = child.communicate()
        if child.returncode != 0:
            raise RuntimeError(f"warming kernel group {k} failed (exit {child.returncode})")
        for line in out.splitlines():
            name, _, sec = line.rpartition(" ")
            took[name] = float(sec)
    return took, time.perf_counter() - t0


if __name__ == "__main__":  # python -m vdps_hil.jit --warm
    args = sys.argv[1:]
    if "--warm" in args:
        _prune_cache()
        took, wall = warm_parallel(verbose=True)
        print(f"compiled kernels of {len(took)} modules in {sum(took.values()):.1f} s"
              f"{'' if ENABLED else ' (VDPS_JIT=0: nothing compiled)'} ({wall:.1f} s wall)")
    elif len(args) == 2 and args[0] == "--warm-group" and args[1].isdigit() and int(args[1]) < len(KERNEL_GROUPS):
        for name, sec in warm(verbose=True, modules=KERNEL_GROUPS[int(args[1])]).items():
            print(f"{name} {sec:.3f}")
    else:
        print("usage: python -m vdps_hil.jit --warm", file=sys.stderr)
        sys.exit(2)
