"""The tree shows the layers: every import in ``vdps_hil/`` (top level and inside functions, read
with ``ast``, never executed) is checked against one declared layer order.

A module may import its own package and packages of earlier layers only. The order is the data
flow (README, "Layout"); the same list stands there. Two further rules:

* ``model/`` depends on nothing of ours but ``units`` and ``conventions`` (one physics core that
  the simulator, the estimator and the predictor share);
* simulator truth is read only in ``sim/`` and ``experiments/`` (and by the applications above
  them): no module of the truth-blind layers imports either, not even inside a function, so the
  estimator, identifier, predictor and workbench cannot reach a ``/truth/`` source by
  construction.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vdps_hil"

# One entry per layer, in data-flow order (README "Layout"). A package may import packages of
# earlier layers; two packages of one layer may not import each other, except the leaf modules
# of layer 0 (units, conventions, geodesy, jit, deferred_imports).
LAYERS: list[tuple[str, ...]] = [
    ("units", "conventions", "geodesy", "jit", "deferred_imports"),
    ("bus",),
    ("codecs",),
    ("adapters",),
    ("record",),
    ("model",),
    ("estimation",),
    ("identification",),
    ("prediction",),
    ("pipeline",),
    ("workbench",),
    ("realdata",),
    ("app",),
    ("sim",),
    ("experiments",),
    ("hil", "batch"),
    ("cli",),
]
TRUTH = {"sim", "experiments"}
TRUTH_BLIND = {p for layer in LAYERS[: [i for i, l in enumerate(LAYERS) if "sim" in l][0]] for p in layer}
MODEL_MAY_IMPORT = {"model", "units", "conventions", "jit"}
LAYER_OF = {pkg: i for i, layer in enumerate(LAYERS) for pkg in layer}


def _module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _top(module: str) -> str | None:
    """'vdps_hil.estimation.ekf' -> 'estimation'; 'vdps_hil' itself -> None."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "vdps_hil" else None


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


@functools.lru_cache(maxsize=None)
def _parse(source: str) -> ast.Module:
    """The syntax tree of a source text, made once per text (each module is read by three tests;
    nothing changes a tree)."""
    return ast.parse(source)


def imports_of(path: Path, package_dir: Path = PACKAGE, include_type_only: bool = True) -> list[tuple[str, int]]:
    """Every vdps_hil module this file imports, with its line: absolute and relative imports,
    at any depth (inside functions, classes, if/try blocks, ``importlib.import_module("...")``
    with a literal name). ``from pkg import name`` counts as importing ``pkg.name`` when that
    is a module of the tree, else ``pkg``. ``include_type_only=False`` leaves out the imports
    under ``if TYPE_CHECKING:`` (annotations only: never executed, so no import cycle)."""
    name = _module_name(path, package_dir)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    root = package_dir.parent
    found = []
    tree = _parse(path.read_text(encoding="utf-8"))
    type_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If) and _is_type_checking(block.test)
                 for stmt in block.body for n in ast.walk(stmt)}
    for node in ast.walk(tree):
        if id(node) in type_only and not include_type_only:
            continue
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                as_module = root.joinpath(*sub.split("."))
                found.append((sub if as_module.with_suffix(".py").exists() or as_module.is_dir() else target, node.lineno))
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module":
            if node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
                found.append((node.args[0].value, node.lineno))
    return [(t, ln) for t, ln in found if t == "vdps_hil" or t.startswith("vdps_hil.")]


SOURCES = sorted(PACKAGE.rglob("*.py"))


def test_every_package_is_in_the_layer_order():
    tops = {_top(_module_name(p)) for p in SOURCES} - {None}
    assert tops <= set(LAYER_OF), sorted(tops - set(LAYER_OF))


def layer_violations(path: Path, package_dir: Path = PACKAGE) -> list[str]:
    """The imports of one file that break the layer order, the model rule or the truth rule."""
    here = _top(_module_name(path, package_dir))
    if here is None:  # the package itself: only layer 0's leaves (importing vdps_hil drags no layer in)
        return [f"line {line}: vdps_hil/__init__.py imports {t}" for t, line in imports_of(path, package_dir)
                if LAYER_OF.get(_top(t)) != 0]
    bad = []
    for target, line in imports_of(path, package_dir):
        there = _top(target)
        if there is None or there == here:
            continue
        if there not in LAYER_OF:
            bad.append(f"line {line}: {target} is in no layer")
            continue
        if LAYER_OF[there] > LAYER_OF[here] or (LAYER_OF[there] == LAYER_OF[here] and LAYER_OF[here] != 0):
            bad.append(f"line {line}: {target} (layer {LAYER_OF[there]} {there}) from layer {LAYER_OF[here]} {here}")
        if here == "model" and there not in MODEL_MAY_IMPORT:
            bad.append(f"line {line}: model/ imports {target}")
        if here in TRUTH_BLIND and there in TRUTH:
            bad.append(f"line {line}: truth-blind {here}/ imports {target}")
    return bad


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (module -> imported modules), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if t not in graph:
                continue
            if state.get(t) == 1:
                return stack[stack.index(t):] + [t]
            if not state.get(t):
                cycle = visit(t)
                if cycle:
                    return cycle
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if not state.get(m):
            cycle = visit(m)
            if cycle:
                return cycle
    return None


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_follow_the_layer_order(path):
    bad = layer_violations(path)
    assert not bad, "\n".join(bad)


