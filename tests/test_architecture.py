"""Dependency direction (STYLE.md): model/ depends on nothing of ours but units and
conventions; the pipeline (estimation, identification, prediction) never imports sim/, so it
cannot reach simulator ground truth by construction."""

import subprocess
import sys

import pytest


def imported_vdps_modules(module: str) -> set[str]:
    code = (f"import sys, importlib; importlib.import_module({module!r}); "
            "print('\\n'.join(m for m in sys.modules if m.startswith('vdps_hil')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    return set(out.stdout.split())


@pytest.mark.parametrize("module", ["vdps_hil.estimation", "vdps_hil.estimation.pipeline",
                                    "vdps_hil.identification", "vdps_hil.identification.problems",
                                    "vdps_hil.prediction", "vdps_hil.prediction.predictor",
                                    "vdps_hil.prediction.warning", "vdps_hil.pipeline.node",
                                    "vdps_hil.app.replay",
                                    "vdps_hil.workbench.diagnosis", "vdps_hil.cli.replay_cmd",
                                    "vdps_hil.cli.diagnose_cmd"])
def test_pipeline_never_imports_sim(module):
    mods = imported_vdps_modules(module)
    assert not any(m == "vdps_hil.sim" or m.startswith("vdps_hil.sim.") for m in mods), sorted(mods)


def test_model_imports_only_units_and_conventions():
    mods = imported_vdps_modules("vdps_hil.model.core") | imported_vdps_modules("vdps_hil.model.effects")
    allowed_prefixes = ("vdps_hil.model", "vdps_hil.units", "vdps_hil.conventions")
    extra = sorted(m for m in mods if m != "vdps_hil" and not m.startswith(allowed_prefixes))
    assert not extra, extra
