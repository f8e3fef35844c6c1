"""Tests of vdps_hil.batch.runner: resume skips unchanged results and recomputes changed and
failed ones; task ids must be unique."""

from __future__ import annotations

from pathlib import Path

import pytest

from vdps_hil.batch.engine import EngineConfig
from vdps_hil.batch.runner import run_batch, strip_run
from vdps_hil.batch.tasks import replay_tasks
from vdps_hil.batch.worker import Task

from batch_drives import corrupt, drives  # noqa: F401 - fixtures


def test_resume_skips_unchanged_results_and_recomputes_changed_and_failed(drives, corrupt, tmp_path):
    inputs = [tmp_path / f"d{i}.mcap" for i in range(3)] + [tmp_path / "corrupt.mcap"]
    for src, dst in zip(drives[:3] + [corrupt], inputs):
        dst.write_bytes(Path(src).read_bytes())

    class Stop(Exception):
        pass

    class InterruptAfter:
        """Progress that interrupts the batch after n outcomes (a Ctrl-C)."""

        def __init__(self, n):
            self.n, self.seen = n, []

        def start(self, total, reused):
            self.reused = reused

        def engine(self, info):
            pass

        def update(self, o):
            self.seen.append(o.id)
            if len(self.seen) == self.n:
                raise Stop

        def close(self):
            pass

    cfg = EngineConfig(backend="inline")
    out = tmp_path / "out"
    with pytest.raises(Stop):
        run_batch(replay_tasks(inputs), cfg, out_dir=out, progress=InterruptAfter(2))
    assert len(list((out / "drives").glob("*.json"))) == 2  # written as they finished
    prog = InterruptAfter(-1)
    res = run_batch(replay_tasks(inputs), cfg, out_dir=out, progress=prog)
    assert prog.reused == 2 and len(prog.seen) == 2  # resumed: only the rest ran
    assert res.aggregate["run"]["reused"] == 2 and res.counts["failed"] == 1
    # a rerun: everything reused except the failed corrupt file, which is tried again
    prog = InterruptAfter(-1)
    res2 = run_batch(replay_tasks(inputs), cfg, out_dir=out, progress=prog)
    assert prog.seen == ["corrupt"] and strip_run(res2.aggregate) == strip_run(res.aggregate)
    # a changed recording gets a new key and is recomputed; a changed option recomputes all
    inputs[0].write_bytes(Path(drives[5]).read_bytes())
    prog = InterruptAfter(-1)
    run_batch(replay_tasks(inputs), cfg, out_dir=out, progress=prog)
    assert sorted(prog.seen) == ["corrupt", "d0"]
    prog = InterruptAfter(-1)
    run_batch(replay_tasks(inputs, options={"predict": False}), cfg, out_dir=out, progress=prog)
    assert len(prog.seen) == 4
    prog = InterruptAfter(-1)
    run_batch(replay_tasks(inputs), cfg, out_dir=out, progress=prog, force=True)
    assert len(prog.seen) == 4


def test_duplicate_ids_are_refused():
    with pytest.raises(ValueError, match="unique"):
        run_batch([Task("a", "x:y"), Task("a", "x:y")], EngineConfig(backend="inline"))
