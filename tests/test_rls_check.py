"""The workbench's fitted parameters labelled by the identifier's outcome on the same drive
(``workbench.ranking.rls_check``): z of the two estimates, the verdict, the labels and their JSON."""

from __future__ import annotations

import json
import math

import pytest

from vdps_hil.workbench.estimator_run import RlsResult
from vdps_hil.workbench.ranking.results import RankEntry
from vdps_hil.workbench.ranking.rls_check import AGREE_Z, VERDICTS, agreement_z, cross_check, verdict


def _entry(param: str, value: float, sigma: float, kind: str = "parameter") -> RankEntry:
    return RankEntry(effect=param, kind=kind, explained_fraction=0.1, explained_by_equation={},
                     parameters={param: (value, sigma)}, plausible=True, excited=True, excitation_z=math.nan,
                     group=[])


def _rls(**per_param) -> RlsResult:
    """RlsResult from {param: (value, sigma, status)}."""
    return RlsResult({p: v for p, (v, s, st) in per_param.items()}, {p: s for p, (v, s, st) in per_param.items()},
                     {}, status={p: st for p, (v, s, st) in per_param.items()})


def test_z_is_the_difference_over_the_combined_sigma():
    assert agreement_z(103.0, 3.0, 99.0, 4.0) == 4.0 / 5.0
    assert agreement_z(1.0, math.nan, 0.0, 0.5) == 2.0  # a missing sigma counts as zero
    assert math.isnan(agreement_z(1.0, 0.0, 0.0, 0.0))  # no sigma at all: not comparable
    assert math.isnan(agreement_z(math.nan, 1.0, 0.0, 1.0))


def test_verdict_needs_the_identifier_to_have_identified_it_and_to_agree_within_three_sigma():
    assert AGREE_Z == 3.0 and set(VERDICTS) == {"agrees", "disagrees", "unconfirmed"}
    assert verdict("identified", 2.99) == "agrees" and verdict("identified", -3.0) == "agrees"
    assert verdict("identified", 3.01) == "disagrees" and verdict("identified", -7.4) == "disagrees"
    assert verdict("identified", math.nan) == "unconfirmed"
    for st in ("model mismatch", "at bound", "not excited", "not identifiable", "not converged"):
        assert verdict(st, 0.0) == "unconfirmed"  # agreeing values do not confirm an unidentified one


def test_cross_check_labels_parameters_only_and_nothing_without_the_identifier():
    mass, iz, cf = (_entry("mass_kg", 1469.0, 0.92), _entry("inertia_z_kgm2", 2705.0, 7.0),
                    _entry("cornering_stiffness_front_nprad", 229.8e3, 2.2e3))
    drag = _entry("aero_drag", 0.7, 0.01, kind="effect")
    rls = _rls(mass_kg=(1479.7, 1.13, "identified"), inertia_z_kgm2=(2612.0, 100.0, "identified"),
               cornering_stiffness_front_nprad=(154.1e3, 9.6e3, "model mismatch"))
    cross_check([mass, iz, cf, drag], rls)
    assert mass.identifier["verdict"] == "disagrees" and mass.identifier["z"] < -AGREE_Z
    assert iz.identifier["verdict"] == "agrees" and iz.identifier["value"] == 2612.0
    assert cf.identifier["verdict"] == "unconfirmed" and cf.identifier["status"] == "model mismatch"
    assert drag.identifier == {}
    fresh = _entry("mass_kg", 1469.0, 0.92)
    cross_check([fresh], None)
    assert fresh.identifier == {}
    other = _entry("anti_roll_stiffness_front_nmprad", 1e4, 1e3)  # not one of the identifier's ten
    cross_check([other], rls)
    assert other.identifier == {}


def test_the_labels_are_in_the_entry_json_without_nan():
    e = _entry("mass_kg", 1469.0, 0.92)
    cross_check([e], _rls(mass_kg=(1479.7, math.nan, "not converged")))
    doc = json.loads(json.dumps(e.to_json(), allow_nan=False))
    assert doc["identifier"]["verdict"] == "unconfirmed" and doc["identifier"]["status"] == "not converged"
    assert doc["identifier"]["sigma"] is None and doc["identifier"]["param"] == "mass_kg"
    assert "identifier" not in _entry("mass_kg", 1.0, 1.0).to_json()


CR_SEED = 41
"""Test seed of the CommonRoad check below: no study's or tuning set's seed (asserted)."""


def test_cr_seed_is_held_out():
    from vdps_hil.experiments import ident_study, workbench_study

    from vdps_hil.experiments.seeds import check_held_out

    check_held_out([CR_SEED], __name__)  # every tuning set's (experiments.seeds)
    for mod in (ident_study, workbench_study):
        assert CR_SEED not in mod.TUNING_SEEDS and CR_SEED not in mod.STUDY_SEEDS


def test_on_commonroad_nothing_the_identifier_rejects_is_called_identified(tmp_path):
    """On the independent truth (CommonRoad set 3, the 1 Hz sine with in-phase acceleration,
    read from /raw/ and the model file only; the study drives' 100 Hz suspension): the identifier
    runs in the estimator pass, a status for each of its ten parameters, its mass within 1 % of
    the truth (issue 17's bar; on this seed it calls the mass a "model mismatch" through the
    vertical row all the same, 0.05 % off: ``vdps replay`` says the same); every excited, plausible
    parameter of the base fit carries the identifier's verdict, and the summary's words call a
    value identified exactly when the identifier identified it too and agrees."""
    from vdps_hil.experiments.workbench_study import cached_drive
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.sim.cr_model import truth_figures
    from vdps_hil.workbench.dataset import DatasetConfig, load_drive
    from vdps_hil.workbench.ranking.selection import rank
    from vdps_hil.workbench.words import describe_entry

    veh = load_vehicle("cr3-model")
    path = cached_drive(tmp_path, "shipped:cr-sine-accel", (), CR_SEED, truth="commonroad-mb:3")
    tab = load_drive(path, veh, config=DatasetConfig(identify=True))
    assert tab.rls is not None and set(tab.rls.status) == set(tab.rls.params)
    assert tab.rls.params["mass_kg"] == pytest.approx(truth_figures(3)["mass_kg"], rel=0.01)
    rk = rank(tab, veh)
    cross_check(rk.parameters, tab.rls)
    checked = [e for e in rk.parameters if e.excited and e.plausible]
    assert checked
    for e in checked:
        v = e.identifier["verdict"]
        assert v in VERDICTS and e.identifier["status"] == tab.rls.status[e.identifier["param"]]
        head = describe_entry(rk, e).split(";")[0]
        assert ("identified" in head.split(" -- ")[0]) == (v == "agrees"), head
        if e.identifier["status"] in ("model mismatch", "at bound", "not excited"):
            assert "not confirmed" in head and e.identifier["status"] in head
