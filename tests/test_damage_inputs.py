"""tools/damage_inputs.py: its TOML writer gives back the file it read, every leaf is damaged,
and a command that fails with an internal error (exit 1), a traceback or a signal is counted bad
while a one-line refusal (exit 2) is not."""

from __future__ import annotations

import importlib.util
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("damage_inputs", REPO / "tools" / "damage_inputs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_toml_writer_round_trips_the_shipped_configs():
    tool = _tool()
    for path in ("configs/signalmaps/canedge_gnss_imu.toml", "configs/sensorsets/rav4-can-ublox.toml",
                 "configs/scenarios/paper.toml", "configs/vehicles/sedan-model.toml"):
        doc = tomllib.load(open(REPO / path, "rb"))
        assert tomllib.loads(tool.toml_text(doc)) == doc, path


def test_every_leaf_is_replaced_once_per_replacement(tmp_path):
    tool = _tool()
    p = tmp_path / "x.toml"
    p.write_text('a = 1.5\n[t]\nb = "s"\n[[t.m]]\nc = [1, 2]\n')
    labels = [label for label, _ in tool.toml_cases(str(p), "0256")]
    # 3 leaves x 4 replacements, less the one equal to a leaf's own value ([1, 2] for c)
    assert len(labels) == 11 and "t.m.0.c=nan" in labels and "t.m.0.c=[1, 2]" not in labels


def test_exit_1_and_tracebacks_are_bad_a_one_line_refusal_is_not(tmp_path, capsys):
    tool = _tool()
    p = tmp_path / "x.toml"
    p.write_text("a = 1.5\n")
    refuse = "import sys, tomllib; tomllib.load(open(sys.argv[1], 'rb'))['a'] + 0; sys.exit(0)"
    # a string for 'a' raises TypeError (a traceback, exit 1); the numbers pass
    assert tool.main(["toml", str(p), "--reps", "034", "--", sys.executable, "-c", refuse, "{}"]) == 1
    out = capsys.readouterr().out
    assert "3 cases, 1 bad" in out and "BAD a='zz': exit 1" in out
    ok = "import sys; print('error: one line', file=sys.stderr); sys.exit(2)"
    assert tool.main(["bytes", str(p), "--", sys.executable, "-c", ok, "{}"]) == 0
    assert f"{len(list(tool.byte_cases(str(p), 5)))} cases, 0 bad" in capsys.readouterr().out
