"""The held-out rule over every tuning set of the project (experiments.seeds): no study's seeds
are a tuning seed of any threshold, a tuning seed is refused by name, and the study tools refuse
one unless told the run is a tuning run."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from vdps_hil.experiments import seeds as S

TOOLS = Path(__file__).resolve().parents[1] / "tools"


def test_every_tuning_set_is_gathered_and_no_study_uses_any_tuning_seed():
    assert {0, 1, 2, 100, 101, 102, 103} <= S.tuning_seeds()
    for study, seeds in S.STUDIES.items():
        assert len(seeds) >= 10, study  # the issues ask for >= 10 seeds per configuration
        assert not set(seeds) & S.tuning_seeds(), study


def test_a_tuning_seed_is_refused_by_name_and_a_held_out_one_passes():
    S.check_held_out(range(113, 123), "a study")
    with pytest.raises(ValueError, match=r"^a study: seed 102 is a tuning seed of the workbench's ranking thresholds"):
        S.check_held_out([111, 102, 103], "a study")  # the identification study's old seeds


def test_held_out_seeds_skip_every_tuning_seed():
    assert S.held_out_seeds(1, 20) == list(range(3, 23))  # vdps paper's identification drives
    assert S.held_out_seeds(99, 3) == [99, 104, 105]
    assert not set(S.held_out_seeds(0, 200)) & S.tuning_seeds()


@pytest.mark.parametrize("tool, args", [
    ("ident_study.py", ["--seeds", "101", "103", "--cached-only"]),
    ("workbench_study.py", ["--first-seed", "100", "--seeds", "1", "--summary-only"]),
    ("workbench_study_cr.py", ["--first-seed", "102", "--seeds", "1"]),
])
def test_the_study_tools_refuse_a_tuning_seed_in_one_line(tool, args, tmp_path):
    # in safe-path mode, as a test worker's children are once a pool has run (app.children): the
    # tools import their siblings from tools/ themselves (workbench_study_cr failed so in CI)
    env = dict(os.environ, PYTHONSAFEPATH="1")
    r = subprocess.run([sys.executable, str(TOOLS / tool), *args], capture_output=True, text=True,
                       cwd=tmp_path, timeout=120, env=env)
    assert r.returncode == 2, r.stderr
    assert "is a tuning seed of" in r.stderr and "(or --tuning)" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
