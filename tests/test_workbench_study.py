"""The study definitions: maneuvers parse, effects exist, hit definition, Wilson interval."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from scipy.stats import binomtest

from vdps_hil.experiments import workbench_study as S
from vdps_hil.model.effects import REGISTRY
from vdps_hil.sim.drive import parse_effect_spec


def test_every_maneuver_parses_and_every_effect_is_known():
    for name in S.MANEUVERS:
        sc = S.scenario(name)
        assert sc.effect_names == () and sc.duration_s <= 20.0
    for eff, (man, spec) in S.HIDDEN.items():
        assert man in S.MANEUVERS and eff in REGISTRY
        n, params = parse_effect_spec(spec)
        assert n == eff
        REGISTRY[n](**params)  # magnitudes are valid


def test_shipped_scenarios_keep_their_truth():
    """A shipped scenario is a maneuver of the study as shipped: its own truth vehicle and the
    Magic Formula tire (issue 18's 'own scenarios'), its own duration; an unknown name says so."""
    for name in ("sine-sweep", "lane-change-iso3888", "coast-down"):
        sc = S.scenario(S.SHIPPED + name)
        assert sc.name == name and "magic_formula_tire" in sc.effect_names and sc.vehicle.kind == "truth"
    assert S.scenario("sine-sweep").effect_names == ()  # the study's own maneuver of that name
    with pytest.raises(ValueError, match="own duration"):
        S.scenario(S.SHIPPED + "coast-down", duration_s=10.0)
    for bad in ("no-such-maneuver", "shipped:no-such", "lane-change-iso3888"):
        with pytest.raises(KeyError, match="neither"):
            S.maneuver_text(bad)


def test_issue_magnitudes():
    assert S.HIDDEN["aero_drag"][1].endswith("cda_m2=0.7")
    assert "coefficient=0.012" in S.HIDDEN["rolling_resistance"][1]
    assert "radius_reduction=0.015" in S.HIDDEN["low_pressure_tire"][1]
    assert "wind_speed_mps=10" in S.HIDDEN["crosswind"][1]
    assert "lever_x_m=0.5" in S.HIDDEN["imu_lever_arm"][1]
    b = REGISTRY["imu_bias"]()
    assert b.accel_bias_x_mps2 == 0.05 and abs(b.gyro_bias_z_radps - 0.1 * 3.141592653589793 / 180) < 1e-12


def _rk(rec=None, eq=(), groups=()):
    return SimpleNamespace(recommendation=rec, equivalent_to=list(eq), groups=[{"members": list(g)} for g in groups])


def test_hit_definition():
    assert S.is_hit(_rk("aero_drag"), "aero_drag")
    assert S.is_hit(_rk("cornering_stiffness_front", groups=[("cornering_stiffness_front", "steering_compliance")]),
                    "steering_compliance")
    assert S.is_hit(_rk("magic_formula_tire", eq=["load_dependent_cornering_stiffness"]),
                    "load_dependent_cornering_stiffness")
    assert not S.is_hit(_rk(None), "aero_drag")
    assert not S.is_hit(_rk(None, groups=[("mass", "imu_bias"), ("aero_drag", "imu_bias")]), "aero_drag")
    assert not S.is_hit(_rk("crosswind"), "aero_drag")
    # a top group with nothing recommended is "no missing effect found", not a hit
    assert not S.is_hit(_rk(None, groups=[("aero_drag", "rolling_resistance")]), "aero_drag")
    assert not S.is_hit(_rk("imu_bias", groups=[("aero_drag", "rolling_resistance")]), "aero_drag")


@pytest.mark.parametrize("k, n", [(0, 20), (18, 20), (20, 20), (7, 13)])
def test_wilson_interval_matches_scipy(k, n):
    lo, hi = S.wilson_interval(k, n)
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert lo == pytest.approx(ci.low, abs=1e-9) and hi == pytest.approx(ci.high, abs=1e-9)


def test_the_model_file_follows_the_truth_backend():
    """A drive of CommonRoad's set N is diagnosed with ``crN-model``, ours with ``sedan-model``;
    set 2 (the held-out acceptance set) and unknown backends are refused."""
    from vdps_hil.experiments.workbench_study import model_file

    assert model_file(None) == "sedan-model"
    assert model_file("commonroad-mb:1") == "cr1-model" and model_file("commonroad-mb:3") == "cr3-model"
    assert model_file("commonroad-mb:3:linear-lateral") == "cr3-model"  # the same vehicle, tires unsaturated
    for bad in ("commonroad-mb:2", "commonroad-ks:1", "ours", "commonroad-mb:1:brush", "commonroad-mb:2:linear-lateral"):
        with pytest.raises(ValueError, match="unknown study truth"):
            model_file(bad)


def test_processes_sharing_a_drive_folder_simulate_each_drive_once(tmp_path, monkeypatch):
    """cached_drive's lock: two callers asking for one drive at once (threads here, each with its
    own open file, which flock treats as two holders) simulate it once; the other waits and reads
    the file; a drive with another key is simulated for itself."""
    import threading
    import time

    calls = []

    def fake_drive(path, maneuver, effects=(), seed=0, duration_s=None, truth=None):
        calls.append((maneuver, seed))
        time.sleep(0.3)  # long enough for the other caller to arrive while this one holds the lock
        with open(path, "wb") as f:
            f.write(b"drive")

    monkeypatch.setattr(S, "hidden_drive", fake_drive)
    got = []
    threads = [threading.Thread(target=lambda: got.append(S.cached_drive(tmp_path, "step-steer", (), seed=5)))
               for _ in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert calls == [("step-steer", 5)] and len(set(got)) == 1
    assert open(got[0], "rb").read() == b"drive"
    S.cached_drive(tmp_path, "step-steer", (), seed=6)
    assert calls == [("step-steer", 5), ("step-steer", 6)]
    assert not list(tmp_path.glob("*.tmp"))


def test_a_model_effect_of_a_job_is_in_the_model_it_ranks_against(drive_cache):
    """``run_job``'s ``model_effects`` (``tools/workbench_study_cr.py --model-effect``): the model
    carries the effect, so it is no candidate; with the hidden drag itself in the model (seed 21's
    accel-coast, C_d A 0.7), nothing is missing and nothing is recommended."""
    from vdps_hil.experiments.workbench_study import HIDDEN, run_job

    man, spec = HIDDEN["aero_drag"]
    r = run_job({"maneuver": man, "specs": [spec], "seed": 21, "cache": str(drive_cache), "model_effects": [spec]})
    assert "error" not in r, r.get("error")
    assert "aero_drag" not in r["entries"] and r["recommendation"] is None, (r["recommendation"], r["messages"])
