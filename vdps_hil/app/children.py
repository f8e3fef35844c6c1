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
"""

from __future__ import annotations

import os
import site
import sys
from pathlib import Path
from typing import Mapping, Sequence

__all__ = ["python_module_command", "child_environ", "isolate_spawned_children", "PACKAGE_ROOT"]

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
