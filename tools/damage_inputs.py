#!/usr/bin/env python3
"""Damage an input file many ways and run a vdps command on each copy: every run must end in a
result or a one-line error (exit 0 or 2), never an internal error (exit 1), a traceback, a
signal or a crash (the brief's bad-input rule, tried as a user would).

Usage::

    .venv/bin/python tools/damage_inputs.py toml  FILE [--reps 0123456] -- vdps ARGS... {} ...
    .venv/bin/python tools/damage_inputs.py bytes FILE [--seed 5]       -- vdps ARGS... {} ...

``{}`` in the command is the damaged copy's path. ``toml``: each leaf of the TOML file (tables,
arrays of tables and inline tables followed) replaced in turn by -1.0, 0, nan, 1e300, a string, a
list, true (``--reps`` picks them by index). ``bytes``: cut at 0-99 %, 1/10/100/200 random bytes
flipped, a random burst, random bytes. The copies are written next to nothing of the project
(a temporary directory). Prints each bad case and the count; exit status 1 when any was bad.

Used 2026-12-06 on the sensor sets, signal maps, sensor profiles, scenarios and vehicle files, on
recordings (``vdps replay``, ``diagnose``, ``info``, ``export``, ``plot``, ``recover``) and on
real CAN/NMEA/MF4 logs and a DBC (``vdps import``): README, "Bad input".
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import tomllib

REPLACEMENTS = (-1.0, 0, float("nan"), 1e300, "zz", [1, 2], True)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {v!r} as TOML")


def toml_text(doc: dict, prefix: str = "") -> str:
    """``doc`` as TOML: scalars first, then each sub-table (arrays of tables inline)."""
    lines, tables = [], []
    for k, v in doc.items():
        (tables if isinstance(v, dict) else lines).append((k, v))
    out = [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in lines]
    for k, v in tables:
        name = f"{prefix}.{json.dumps(k)}" if prefix else json.dumps(k)
        out += [f"\n[{name}]", toml_text(v, name)]
    return "\n".join(out)


def leaves(node, path=()):
    """(path, value) of every leaf, through tables and arrays of tables."""
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for k, v in items:
        if isinstance(v, dict) or (isinstance(v, list) and v and all(isinstance(x, dict) for x in v)):
            yield from leaves(v, path + (k,))
        else:
            yield path + (k,), v


def with_leaf(doc: dict, path, value) -> dict:
    out = copy.deepcopy(doc)
    node = out
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return out


def toml_cases(path: str, reps: str):
    doc = tomllib.load(open(path, "rb"))
    chosen = [REPLACEMENTS[int(i)] for i in reps]
    for p, v in leaves(doc):
        for rep in chosen:
            if type(rep) is type(v) and rep == v:
                continue
            yield f"{'.'.join(map(str, p))}={rep!r}", toml_text(with_leaf(doc, p, rep)).encode()


def byte_cases(path: str, seed: int):
    data = open(path, "rb").read()
    n, rnd = len(data), random.Random(seed)
    for frac in (0.0, 0.01, 0.03, 0.1, 0.2, 0.3, 0.37, 0.5, 0.61, 0.73, 0.9, 0.99):
        yield f"cut at {frac:.0%}", data[: int(n * frac)]
    for k, count in enumerate((1, 10, 100, 200) * 2):
        b = bytearray(data)
        for _ in range(count):
            b[rnd.randrange(n)] = rnd.randrange(256)
        yield f"{count} bytes flipped (#{k})", bytes(b)
    for k in range(3):
        b = bytearray(data)
        i, length = rnd.randrange(n), rnd.randrange(1, 5000)
        b[i:i + length] = rnd.randbytes(length)
        yield f"burst of {length} at {i}", bytes(b)
    yield "random bytes", rnd.randbytes(min(n, 300_000))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--" not in argv:
        print(__doc__.split("Usage::")[1].split("``{}``")[0].rstrip(), file=sys.stderr)
        return 2
    cut = argv.index("--")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("toml", "bytes"))
    ap.add_argument("file")
    ap.add_argument("--reps", default="0123456", help="indices into the replacements (toml)")
    ap.add_argument("--seed", type=int, default=5, help="random damage (bytes)")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per run")
    a = ap.parse_args(argv[:cut])
    # run in a scratch directory (outputs a command writes by default land there): arguments that
    # name an existing file or directory here are passed as absolute paths
    command = [os.path.abspath(c) if "{}" not in c and os.path.exists(c) else c for c in argv[cut + 1:]]
    if not command or not any("{}" in c for c in command):
        ap.error("the command after -- needs {} where the damaged file goes")
    ext = os.path.splitext(a.file)[1]
    cases = toml_cases(a.file, a.reps) if a.mode == "toml" else byte_cases(a.file, a.seed)
    bad = total = 0
    with tempfile.TemporaryDirectory() as td:
        damaged = os.path.join(td, f"damaged{ext}")
        for label, blob in cases:
            with open(damaged, "wb") as f:
                f.write(blob)
            try:
                r = subprocess.run([c.replace("{}", damaged) for c in command], capture_output=True, text=True,
                                   timeout=a.timeout, cwd=td)
                code, err = r.returncode, r.stderr + r.stdout  # a library may print a traceback on stdout
            except subprocess.TimeoutExpired:
                code, err = "timeout", ""
            total += 1
            if code not in (0, 2) or "Traceback" in err or "Fatal Python error" in err:
                bad += 1
                last = (err.strip().splitlines() or [""])[-1]
                print(f"BAD {label}: exit {code}: {last[:200]}", flush=True)
    print(f"{total} cases, {bad} bad")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
