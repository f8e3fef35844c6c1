"""The candidate interface: parameter spaces, plausibility and materiality; parameter candidates."""

from __future__ import annotations

from vdps_hil.model.effects import REGISTRY
from vdps_hil.model.params import load_vehicle
from vdps_hil.workbench import candidate_base as CB
from vdps_hil.workbench import candidates as C


def test_plausibility_and_materiality():
    drag = C.candidate_for(REGISTRY["aero_drag"])
    assert drag.plausible([0.7]) and not drag.plausible([-0.1])
    assert drag.material([0.7]) and not drag.material([0.02])
    assert drag.clip_phi([-0.3])[0] == 0.0
    lp = C.candidate_for(REGISTRY["low_pressure_tire"])
    assert not lp.material([0.0003]) and lp.material([0.015])


def test_parameter_candidate():
    p = CB.ParameterCandidate("mass_kg", load_vehicle("sedan-model"))
    assert p.name == "mass" and p.kind == "parameter" and p.plausible([1.0]) and not p.plausible([-1.0])
