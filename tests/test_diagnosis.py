"""The whole diagnosis on a recording stripped to its /raw/ topics with the truth vehicle file out
of reach; the JSON has the issue's keys; a user effect takes part like a built-in one."""

from __future__ import annotations

import shutil

import pytest

from vdps_hil.experiments.workbench_study import HIDDEN, cached_drive
from vdps_hil.model import params as P
from vdps_hil.record.decode import copy_raw_topics
from vdps_hil.record.reader import RecordingReader
from vdps_hil.workbench.diagnosis import diagnose
from vdps_hil.workbench.user_effects import load_effect_file

SIDE_FORCE = '''
from vdps_hil.model.effects import DynamicsEffect, ParamSpec

class SideForce(DynamicsEffect):
    """side_force -- a constant lateral force F_y = side_force_n at the CG (a test effect)."""
    name = "side_force"
    HOOKS = ("body_wrench",)
    PARAMS = (ParamSpec("side_force_n", "N", 300.0, "constant lateral force", -5000.0, 5000.0),)

    def body_wrench(self, vel_b, omega_b, air_b):
        return (0.0, self.side_force_n, 0.0, 0.0, 0.0, 0.0)

    def regressors(self, q):
        return {"lat": {"side_force_n": 1.0}}
'''


@pytest.fixture(scope="module")
def stripped(drive_cache, tmp_path_factory):
    """The drag drive with only /raw/ left, and a vehicle directory holding only the model file."""
    d = tmp_path_factory.mktemp("raw_only")
    man, spec = HIDDEN["aero_drag"]
    src = cached_drive(drive_cache, man, [spec], seed=21)
    dst = d / "drive.mcap"
    copy_raw_topics(src, dst)
    vdir = d / "vehicles"
    vdir.mkdir()
    shutil.copy(P.VEHICLE_DIR / "sedan-model.toml", vdir / "sedan-model.toml")
    return dst, vdir


def test_only_raw_topics_and_the_model_file(stripped, monkeypatch, tmp_path):
    path, vdir = stripped
    with RecordingReader(path) as r:
        assert all(t.startswith("/raw/") for t in r.topics())
        assert not any(k.startswith("truth") for k in r.metadata())
    monkeypatch.setattr(P, "VEHICLE_DIR", vdir)  # sedan-truth.toml cannot be found now
    with pytest.raises(P.VehicleFileError):
        P.load_vehicle("sedan-truth")
    veh = P.load_vehicle("sedan-model")
    p = tmp_path / "my_effect.py"
    p.write_text(SIDE_FORCE)
    user = load_effect_file(p)
    dg = diagnose(path, veh, user_effects=user, save_model=tmp_path / "m.toml", with_simulation=True)
    doc = dg.to_json()
    assert set(doc) == {"ranking", "recommendation", "equivalent_to", "before", "after", "workbench"}
    for e in doc["ranking"]:
        assert set(e) == {"effect", "explained_fraction", "parameters", "plausible", "excited", "group"}
        for v in e["parameters"].values():
            assert set(v) == {"value", "sigma"}
    assert doc["recommendation"] == "aero_drag"
    assert "side_force" in [e["effect"] for e in doc["ranking"]]  # the user's effect took part
    side = next(e for e in doc["ranking"] if e["effect"] == "side_force")
    assert abs(side["parameters"]["side_force_n"]["value"]) < 100.0  # nothing of the kind is there
    assert doc["after"] is None
    assert set(doc["before"]["simulation_error"]) == {"0.5", "1", "2"}
    assert "long" in doc["before"]["residual_rms"]
    text = "\n".join(dg.summary_lines())
    assert "aerodynamic drag" in text and "explains" in text
    # every fitted parameter labelled by the identifier run on the same samples (rls_check);
    # "identified" in the text only where the identifier identified it and agrees
    ident = doc["workbench"]["identifier"]
    assert ident["status"]["mass_kg"] == "identified"
    assert ident["params"]["mass_kg"] == pytest.approx(1600.0, rel=0.01)  # issue 17's mass bar, truth 1600 kg
    lines = {p.effect: ln for p, ln in zip(dg.ranking.parameters, text.split("checked against the identifier):\n")[1]
                                           .splitlines())}
    for e in doc["workbench"]["identified_parameters"]:
        if not e["excited"] or not e["plausible"]:
            continue
        v = e["identifier"]["verdict"]
        assert v in ("agrees", "disagrees", "unconfirmed")
        assert ("identified" in lines[e["effect"]].split(" -- ")[0]) == (v == "agrees"), lines[e["effect"]]
    from vdps_hil.workbench.model_file import load_model

    v2, eff, _ = load_model(tmp_path / "m.toml", veh)
    assert v2.params.mass_kg == pytest.approx(1600.0, rel=0.03)


