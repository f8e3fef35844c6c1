"""Tests of vdps_hil.batch.progress: counts, ETA from the observed throughput (reused results
cost nothing), one line per task off a terminal, one redrawn line on a terminal, failures
shown with their error, and silence when disabled."""

from __future__ import annotations

import io

import pytest

from vdps_hil.batch.worker import Outcome
from vdps_hil.batch.progress import Progress, format_duration


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def _ok(i):
    return Outcome(f"d{i}", "ok", {}, None, {})


def _failed(i):
    return Outcome(f"d{i}", "failed", None, {"type": "RecordingError", "message": "bad magic"}, {})


def test_format_duration():
    assert format_duration(0) == "0:00" and format_duration(59.6) == "1:00"
    assert format_duration(3725) == "1:02:05"
    assert format_duration(None) == "--:--" and format_duration(float("nan")) == "--:--"
    assert format_duration(float("inf")) == "--:--"


def test_eta_is_the_observed_throughput_over_computed_tasks():
    clock, out = Clock(), io.StringIO()
    p = Progress("t", stream=out, live=False, clock=clock)
    p.start(total=10, reused=2)  # 8 to compute
    assert p.eta_s() is None  # nothing finished yet
    clock.t += 30.0
    p.update(_ok(0))
    p.update(_ok(1))  # 2 computed in 30 s: 15 s each, 6 left -> 90 s
    assert p.eta_s() == pytest.approx(90.0)
    clock.t += 30.0
    p.update(_failed(2))
    p.update(_ok(3))  # 4 in 60 s, 4 left -> 60 s
    assert p.eta_s() == pytest.approx(60.0)
    assert (p.done, p.ok, p.failed, p.reused) == (6, 3, 1, 2)
    line = p.line()
    assert "6/10" in line and "ok 3" in line and "failed 1" in line and "reused 2" in line
    assert "1:00 elapsed" in line and "ETA 1:00" in line
    text = out.getvalue()
    assert "2 of 10 results reused" in text
    assert "FAILED d2: RecordingError: bad magic" in text
    assert text.count("<- d") == 4  # one line per finished task off a terminal


def test_everything_reused_has_zero_eta():
    p = Progress(stream=io.StringIO(), live=False, clock=Clock())
    p.start(total=3, reused=3)
    assert p.eta_s() == 0.0 and p.done == 3


def test_live_mode_redraws_one_line_and_ends_it():
    clock, out = Clock(), io.StringIO()
    p = Progress("t", stream=out, live=True, clock=clock)
    p.start(total=2)
    p.engine({"backend": "dask", "workers": 2, "scheduler": "tcp://127.0.0.1:1",
              "dashboard": "http://127.0.0.1:2/status", "allowed_failures": 2,
              "warnings": ["1 worker(s) run another vdps-hil"]})
    p.update(_ok(0))
    p.update(_ok(1))
    p.close()
    text = out.getvalue()
    assert "\r\x1b[2K" in text and text.endswith("\n")
    assert "dask with 2 worker(s) at tcp://127.0.0.1:1, dashboard http://127.0.0.1:2/status, " \
           "allowed-failures 2" in text
    assert "warning: 1 worker(s) run another vdps-hil" in text
    assert "<- d0" not in text  # no per-task lines on a terminal


def test_disabled_progress_prints_nothing_but_counts():
    out = io.StringIO()
    p = Progress(stream=out, enabled=False, live=True, clock=Clock())
    p.start(total=1)
    p.update(_failed(0))
    p.close()
    assert out.getvalue() == "" and p.failed == 1
