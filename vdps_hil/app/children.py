"""Python child processes that never import code from the working directory.

``python -m MODULE`` and ``python -c CODE`` (what ``multiprocessing``'s spawn start method and
Dask's worker processes run) put the working directory first on ``sys.path``: a ``json.py``
or ``threading.py`` in the directory where a user starts ``vdps replay`` would be imported and
executed by the child before any of our code. Every child this package starts therefore runs
in Python's safe-path mode (``-P`` / ``PYTHONSAFEPATH``, Python >= 3.11: nothing unsafe is
prepended to ``sys.path``). ``-I`` (isolated mode) is not used: it would also drop
``PYTHONPATH`` and the user site directory, where the package itself may be installed.

* :func:`python_module_command` -- ``[sys.executable, "-P", "-m", module, *args]``;
* :func:`child_environ` -- the environment for such a child: ``PYTHONSAFEPATH=1`` (so its own
  children are safe too) and, unless the package is installed in a site directory, the
  directory holding ``vdps_hil`` first on ``PYTHONPATH`` (a source checkout still imports the
  package, from its own directory, never from the working directory);
* :func:`isolate_spawned_children` -- sets ``PYTHONSAFEPATH=1`` in this process's environment
  before a ``multiprocessing`` (spawn) pool or a local Dask cluster starts: their children
  inherit the environment (tests: ``tests/test_children.py``, with marker modules in the working
  directory that would write a file if imported).
* :func:`one_blas_thread_per_child` -- one BLAS thread in every child spawned from now on
  (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` = 1 where the user has not
  set them): a pool of one worker per core whose numpy each started a BLAS thread per core
  spun them against each other (``vdps batch diagnose --backend processes --workers 2`` on six
  study drives, one session: 22.2-22.7 s wall and 42 s of CPU with OpenBLAS's default, 18.1-19.2 s
  and 34-36 s with one thread set by hand; the machine's spread is about as large, README). Dask's
  nannies set the same three for their workers
  (``distributed.nanny.pre-spawn-environ``);
* :func:`spawned_pool` -- a ``ProcessPoolExecutor`` of spawned children with both of the above
  (the batch engine's process backend and the study tools).
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import site
import sys
from pathlib import Path
from typing import Mapping, Sequence

__all__ = ["python_module_command", "child_environ", "isolate_spawned_children", "one_blas_thread_per_child",
           "BLAS_THREAD_VARIABLES", "PACKAGE_ROOT", "spawned_pool"]

BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
"""The environment variables that size the BLAS thread pools of numpy's OpenBLAS (and of OpenMP
or MKL builds), read once when the library loads."""

PACKAGE_ROOT = str(Path(__file__).resolve().parents[2])
"""The directory that holds the ``vdps_hil`` package (site-packages, or a source checkout)."""


def python_module_command(module: str, args: Sequence[str] = ()) -> list[str]:
    """The command line of ``python -m module args...`` in safe-path mode (module docstring)."""
    return [sys.executable, "-P", "-m", module, *map(str, args)]


def child_environ(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """A copy of ``base`` (default ``os.environ``) for a Python child (module docstring)."""
    env = dict(os.environ if base is None else base)
    env["PYTHONSAFEPATH"] = "1"
    if not _in_site_directory():
        rest = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p and p != PACKAGE_ROOT]
        env["PYTHONPATH"] = os.pathsep.join([PACKAGE_ROOT, *rest])
    return env


def _in_site_directory() -> bool:
    sites = list(getattr(site, "getsitepackages", lambda: [])())
    user = getattr(site, "getusersitepackages", lambda: None)()
    sites += [user] if isinstance(user, str) else []
    return any(os.path.realpath(s) == os.path.realpath(PACKAGE_ROOT) for s in sites)


def isolate_spawned_children() -> None:
    """Make every Python child this process spawns from now on (``multiprocessing``, Dask's
    nannies and workers) start in safe-path mode: ``PYTHONSAFEPATH=1`` in ``os.environ``."""
    os.environ["PYTHONSAFEPATH"] = "1"


def one_blas_thread_per_child() -> None:
    """Make every child this process spawns from now on load numpy's BLAS with one thread
    (module docstring): each of :data:`BLAS_THREAD_VARIABLES` set to 1 in ``os.environ`` unless
    it is already set (the user's own choice wins). This process's BLAS, loaded already, is not
    changed; forked children share it, so only spawned children are affected."""
    for name in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(name, "1")


def spawned_pool(max_workers: int) -> cf.ProcessPoolExecutor:
    """A process pool of ``max_workers`` spawned children in safe-path mode, each loading numpy's
    BLAS with one thread (:func:`isolate_spawned_children`, :func:`one_blas_thread_per_child`).
    Work runs in the children only through picklable top-level functions."""
    isolate_spawned_children()
    one_blas_thread_per_child()
    return cf.ProcessPoolExecutor(max_workers=max_workers, mp_context=multiprocessing.get_context("spawn"))
