"""Tests of ``vdps batch``: a replay batch through the CLI (result files, aggregate on stdout,
report, exit status 3 with a failed drive), resume on rerun, the local Dask cluster through
the CLI, ``vdps batch report``, input expansion and one-line usage errors (exit 2)."""

from __future__ import annotations

import json
import os
import shutil

import pytest

from vdps_hil.batch.runner import strip_run
from vdps_hil.cli.batch_cmd import expand_inputs
from vdps_hil.cli.main import main
from vdps_hil.sim.drive import Drive


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    d = tmp_path_factory.mktemp("cmd")
    for seed in range(2):
        Drive("paper", seed=seed, duration_s=1.0).run(d / f"drive{seed}.mcap")
    (d / "broken.mcap").write_bytes(b"this is not a recording")
    return d


def test_batch_replay_writes_results_report_and_reports_the_broken_drive(drives, tmp_path, capsys):
    out, rep = tmp_path / "out", tmp_path / "rep"
    rc = main(["batch", "replay", str(drives / "*.mcap"), "--backend", "inline", "--out", str(out),
               "--report", str(rep), "--json", "-", "--no-predict"])
    assert rc == 3  # finished, with a failed task
    cap = capsys.readouterr()
    agg = json.loads(cap.out)
    assert agg["counts"] == {"total": 3, "ok": 2, "failed": 1}
    assert [t["id"] for t in agg["tasks"]] == ["broken", "drive0", "drive1"]  # sorted inputs
    assert agg["failed"][0]["id"] == "broken" and "not an MCAP" in agg["failed"][0]["error"]["message"]
    assert agg["options"]["predict"] is False
    assert "failed broken: ReplayError" in cap.err and "2 ok, 1 failed of 3" in cap.err
    assert sorted(p.name for p in (out / "drives").iterdir()) == ["broken.json", "drive0.json", "drive1.json"]
    assert json.loads((out / "batch.json").read_text()) == agg
    html = (rep / "index.html").read_text()
    assert "Identified parameters per drive" in html and "broken" in html
    # rerun: both good drives reused, the broken one tried again
    rc = main(["batch", "replay", str(drives / "*.mcap"), "--backend", "inline", "--out", str(out),
               "--no-predict"])
    assert rc == 3
    err = capsys.readouterr()
    assert "2 of 3 results reused" in err.out + err.err and "(1 computed, 2 reused)" in err.out
    # vdps batch report rewrites the report from the directory
    shutil.rmtree(rep)
    assert main(["batch", "report", str(out), "--report", str(rep)]) == 0
    assert (rep / "index.html").is_file()


def test_batch_replay_on_a_local_dask_cluster_equals_the_inline_run(drives, tmp_path, capsys):
    from vdps_hil.batch.engine import dask_available
    if not dask_available() and not os.environ.get("CI"):
        pytest.skip("distributed not installed (the optional extra 'dask'; CI must have it)")
    good = [str(drives / "drive0.mcap"), str(drives / "drive1.mcap")]
    assert main(["batch", "replay", *good, "--backend", "inline", "--out", str(tmp_path / "a"), "-q",
                 "--no-predict"]) == 0
    assert main(["batch", "replay", *good, "--workers", "2", "--out", str(tmp_path / "b"),
                 "--no-predict"]) == 0
    cap = capsys.readouterr()
    assert "dask with 2 worker(s) at tcp://127.0.0.1:" in cap.err  # progress on stderr
    a = json.loads((tmp_path / "a" / "batch.json").read_text())
    b = json.loads((tmp_path / "b" / "batch.json").read_text())
    assert strip_run(a) == strip_run(b)
    assert b["run"]["engine"]["backend"] == "dask" and b["run"]["engine"]["allowed_failures"] == 2


def test_expand_inputs_globs_directories_and_duplicates(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "b").mkdir()
    for p in ("a/x.mcap", "a/b/y.mcap", "a/z.txt"):
        (tmp_path / p).write_bytes(b"")
    got = expand_inputs((str(tmp_path / "a"), str(tmp_path / "a" / "*.mcap"),
                         str(tmp_path / "**" / "y.mcap")))
    assert [os.path.relpath(p, tmp_path) for p in got] == ["a/b/y.mcap", "a/x.mcap"]
    assert expand_inputs(("plain/missing.mcap",)) == ["plain/missing.mcap"]  # reported as failed


@pytest.mark.parametrize("args, words", [
    (["replay", "{d}/nothing*.mcap"], "no file matches"),
    (["replay", "{d}/drive0.mcap", "--workers", "0"], "at least 1"),
    (["replay", "{d}/drive0.mcap", "--scheduler", "tcp://127.0.0.1:1", "--backend", "processes"],
     "needs the dask backend"),
    (["replay", "{d}/drive0.mcap", "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"],
     "has its own"),
    (["replay", "{d}/drive0.mcap", "--vehicle", "no-such-car"], "no such vehicle file"),
    (["replay", "{d}/drive0.mcap", "--params", "{d}/none.json"], "no such file"),
    (["replay", "{d}/drive0.mcap", "--bus", "vdps"], "expected REC=MAP"),
    (["replay", "{d}/drive0.mcap", "--out", "{d}/drive0.mcap"], "not a directory"),
    (["report", "{d}"], "no batch.json"),
    (["study", "weighting", "--duration", "5", "--out", "{d}/st"], "10.25"),
    (["study", "snr", "--profile", "no-such-profile", "--out", "{d}/st"], "no-such-profile"),
    (["study", "astrology"], "astrology"),
])
def test_usage_errors_are_one_line_with_exit_2(drives, args, words, capsys):
    rc = main(["batch", *[a.format(d=drives) for a in args]])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert words in err and len(err.strip().splitlines()) == 1


def test_batch_is_registered_with_help():
    assert main(["batch", "--help"]) == 0
    assert main(["batch", "replay", "--help"]) == 0
