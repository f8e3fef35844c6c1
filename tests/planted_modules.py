"""Modules planted in a working directory to prove that no child process imports from it.

Each planted ``NAME.py`` writes ``MARKER_NAME`` into the directory it is imported from and then
fails the import: a child that put the working directory on ``sys.path`` leaves a marker (and
usually dies). The names are modules our children import before any of our code runs
(``json`` in ``replay_io``/``hil.child``, ``threading`` and ``pickle`` in multiprocessing's
spawn bootstrap, ``numpy``/``can``/``mcap`` in everything)."""

from __future__ import annotations

import sys
from pathlib import Path

NAMES = ("json", "threading", "pickle", "struct", "argparse", "socket", "selectors", "signal",
         "queue", "numpy", "can", "mcap", "zstandard", "click")

_BODY = ("import os\n"
         "open(os.path.join(os.path.dirname(os.path.abspath(__file__)), 'MARKER_{name}'), 'w').close()\n"
         "raise ImportError('planted module {name} imported from the working directory')\n")


def plant(directory: Path) -> Path:
    """Plant the modules in ``directory`` (made if needed); returns it. The test process itself
    must not have the working directory on its path (checked), or it would import them."""
    assert "" not in sys.path and "." not in sys.path, "the test process imports from its cwd"
    directory.mkdir(parents=True, exist_ok=True)
    for name in NAMES:
        (directory / f"{name}.py").write_text(_BODY.format(name=name))
    return directory


def markers(directory: Path) -> list[str]:
    """The markers left in ``directory`` (names of the planted modules that were imported)."""
    return sorted(p.name[len("MARKER_"):] for p in directory.glob("MARKER_*"))
