"""Third-party imports deferred until they are used: asammdf, python-can's MF4 backend.

python-can (4.x) imports asammdf, and asammdf pandas, in ``can.io.mf4`` as soon as ``import can``
runs, whenever asammdf is installed (this project's ``mdf`` extra): 0.4-0.5 s of CPU in every
process that touches CAN (each ``vdps`` command, each bench child and worker process), for a file
format few runs open. :func:`install` (run by ``vdps_hil/__init__``) lets ``can.io.mf4``'s first
run see no asammdf, so python-can loads without it and marks MF4 unavailable;
:func:`mf4_support`, called before a ``.mf4`` file is opened, imports asammdf and runs
``can.io.mf4`` again. The module runs again in its own namespace, and python-can's reader and
writer classes (also those already held in its format tables) look asammdf up there when they are
made, so they work from then on. Nothing else is hidden: an ``import asammdf`` from anywhere but
``can.io.mf4``'s own first run is served as usual.
"""

from __future__ import annotations

import importlib
import sys

__all__ = ["install", "mf4_support"]

CAN_MF4 = "can.io.mf4"
_DEFERRED = "asammdf"
_released = False


def _importing_from_can_mf4() -> bool:
    f = sys._getframe(2)
    while f is not None:
        if f.f_code.co_name == "<module>" and f.f_globals.get("__name__") == CAN_MF4:
            return True
        f = f.f_back
    return False


class _DeferFromCanMf4:
    """A finder on ``sys.meta_path`` (the protocol of ``importlib.abc.MetaPathFinder``, not
    imported: the package's import must stay cheap) that answers "not installed" for asammdf
    while ``can.io.mf4`` is first imported, and otherwise leaves the search to the others."""

    def find_spec(self, name, path=None, target=None):
        if _released or (name != _DEFERRED and not name.startswith(_DEFERRED + ".")):
            return None
        if _importing_from_can_mf4():
            raise ModuleNotFoundError(f"{name}: deferred until an MF4 file is opened "
                                      "(vdps_hil.deferred_imports)", name=name)
        return None


_FINDER = _DeferFromCanMf4()


def install() -> None:
    """Defer asammdf for ``can.io.mf4`` (once per process; nothing to do when python-can was
    imported already)."""
    if _FINDER not in sys.meta_path and CAN_MF4 not in sys.modules:
        sys.meta_path.insert(0, _FINDER)


def mf4_support() -> bool:
    """Make python-can's MF4 reader and writer usable: import asammdf and, if ``can.io.mf4`` ran
    without it, run it again. False when asammdf is not installed (python-can then says so
    itself when an MF4 reader is made)."""
    global _released
    _released = True
    if _FINDER in sys.meta_path:
        sys.meta_path.remove(_FINDER)
    try:
        import asammdf  # noqa: F401
    except ImportError:
        return False
    mod = sys.modules.get(CAN_MF4)
    if mod is not None and getattr(mod, "asammdf", None) is None:
        importlib.reload(mod)
    return True
