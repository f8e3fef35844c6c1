"""Tests of vdps_hil.batch.report: the robust fleet comparison flags the drive where the mass
jumped (and not a drive that merely identified it poorly), result layouts are read, and the
HTML page holds the plots, the flagged drives, the effects per drive and the failures."""

from __future__ import annotations

import base64
import json
import re

import pytest

from vdps_hil.batch.engine import EngineConfig
from vdps_hil.batch.runner import run_batch
from vdps_hil.batch.worker import Task
from vdps_hil.batch.report import (aggregate_from_dir, identified_params, parameter_flags,
                                   prior_params, recommended_effects, render_html, write_report)


def _fleet(rng, n=12, jump_at=7, jump_kg=320.0):
    """A fleet of drives of one car: mass 1520 kg identified with sigma 8-15 kg, one drive with
    a trailer (+jump_kg), one drive with a poorly identified mass (sigma 400 kg)."""
    tasks = []
    for i in range(n):
        sig = float(rng.uniform(8.0, 15.0))
        m = 1520.0 + float(rng.normal(0.0, sig))
        if i == jump_at:
            m += jump_kg
        if i == 2:
            sig, m = 400.0, 1900.0
        iz = 2900.0 + float(rng.normal(0, 30))
        result = {"identification": {"params": {"mass_kg": m, "inertia_z_kgm2": iz},
                                     "sigmas": {"mass_kg": sig, "inertia_z_kgm2": 30.0}},
                  "recommended_effects": ["aero_drag"] + (["trailer_load"] if i == jump_at else [])}
        tasks.append({"id": f"drive{i:02d}", "input": f"/d/drive{i:02d}.mcap", "status": "ok",
                      "result": result, "error": None, "run": {"wall_s": 1.0, "peak_rss_mib": 100.0}})
    tasks.append({"id": "broken", "input": "/d/broken.mcap", "status": "failed", "result": None,
                  "error": {"type": "RecordingError", "message": "bad magic <&> here"}, "run": {}})
    return {"kind": "diagnose", "tool": "0.1.0+src.test", "options": {"vehicle": "sedan-model"},
            "counts": {"total": n + 1, "ok": n, "failed": 1}, "tasks": tasks,
            "failed": [{"id": "broken", "error": tasks[-1]["error"]}],
            "run": {"engine": {"backend": "dask", "workers": 2}, "wall_s": 3.0, "computed": n + 1,
                    "reused": 0}}


def test_the_drive_where_the_mass_jumped_is_flagged_and_only_it(rng):
    agg = _fleet(rng)
    vals = [t["result"]["identification"]["params"]["mass_kg"] for t in agg["tasks"][:-1]]
    sigs = [t["result"]["identification"]["sigmas"]["mass_kg"] for t in agg["tasks"][:-1]]
    ref, s_ref, z = parameter_flags(vals, sigs)
    assert ref == pytest.approx(1520.0, abs=15.0)  # the trailer does not move the median
    flagged = [i for i, zi in enumerate(z) if abs(zi) > 3.0]
    assert flagged == [7]
    assert abs(z[2]) < 3.0  # 380 kg off but sigma 400 kg: not evidence of a change


def test_a_consistent_fleet_flags_nobody(rng):
    vals = list(1520.0 + rng.normal(0.0, 10.0, 30))
    _, _, z = parameter_flags(vals, [10.0] * 30)
    assert max(abs(v) for v in z) < 3.0
    assert parameter_flags([None, None], [None, None]) == (None, None, [None, None])
    _, s, z = parameter_flags([5.0, 5.0, 5.0], [0.0, 0.0, 0.0])  # identical: no spread, no flag
    assert s == 0.0 and z == [0.0, 0.0, 0.0]


def test_result_layouts_are_read():
    a = {"identification": {"params": {"mass_kg": 1500.0}, "sigmas": {"mass_kg": 9.0}}}
    b = {"identified": {"mass_kg": {"value": 1500.0, "sigma": 9.0}}}
    c = {"ident": {"final": {"params": {"mass_kg": 1500.0, "x": float("nan")}, "sigmas": {}}}}
    assert identified_params(a) == identified_params(b) == {"mass_kg": (1500.0, 9.0)}
    assert identified_params(c) == {"mass_kg": (1500.0, None)}
    assert identified_params(None) == {} and identified_params({"estimator": {}}) == {}
    assert prior_params({"identification": {"prior": {"mass_kg": 1550.0, "bad": "x"}}}) == {"mass_kg": 1550.0}
    assert prior_params(b) == {} and prior_params(None) == {}
    assert recommended_effects({"recommended_effects": ["a", {"name": "b"}, {"effect": "c"}, 3]}) \
        == ["a", "b", "c"]
    assert recommended_effects({"effects": {"recommended": ["d"]}}) == ["d"]
    assert recommended_effects({}) == []
    # the workbench's diagnosis layout (vdps diagnose --json)
    diag = {"recommendation": "aero_drag", "equivalent_to": [],
            "workbench": {"selected": ["aero_drag", "crosswind"],
                          "identified_parameters": [
                              {"effect": "mass_kg", "parameters": {"mass_kg": {"value": 1610.0, "sigma": 12.0}}},
                              {"effect": "x", "parameters": {"inertia_z_kgm2": {"value": None, "sigma": None}}}]}}
    assert recommended_effects(diag) == ["aero_drag", "crosswind"]
    assert recommended_effects({"recommendation": "imu_bias"}) == ["imu_bias"]
    assert recommended_effects({"recommendation": None}) == []
    assert identified_params(diag) == {"mass_kg": (1610.0, 12.0)}


def test_report_page_shows_plots_flags_effects_and_failures(rng, tmp_path):
    agg = _fleet(rng)
    path = write_report(agg, tmp_path / "rep")
    text = path.read_text()
    assert path.name == "index.html" and text.startswith("<!doctype html>")
    imgs = re.findall(r'src="data:image/png;base64,([^"]+)"', text)
    assert len(imgs) == 2  # parameters, effects
    assert all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in imgs)
    flagged = text[text.index("Drives that differ"):text.index("Effects recommended")]
    assert "drive07" in flagged and "mass_kg" in flagged and "drive02" not in flagged
    eff = text[text.index("Effects recommended"):text.index("Failed drives")]
    assert "trailer_load" in eff and "aero_drag" in eff
    failed = text[text.index("Failed drives"):]
    assert "broken" in failed and "RecordingError" in failed
    assert "bad magic &lt;&amp;&gt; here" in failed  # escaped
    assert "<&>" not in text


def test_report_of_an_interrupted_batch_is_assembled_from_its_result_files(tmp_path):
    tasks = [Task(f"t{i}", "vdps_hil.batch.tasks:worker_info") for i in range(3)]
    tasks.append(Task("bad", "vdps_hil.batch.tasks:no_such_task"))
    run_batch(tasks, EngineConfig(backend="inline"), out_dir=tmp_path)
    (tmp_path / "batch.json").unlink()  # as if interrupted before the aggregate
    agg = aggregate_from_dir(tmp_path)
    assert agg["counts"] == {"total": 4, "ok": 3, "failed": 1}
    assert [f["id"] for f in agg["failed"]] == ["bad"]
    html = render_html(agg)
    assert "Failed drives (1)" in html and "AttributeError" in html
    with pytest.raises(ValueError, match="no batch.json"):
        aggregate_from_dir(tmp_path / "empty")


def test_aggregate_document_round_trips_through_json(rng):
    agg = _fleet(rng)
    assert render_html(json.loads(json.dumps(agg))) == render_html(agg)
