"""Tests of vdps_hil.batch.worker: a task's exception becomes a one-line failure; results are
made plain JSON."""

from __future__ import annotations

import json
import os
from pathlib import Path

from vdps_hil.batch.worker import execute, to_jsonable


def test_execute_turns_an_exception_into_a_one_line_failure(tmp_path):
    doc = execute("vdps_hil.batch.tasks:replay_drive", {"path": os.fspath(tmp_path / "none.mcap")})
    assert doc["status"] == "failed" and doc["result"] is None
    assert doc["error"]["type"] == "ReplayError" and "none.mcap" in doc["error"]["message"]
    assert "\n" not in doc["error"]["message"]
    assert doc["run"]["pid"] == os.getpid() and doc["run"]["wall_s"] >= 0
    bad = execute("vdps_hil.batch.tasks:no_such_function", {})
    assert bad["status"] == "failed" and bad["error"]["type"] == "AttributeError"


def test_to_jsonable_makes_plain_json():
    import numpy as np
    doc = to_jsonable({"a": np.float64(1.5), "b": (1, float("nan")), 3: np.arange(2),
                       "p": Path("/x")})
    assert doc == {"a": 1.5, "b": [1, None], "3": [0, 1], "p": "/x"}
    json.dumps(doc, allow_nan=False)