def test_no_import_cycle_between_modules():
    """No module imports itself through others at run time (the layer test above already
    forbids cycles between packages; this one catches them inside a package, such as the
    driver <-> scenarios cycle there was in sim/, hidden by in-function imports)."""
    graph = {_module_name(p): {t for t, _ in imports_of(p, include_type_only=False)} for p in SOURCES}
    cycle = find_cycle(graph)
    assert cycle is None, " -> ".join(cycle)


def test_the_reader_finds_hidden_relative_and_dynamic_imports(tmp_path):
    """The reader itself, on a small tree of its own: an import inside a function, a relative
    import, ``from package import module`` and ``importlib.import_module`` are all found."""
    pkg = tmp_path / "vdps_hil"
    (pkg / "estimation").mkdir(parents=True)
    (pkg / "sim").mkdir()
    for f in (pkg / "__init__.py", pkg / "estimation" / "__init__.py", pkg / "sim" / "__init__.py",
              pkg / "sim" / "drive.py", pkg / "estimation" / "ekf.py"):
        f.write_text("")
    probe = pkg / "estimation" / "probe.py"
    probe.write_text("import importlib\n"
                     "def f():\n    from vdps_hil.sim import drive\n"
                     "def g():\n    from . import ekf\n    from ..sim.drive import x\n"
                     "def h():\n    return importlib.import_module('vdps_hil.sim')\n")
    got = imports_of(probe, pkg)
    assert ("vdps_hil.sim.drive", 3) in got  # inside a function, package.module form
    assert ("vdps_hil.estimation.ekf", 5) in got  # relative
    assert ("vdps_hil.sim.drive", 6) in got  # relative, two levels
    assert ("vdps_hil.sim", 8) in got  # dynamic import with a literal name


def test_the_checks_fail_on_an_upward_import_a_truth_import_and_a_cycle(tmp_path):
    """The rules themselves, on a small tree: estimation importing the pipeline node (upward)
    and sim (truth), model importing estimation, and a two-module cycle are all reported."""
    pkg = tmp_path / "vdps_hil"
    for d in ("estimation", "pipeline", "sim", "model"):
        (pkg / d).mkdir(parents=True)
        (pkg / d / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "pipeline" / "node.py").write_text("")
    (pkg / "sim" / "drive.py").write_text("")
    bad_est = pkg / "estimation" / "bad.py"
    bad_est.write_text("def f():\n    from vdps_hil.pipeline import node\n    import vdps_hil.sim.drive\n")
    bad_model = pkg / "model" / "core.py"
    bad_model.write_text("from vdps_hil.estimation import bad\n")
    est = layer_violations(bad_est, pkg)
    assert any("layer 9 pipeline" in b for b in est) and any("truth-blind estimation/" in b for b in est)
    assert any("model/ imports vdps_hil.estimation.bad" in b for b in layer_violations(bad_model, pkg))
    assert find_cycle({"a": {"b"}, "b": {"a"}}) == ["a", "b", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
KERNEL_MARK = "hand-specialised"
"""A function longer than MAX_FUNCTION_LINES is allowed only as a numeric kernel whose
docstring (or its enclosing function's) says it is hand-specialised; such kernels are tested
equal to their reference (e.g. tests/test_reduced.py)."""


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_modules_and_functions_fit_in_a_head(path):
    src = path.read_text(encoding="utf-8")
    assert len(src.splitlines()) <= MAX_MODULE_LINES
    tree = _parse(src)
    too_long = []

    def walk(node, kernel: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                k = kernel or KERNEL_MARK in (ast.get_docstring(child) or "")
                if child.end_lineno - child.lineno + 1 > MAX_FUNCTION_LINES and not k:
                    too_long.append(f"{child.name} (line {child.lineno})")
                walk(child, k)
            else:
                walk(child, kernel)

    walk(tree, False)
    assert not too_long, too_long