def test_add_through_the_diagnosis_fills_after(stripped, monkeypatch, tmp_path):
    path, vdir = stripped
    monkeypatch.setattr(P, "VEHICLE_DIR", vdir)
    veh = P.load_vehicle("sedan-model")
    # the before/after simulation errors of --add are tested in test_add (held-out refits); here
    # the residual tables and the saved model
    dg = diagnose(path, veh, add=["aero_drag"], save_model=tmp_path / "m.json", with_simulation=False)
    doc = dg.to_json()
    assert doc["after"]["residual_rms"]["long"] < 0.2 * doc["before"]["residual_rms"]["long"]
    # the change per equation, in the JSON and in the text; drag makes no balance worse
    change = doc["workbench"]["added"]["residual_change"]["long"]
    assert change < -0.8 and doc["workbench"]["added"]["worse"] == []
    line = next(ln for ln in dg.summary_lines() if ln.lstrip().startswith("long "))
    assert f"({100 * change:+.0f} %)" in line
    assert not any(ln.startswith("worse with") for ln in dg.summary_lines())
    lat0 = doc["before"]["residual_rms"]["lat"]
    dg.add.after["residual_rms"]["lat"] = 1.5 * lat0
    assert 0.5 * lat0 > 0.5 * dg.add.noise_sigma["lat"]  # above the noise floor of "worse"
    assert (f"worse with aerodynamic drag: the lat residual rose 50 % ({lat0:.4g} -> {1.5 * lat0:.4g} N)"
            in dg.summary_lines())
    # a held-out prediction error the effect made worse: a line, the JSON, the report's table
    q = ("position_m", "yaw_deg", "roll_deg", "speed_mps")
    dg.add.before["simulation_error"] = {"2": dict(zip(q, (0.5, 2.0, 1.0, 0.1)))}
    dg.add.after["simulation_error"] = {"2": dict(zip(q, (0.75, 2.1, 1.0, 0.1)))}
    assert ("worse with aerodynamic drag: the held-out 2 s prediction error rose: position 0.5 -> 0.75 m (+50 %)"
            in dg.summary_lines())
    assert dg.to_json()["workbench"]["added"]["worse_predictions"] == {"2": {"position_m": pytest.approx(0.5)}}
    from vdps_hil.workbench.report import render_report
    assert "<td>0.75 m (worse)</td>" in render_report(dg) and "<td>2.1 deg</td>" in render_report(dg)
    from vdps_hil.workbench.model_file import load_model

    _, eff, _ = load_model(tmp_path / "m.json", veh)
    assert eff["aero_drag"].cda_m2 == pytest.approx(0.7, abs=0.07)
    # the added effect's parameters with their status (workbench.added_params): fitted here
    cda = doc["workbench"]["added"]["parameters"]["aero_drag"]["cda_m2"]
    assert cda["status"] == "fitted" and cda["sigma"] > 0
    assert any(ln.startswith("  cda_m2: fitted ") and ln.endswith(" m^2") for ln in dg.summary_lines())
    # at a bound: never a result -- no sigma in the text or the saved file, named in the report
    from vdps_hil.workbench.added_params import parameter_entries
    from vdps_hil.workbench.diagnosis import _save_fitted
    from vdps_hil.workbench.model_file import read_model
    dg.add.parameters["aero_drag"] = parameter_entries(dg.add.fitted.effects["aero_drag"], {"cda_m2": 1e-3})
    dg.add.parameters["aero_drag"]["cda_m2"].update(value=3.0, status="at bound", bound="upper", sigma=None)
    line = next(ln for ln in dg.summary_lines() if ln.lstrip().startswith("cda_m2"))
    assert "AT BOUND -- 3 m^2, the upper bound of 0-3: not identified" in line and "+-" not in line
    assert "AT BOUND (upper bound 3): not identified" in render_report(dg)
    _save_fitted(tmp_path / "b.json", path, ["aero_drag"], dg.add, None, dg.ranking)
    assert read_model(tmp_path / "m.json").effect_sigmas["aero_drag"]["cda_m2"] > 0  # fitted: kept
    mf = read_model(tmp_path / "b.json")
    assert mf.source.endswith("; at bound, not identified: aero_drag.cda_m2")
    assert "cda_m2" not in mf.effect_sigmas.get("aero_drag", {}) and dict(mf.effects)["aero_drag"]["cda_m2"] > 0
