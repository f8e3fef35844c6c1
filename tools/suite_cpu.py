#!/usr/bin/env python3
"""Where the test suite's CPU goes (issue 19: ``make test`` <= 10 minutes on 2 cores).

Records the first phase of ``make test`` (everything but the real-time tests, the same pytest
options) under py-spy, sampling every Python process the suite starts (xdist workers, process
pools, ``vdps`` commands, bench children), and attributes the samples: by the work on the stack
(importing modules, with the first third-party package imported; the estimator's sample path;
the workbench's estimator pass, ranking and ``--add``; simulating drives; replays; the rest), and
the functions with the most samples of their own. A sample is one thread seen running Python
code at one instant (py-spy leaves out threads it sees idle), so the shares are shares of the
CPU the suite's Python used.

py-spy is not a dependency of the project: install it anywhere (``pip install py-spy`` in any
environment) and name it with ``--py-spy`` when it is not on the PATH. Recording runs the suite
once (12-13 minutes here) and slows it a little (25 samples a second).

Usage::

    python tools/suite_cpu.py record [--py-spy PATH] [--rate 25] [-o suite.raw] [-- PYTEST_ARGS]
    python tools/suite_cpu.py report suite.raw [--top 30]
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

CATEGORIES = (
    # (name, a pattern that a frame on the stack matches); the first match wins
    ("importing modules", r"^_find_and_load \("),
    ("numba loading cached kernels", r"^Cache\.load_overload \("),
    ("workbench: ranking", r"^rank \(.*ranking/selection\.py"),
    ("workbench: --add", r"^add_effects \(.*workbench/add\.py"),
    ("workbench: estimator pass (load_drive)", r"^load_drive \(.*workbench/dataset\.py"),
    ("simulating drives", r"^(Drive\.run|Simulator\.\w+) \("),
    ("replays and chain runs (VdpsSystem)", r"^VdpsSystem\.handle \("),
    ("decoding recordings", r"^DecodedRecording\._run \("),
    ("pytest collection", r"^pytest_collection \("),
)
"""Categories of a sample, by the frames on its stack."""
_CATEGORY_RE = [(name, re.compile(pattern)) for name, pattern in CATEGORIES]

FRAME = re.compile(r"^(?P<fn>.*) \((?P<path>.*?):(?P<line>\d+)\)$")


def _relative(path: str) -> str:
    """A module file's path from its import root (site-packages, the standard library, this repo)."""
    path = path.split("/site-packages/")[-1].replace(str(REPO) + "/", "")
    return re.sub(r".*/lib/python3\.\d+/", "", path)


def _short(frame: str) -> str:
    m = FRAME.match(frame)
    if not m:
        return frame[:80]
    return f"{m['fn']} ({_relative(m['path'])})"


def _package(path: str) -> str:
    """The top-level package of a module file (``vdps_hil`` itself as ``vdps_hil/<subpackage>``)."""
    parts = _relative(path).split("/")
    return "/".join(parts[:2]) if parts[0] == "vdps_hil" else parts[0]


def report(raw: Path, top: int = 30) -> dict:
    """The attribution of a py-spy ``--format raw`` file (module docstring)."""
    total = 0
    cats: collections.Counter = collections.Counter()
    imports: collections.Counter = collections.Counter()
    own: collections.Counter = collections.Counter()
    with open(raw, encoding="utf-8", errors="replace") as f:
        for line in f:
            stack, _, n = line.rstrip("\n").rpartition(" ")
            if not n.isdigit():
                continue
            n = int(n)
            frames = stack.split(";")
            total += n
            own[_short(frames[-1])] += n
            cat = next((name for name, rx in _CATEGORY_RE if any(rx.match(fr) for fr in frames)), "other")
            cats[cat] += n
            if cat == "importing modules":
                first = next(i for i, fr in enumerate(frames) if fr.startswith("_find_and_load ("))
                mods = [FRAME.match(fr) for fr in frames[first:] if fr.startswith("<module> (")]
                pkgs = [_package(m["path"]) for m in mods if m]
                third = [p for p in pkgs if not p.startswith("vdps_hil") and not p.endswith(".py")]
                imports[third[0] if third else (pkgs[0] if pkgs else "(loading, before a module body runs)")] += n
    return {"samples": total, "categories": cats.most_common(), "imports": imports.most_common(top),
            "own": own.most_common(top)}


def _print(rep: dict) -> None:
    total = max(1, rep["samples"])
    print(f"{rep['samples']} samples")
    for title, key in (("by the work on the stack", "categories"),
                       ("imports, by the first third-party package imported", "imports"),
                       ("functions, by their own samples", "own")):
        print(f"\n{title}:")
        for name, n in rep[key]:
            print(f"  {100 * n / total:5.1f} %  {n:7d}  {name}")


def record(py_spy: str, rate: int, out: Path, pytest_args: list[str]) -> int:
    """Run the first phase of ``make test`` under py-spy (module docstring)."""
    python = REPO / ".venv" / "bin" / "python"
    workers = str((os.cpu_count() or 1) + 1)
    args = pytest_args or ["-q", "-p", "no:cacheprovider", "--timeout", "600", "-n", workers, "--dist", "loadfile",
                           "-m", "not realtime", "tests"]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    cmd = [py_spy, "record", "--subprocesses", "--nonblocking", "--rate", str(rate), "--format", "raw",
           "-o", str(out), "--", str(python), "-m", "pytest", *args]
    return subprocess.call(cmd, cwd=REPO, env=env)


def main(argv: list[str] | None = None) -> int:
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `... | head` ends the report quietly
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="run the suite's first phase under py-spy")
    r.add_argument("--py-spy", default=shutil.which("py-spy") or "py-spy")
    r.add_argument("--rate", type=int, default=25)
    r.add_argument("-o", "--output", type=Path, default=Path("suite.raw"))
    r.add_argument("pytest_args", nargs="*")
    p = sub.add_parser("report", help="attribute a recorded profile")
    p.add_argument("raw", type=Path)
    p.add_argument("--top", type=int, default=30)
    a = ap.parse_args(argv)
    if a.cmd == "record":
        if not shutil.which(a.py_spy) and not os.path.isfile(a.py_spy):
            print(f"suite_cpu: py-spy not found ({a.py_spy}); install it and pass --py-spy PATH", file=sys.stderr)
            return 2
        return record(a.py_spy, a.rate, a.output, a.pytest_args)
    if not a.raw.is_file():
        print(f"suite_cpu: {a.raw}: no such file", file=sys.stderr)
        return 2
    _print(report(a.raw, a.top))
    return 0


if __name__ == "__main__":
    sys.exit(main())
