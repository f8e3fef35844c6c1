"""Tests of vdps_hil.batch.progress: the bar (tqdm) is drawn on a real pseudo-terminal with a
percentage and an ETA and nothing is written when the stream is a pipe or quiet; the batch's
counts and ETA from the observed throughput (reused results cost nothing); failures shown as
lines (also off a terminal); silence when disabled."""

from __future__ import annotations

import fcntl
import io
import os
import pty
import re
import struct
import termios
import time

import pytest

from vdps_hil.batch.progress import Progress, ProgressBar, format_duration, is_live
from vdps_hil.batch.worker import Outcome


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def _ok(i):
    return Outcome(f"d{i}", "ok", {}, None, {})


def _failed(i):
    return Outcome(f"d{i}", "failed", None, {"type": "RecordingError", "message": "bad magic"}, {})


@pytest.fixture
def terminal():
    """A real pseudo-terminal: (writable text stream on the slave side, function reading what
    the master side has received so far)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 30, 100, 0, 0))  # 30 rows, 100 columns
    stream = os.fdopen(slave, "w", buffering=1, encoding="utf-8")

    def received() -> str:
        stream.flush()
        chunks = []
        os.set_blocking(master, False)
        try:
            while True:
                chunks.append(os.read(master, 65536))
        except (BlockingIOError, OSError):
            pass
        return b"".join(chunks).decode("utf-8", "replace")

    yield stream, received
    stream.close()
    os.close(master)


def test_format_duration():
    assert format_duration(0) == "0:00" and format_duration(59.6) == "1:00"
    assert format_duration(3725) == "1:02:05"
    assert format_duration(None) == "--:--" and format_duration(float("nan")) == "--:--"
    assert format_duration(float("inf")) == "--:--"


def test_bar_on_a_pseudo_terminal_has_percentage_and_eta(terminal):
    stream, received = terminal
    assert is_live(stream) and not is_live(stream, quiet=True)
    with ProgressBar(60.0, "vdps replay", unit="s", stream=stream) as bar:
        bar.update_to(15.0)
        bar.note("a stage line")
        bar.update_to(30.0)
        bar.update_to(20.0)  # never backwards
        assert bar.n == 30.0
        time.sleep(0.25)  # past tqdm's redraw interval
        bar.update_to(31.0)
        mid = received()
    assert "vdps replay" in mid and "52%" in mid and "31.0/60.0" in mid
    assert re.search(r"\[\d\d:\d\d<\d\d:\d\d", mid)  # elapsed<remaining: the ETA
    assert "a stage line" in mid
    assert "100%" in received()


def test_nothing_when_piped_or_quiet(terminal):
    pipe = io.StringIO()  # not a terminal
    bar = ProgressBar(10, "x", stream=pipe)
    bar.update_to(5)
    bar.note("note")
    bar.callback()(7, 10)
    bar.close()
    assert pipe.getvalue() == "" and not bar.live
    stream, received = terminal
    quiet = ProgressBar(10, "x", stream=stream, quiet=True)
    quiet.update_to(5)
    quiet.close()
    assert received() == ""


def test_callbacks_drive_the_bar(terminal):
    stream, received = terminal
    bar = ProgressBar(None, "vdps paper", unit="run", stream=stream)
    cb = bar.callback()
    cb(1, 4)  # the total learnt from the work
    cb(2, 4)
    assert bar.n == 2
    stage = ProgressBar(3, "vdps diagnose", unit="stage", stream=stream)
    st = stage.stage_callback()
    st("decoding")
    st("ranking")
    assert stage.n == 1
    time.sleep(0.25)
    st("ranking again")
    stage.close()
    bar.close()
    text = received()
    assert "ranking again" in text and "100%" in text and "4/4" in text


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
    assert "6/10" in line and "ok 3" in line and "failed 1" in line and "reused 2" in line and "ETA 1:00" in line
    text = out.getvalue()
    assert "2 of 10 results reused" in text
    assert "FAILED d2: RecordingError: bad magic" in text
    assert "<- d" not in text and text.count("\n") == 2  # off a terminal: the messages only


def test_everything_reused_has_zero_eta():
    p = Progress(stream=io.StringIO(), live=False, clock=Clock())
    p.start(total=3, reused=3)
    assert p.eta_s() == 0.0 and p.done == 3


def test_batch_bar_on_a_pseudo_terminal(terminal):
    stream, received = terminal
    p = Progress("vdps batch replay", stream=stream)
    assert p.live
    p.start(total=2)
    p.engine({"backend": "dask", "workers": 2, "scheduler": "tcp://127.0.0.1:1",
              "dashboard": "http://127.0.0.1:2/status", "allowed_failures": 2,
              "warnings": ["1 worker(s) run another vdps-hil"]})
    p.update(_ok(0))
    p.update(_failed(1))
    p.close()
    text = received()
    assert "dask with 2 worker(s) at tcp://127.0.0.1:1, dashboard http://127.0.0.1:2/status, " \
           "allowed-failures 2" in text
    assert "FAILED d1" in text and "100%" in text and "2/2" in text


def test_disabled_prints_nothing_but_counts():
    out = io.StringIO()
    p = Progress(stream=out, live=False, enabled=False)
    p.start(total=2, reused=1)
    p.update(_failed(0))
    p.close()
    assert out.getvalue() == "" and p.done == 2
