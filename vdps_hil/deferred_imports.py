"""Third-party imports deferred until they are used: asammdf, python-can's MF4 backend.

python-can (4.x) imports asammdf, and asammdf pandas, in ``can.io.mf4`` as soon as ``import can``
runs, whenever asammdf is installed (this project's ``mdf`` extra): 0.4-0.5 s of CPU in every
process that touches CAN (each ``vdps`` command, each bench child and worker process), for a file
format few runs open. :func:`install` (run by ``vdps_hil/__init__``) puts a finder first on
``sys.meta_path`` that changes one thing: while ``can.io.mf4`` first runs, ``import asammdf``
answers "not installed", so python-can loads without it. Its two MF4 classes are then given an
``__init__`` that first calls :func:`mf4_support` (import asammdf, run ``can.io.mf4`` again in its
own namespace, where those classes look asammdf up) and then python-can's own ``__init__``: a
``can.LogReader("x.mf4")``, ``can.Logger("x.mf4")`` or ``can.MF4Reader(...)`` works as it did,
paying the import when it is made. Where asammdf is not installed nothing is changed (python-can's
own "asammdf not found" stays), and an ``import asammdf`` from anywhere else is never touched.
"""

from __future__ import annotations

import _thread
import functools
import importlib
import sys

__all__ = ["install", "mf4_support"]

CAN_MF4 = "can.io.mf4"
_DEFERRED = "asammdf"
_state = {"hiding": None, "released": False}  # hiding: the thread running can.io.mf4 without asammdf


class _DeferredMf4Finder:
    """A ``sys.meta_path`` finder (``importlib.abc.MetaPathFinder``'s protocol; importlib.abc is not
    imported, the package's own import must stay cheap): finds ``can.io.mf4`` as the other finders
    do, with its loader wrapped (:class:`_DeferringLoader`), and hides asammdf while that loader runs."""

    def find_spec(self, name, path=None, target=None):
        if _state["released"]:
            return None
        if _state["hiding"] == _thread.get_ident() and (name == _DEFERRED or name.startswith(_DEFERRED + ".")):
            raise ModuleNotFoundError(f"{name}: deferred until an MF4 file is opened "
                                      "(vdps_hil.deferred_imports)", name=name)
        if name != CAN_MF4 or _DEFERRED in sys.modules:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                if spec.loader is not None and hasattr(spec.loader, "exec_module") and _installed():
                    spec.loader = _DeferringLoader(spec.loader)
                return spec
        return None


def _installed() -> bool:
    """asammdf can be imported (found on the path, not imported)."""
    from importlib.machinery import PathFinder

    return PathFinder.find_spec(_DEFERRED) is not None


class _DeferringLoader:
    """python-can's loader of ``can.io.mf4``, run with asammdf hidden; its MF4 classes then make
    asammdf available themselves when first made."""

    def __init__(self, loader):
        self.loader = loader

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module) -> None:
        _state["hiding"] = _thread.get_ident()  # another thread's import of asammdf is served as usual
        try:
            self.loader.exec_module(module)
        finally:
            _state["hiding"] = None
            _uninstall()  # its work is done: no later import passes through it
        classes = [getattr(module, name, None) for name in ("MF4Reader", "MF4Writer")]
        if not all(isinstance(cls, type) for cls in classes):  # not the python-can this was written for:
            _state["released"] = True  # run it again with asammdf, as python-can itself would have
            self.loader.exec_module(module)
            return
        for cls in classes:
            cls.__init__ = _enabling(cls.__init__)


def _enabling(init):
    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        mf4_support()
        init(self, *args, **kwargs)
    return __init__


_FINDER = _DeferredMf4Finder()


def install() -> None:
    """Defer asammdf for ``can.io.mf4`` (once per process; nothing to do when python-can's MF4
    module was imported already)."""
    if _FINDER not in sys.meta_path and CAN_MF4 not in sys.modules:
        sys.meta_path.insert(0, _FINDER)


def _uninstall() -> None:
    if _FINDER in sys.meta_path:
        sys.meta_path.remove(_FINDER)


def mf4_support() -> bool:
    """Make python-can's MF4 reader and writer ready now: import asammdf and, if ``can.io.mf4``
    ran without it, run it again. False when asammdf is not installed."""
    _state["released"] = True
    _uninstall()
    try:
        import asammdf  # noqa: F401
    except ImportError:
        return False
    mod = sys.modules.get(CAN_MF4)
    if mod is not None and getattr(mod, "asammdf", None) is None:
        importlib.reload(mod)
    return True
