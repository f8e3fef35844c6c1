"""Third-party log readers that speak past our one-line errors, kept quiet while they open a file.

asammdf (python-can's ``.mf4`` reader) prints its own errors on a console handler of the
``asammdf`` logger ("asammdf - ERROR - Expected "##CG" block ..."), and when its reader fails
half-built (a truncated or damaged MF4) its ``__del__`` raises ``AttributeError`` in the garbage
collector, which Python prints as "Exception ignored in ... Traceback ...". Where its finalising
of an unfinished MF4 fails (the CANedge log cut at 30 %: "seek out of range") it prints the
traceback itself, ``print(format_exc())``, on standard output. The failure itself reaches the
user once, as the adapter's one-line error; :func:`library_noise_off` keeps all three off the
terminal while a reader opens (``sys.stdout`` is a sink for that moment, process-wide: nothing of
ours prints while a log opens), and :func:`collect_half_built`, called inside it, frees the
half-built reader before it ends.

asammdf also copies an unfinalised MF4 (a CANedge log) into the temporary folder to finalise it,
and deletes the copy only when the reader closes: a reader that fails while opening left the copy
behind, one per attempt. :func:`reader_scratch` makes a folder of ours for it (loading
python-can's MF4 support, ``deferred_imports.mf4_support``), :func:`reader_scratch_folder` points
asammdf there while the reader opens; the adapter removes the folder when it closes or fails.
"""

from __future__ import annotations

import gc
import io
import logging
import sys
import tempfile
from contextlib import contextmanager, redirect_stdout
from typing import Iterator

from vdps_hil.deferred_imports import mf4_support

__all__ = ["NOISY_LOGGERS", "library_noise_off", "collect_half_built", "reader_scratch", "reader_scratch_folder"]

NOISY_LOGGERS = ("asammdf",)
"""Loggers of readers that print on their own handlers (not through the root logger)."""


def _from_noisy_library(obj) -> bool:
    module = getattr(obj, "__module__", None) or type(obj).__module__ or ""
    return any(module == n or module.startswith(n + ".") for n in NOISY_LOGGERS)


@contextmanager
def library_noise_off() -> Iterator[None]:
    """Within the block: the :data:`NOISY_LOGGERS` are disabled, what is printed on ``sys.stdout``
    is dropped, and an exception raised in the
    ``__del__`` of one of their objects is dropped (any other still goes to Python's hook). Call
    ``gc.collect()`` inside the block (:func:`collect_half_built`) to let a failed reader's
    leftovers go while it applies."""
    loggers = [logging.getLogger(n) for n in NOISY_LOGGERS]
    disabled = [lg.disabled for lg in loggers]
    hook = sys.unraisablehook

    def quiet(unraisable) -> None:
        if not _from_noisy_library(unraisable.object):
            hook(unraisable)

    for lg in loggers:
        lg.disabled = True
    sys.unraisablehook = quiet
    try:
        with redirect_stdout(io.StringIO()):  # a library's own print(format_exc())
            yield
    finally:
        sys.unraisablehook = hook
        for lg, d in zip(loggers, disabled):
            lg.disabled = d


def collect_half_built() -> None:
    """Free a reader that failed in its constructor now (its frames may sit in a reference cycle),
    inside :func:`library_noise_off`."""
    gc.collect()


@contextmanager
def reader_scratch_folder(folder: tempfile.TemporaryDirectory | None) -> Iterator[None]:
    """Within the block, asammdf puts its working copies of a file in ``folder`` (its global
    ``temporary_folder`` option, restored after; the caller removes the folder when its reader is
    closed or has failed). Without asammdf installed, or with ``folder`` None, the block runs
    unchanged."""
    if folder is None:
        yield
        return
    try:
        from asammdf.blocks.options import GLOBAL_OPTIONS, set_global_option
    except ImportError:
        yield
        return
    before = GLOBAL_OPTIONS.get("temporary_folder")
    set_global_option("temporary_folder", folder.name)
    try:
        yield
    finally:
        set_global_option("temporary_folder", before)


def reader_scratch(suffix: str) -> tempfile.TemporaryDirectory | None:
    """For a ``.mf4`` log: python-can's MF4 support loaded and a fresh folder for asammdf's
    working copies (:func:`reader_scratch_folder`); None for any other format."""
    if suffix != ".mf4":
        return None
    mf4_support()
    return tempfile.TemporaryDirectory(prefix="vdps-mf4-")
