"""tools/suite_cpu.py: the attribution of a py-spy raw profile (stacks written by hand in py-spy's
``--format raw`` layout: frames root first, separated by ';', then the sample count)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("suite_cpu", REPO / "tools" / "suite_cpu.py")
suite_cpu = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(suite_cpu)

SITE = "/x/.venv/lib/python3.11/site-packages"
RAW = "\n".join([
    # an import of numba, reached through a vdps_hil module body: the first third-party package
    f"process 1:\"pytest\";<module> (vdps_hil/model/chassis.py:71);_find_and_load (<frozen importlib._bootstrap>:1176);"
    f"<module> ({SITE}/numba/__init__.py:5);<module> ({SITE}/llvmlite/binding/ffi.py:9) 7",
    # the workbench's estimator pass, inside a ranking test: the ranking is not on this stack
    "process 1:\"pytest\";load_drive (vdps_hil/workbench/dataset.py:381);run_system (vdps_hil/workbench/estimator_run.py:87);"
    "VdpsSystem.handle (vdps_hil/pipeline/node.py:188) 5",
    # the ranking itself
    "process 1:\"pytest\";rank (vdps_hil/workbench/ranking/selection.py:137);gram (vdps_hil/workbench/ranking/gram.py:67) 3",
    "process 2:\"vdps replay\";VdpsSystem.handle (vdps_hil/pipeline/node.py:188);update (x.py:1) 4",
    "process 2:\"vdps replay\";main (vdps_hil/cli/main.py:1) 1",
    "garbage line without a count",
]) + "\n"


def test_samples_are_attributed_by_the_first_matching_category(tmp_path):
    raw = tmp_path / "s.raw"
    raw.write_text(RAW)
    rep = suite_cpu.report(raw)
    assert rep["samples"] == 20
    assert dict(rep["categories"]) == {"importing modules": 7, "workbench: estimator pass (load_drive)": 5,
                                       "workbench: ranking": 3, "replays and chain runs (VdpsSystem)": 4, "other": 1}
    assert dict(rep["imports"]) == {"numba": 7}
    assert dict(rep["own"])["VdpsSystem.handle (vdps_hil/pipeline/node.py)"] == 5


def test_a_missing_profile_is_one_line_and_exit_2(tmp_path):
    p = subprocess.run([sys.executable, str(REPO / "tools" / "suite_cpu.py"), "report", str(tmp_path / "none.raw")],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and p.stdout == "" and p.stderr.count("\n") == 1 and "no such file" in p.stderr
