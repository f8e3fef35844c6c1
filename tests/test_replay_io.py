"""Tests of vdps_hil.app.replay_io: the recording side of a replay, here or in a second
process (``vdps replay --jobs 2``). Real child processes, real pipes, real MCAP files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest
from mcap.reader import make_reader

from vdps_hil.app.replay import ReplayError, replay_file
from vdps_hil.app.replay_io import LocalRecordingSide, RecordingProcess, ReplayIOError
from vdps_hil.record.reader import RecordingReader
from vdps_hil.sim.drive import Drive

WALL_KEYS = {"wall_time_s", "realtime_factor", "output", "jobs"}


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    p = tmp_path_factory.mktemp("replay_io") / "paper.mcap"
    Drive("paper", seed=5, duration_s=3.0).run(p)
    return p


def _messages(path):
    """Every message of an MCAP file as (topic, channel metadata, log time, publish time, bytes),
    in a canonical order (read through the mcap library and its indexes)."""
    with open(path, "rb") as f:
        r = make_reader(f)
        out = [(ch.topic, tuple(sorted(ch.metadata.items())), m.log_time, m.publish_time, m.data)
               for _, ch, m in r.iter_messages(log_time_order=True)]
        stats = r.get_summary().statistics
    return sorted(out, key=lambda x: (x[2], x[0], x[4])), stats


def _doc(d):
    return json.loads(json.dumps({k: v for k, v in d.items() if k not in WALL_KEYS}, default=str))


def test_two_processes_write_the_same_messages_and_summary(drive, tmp_path):
    """The whole chain (estimator, identifier, predictor, warning frames on /est/can/vdps):
    jobs 2 writes exactly the messages jobs 1 writes (topic, channel metadata, times, bytes),
    the summary statistics agree, and the --json documents are equal but for wall time."""
    a = replay_file(drive, output=tmp_path / "one.mcap", jobs=1)
    b = replay_file(drive, output=tmp_path / "two.mcap", jobs=2)
    ma, sa = _messages(tmp_path / "one.mcap")
    mb, sb = _messages(tmp_path / "two.mcap")
    topics = {m[0] for m in ma}
    assert "/est/state" in topics and "/est/can/vdps" in topics and any(t.startswith("/raw/") for t in topics)
    assert len(ma) == len(mb) > 10_000
    assert ma == mb
    assert sa.message_count == sb.message_count == len(ma)
    assert sa.channel_message_counts.keys() == sb.channel_message_counts.keys()
    assert _doc(a) == _doc(b)


def test_without_output_the_summaries_agree(drive):
    a = replay_file(drive, identify=False, predict=False, jobs=1)
    b = replay_file(drive, identify=False, predict=False, jobs=2)
    assert _doc(a) == _doc(b) and a["estimates_summary"]["count"] > 250
    assert (a["jobs"], b["jobs"]) == (1, 2)


def test_a_refused_configuration_writes_nothing_and_leaves_no_process(drive, tmp_path):
    out = tmp_path / "never.mcap"
    with pytest.raises(ReplayError, match="sensor set"):
        replay_file(drive, output=out, sensorset=tmp_path / "missing.toml", jobs=2)
    assert not out.exists()
    side = RecordingProcess(drive, output=out)
    next(iter(side))
    side.abort()  # the parent gives up before start_output
    assert side._proc.returncode is not None and not out.exists()


def test_a_cut_recording_is_read_as_far_as_it_goes_in_both(drive, tmp_path):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(drive.read_bytes()[: drive.stat().st_size // 2])
    a = replay_file(cut, identify=False, predict=False, jobs=1)
    b = replay_file(cut, identify=False, predict=False, jobs=2)
    assert a["decode"]["reader"]["problems"] and _doc(a) == _doc(b)
    assert a["estimates_summary"]["count"] > 50


def test_errors_in_the_second_process_are_one_line(drive, tmp_path):
    """A decoding option the child refuses, an output it cannot write, a child that dies:
    one line each (ReplayError / ReplayIOError), never a traceback or a hang."""
    with pytest.raises(ReplayError) as e:
        replay_file(drive, identify=False, predict=False, signalmap=tmp_path / "none.toml", jobs=2)
    assert len(str(e.value).splitlines()) == 1 and "none.toml" in str(e.value)
    with pytest.raises(ReplayError) as e:
        replay_file(drive, identify=False, predict=False, output=tmp_path / "no" / "such" / "dir.mcap", jobs=2)
    assert "cannot write" in str(e.value) and len(str(e.value).splitlines()) == 1
    side = RecordingProcess(drive)  # dies before it has sent anything
    os.kill(side.pid, signal.SIGKILL)
    with pytest.raises(ReplayIOError, match="ended without a result"):
        next(iter(side))
    side.abort()


def test_a_child_that_refuses_its_options_leaves_one_line_on_the_terminal(drive, tmp_path):
    """The child's own stderr is the user's terminal: after it sent its one-line error it used to
    end through the interpreter's teardown, which aborted on stdin's lock held by its listening
    thread ("Fatal Python error: _enter_buffered_busy ...", five more lines, on every run)."""
    vdps = os.path.join(os.path.dirname(sys.executable), "vdps")
    for _ in range(3):
        r = subprocess.run([vdps, "replay", str(drive), "--jobs", "2", "--signalmap", "nosuch", "--dbc", "x.dbc"],
                           cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert r.returncode == 2
        assert r.stderr.strip().splitlines() == ["vdps: error: signal map nosuch: cannot read: No such file or directory"]


def test_a_child_that_dies_half_way_is_one_line(tmp_path):
    """Killed in the middle of a 10 s drive (its ~2.5 MB of sample frames cannot all wait in
    the 1 MiB pipe, so after the first frame the child is still decoding): the samples already
    sent arrive, then one line, never a hang."""
    long_drive = tmp_path / "long.mcap"
    Drive("paper", seed=6, duration_s=10.0).run(long_drive)
    side = RecordingProcess(long_drive)
    it = iter(side)
    next(it)
    os.kill(side.pid, signal.SIGKILL)
    got = 1
    with pytest.raises(ReplayIOError, match="ended without a result"):
        for _ in it:
            got += 1
    side.abort()
    assert 0 < got < 30_000  # of the ~42,000 samples the 10 s drive decodes to


def test_local_side_holds_raw_records_until_the_output_starts(drive, tmp_path):
    """Raw records read before ``start_output`` wait (nothing is written); after it, the output
    opens at the first raw record with that record's clock and holds every /raw/ message."""
    out = tmp_path / "local.mcap"
    with RecordingReader(drive) as reader:
        side = LocalRecordingSide(reader, output=out)
        first = [next(side) for _ in range(1000)]
        assert first[0].t_ns <= first[-1].t_ns and not out.exists() and side.writer is None
        side.start_output({"source": "test"})
        assert side.writer is not None
        n = sum(1 for _ in side) + len(first)
        side.finish()
    with RecordingReader(drive) as r:
        raw_in = [(m.topic, m.t_ns, m.data) for m in r.iter_records(prefixes=("/raw/",))]
    with RecordingReader(out) as r:
        raw_out = [(m.topic, m.t_ns, m.data) for m in r.iter_records(prefixes=("/raw/",))]
        meta = r.metadata()["vdps.recording"]
    assert meta["source"] == "test" and int(meta["sim_epoch_ns"]) > 0  # the input's clock kept
    assert sorted(raw_out) == sorted(raw_in) and n > 10_000


def test_the_second_process_imports_nothing_from_the_working_directory(drive, tmp_path):
    """``vdps replay --jobs 2`` run where modules named json, threading, numpy, ... lie in the
    working directory: the child (python -P -m vdps_hil.app.replay_io) never imports them."""
    from planted_modules import markers, plant

    cwd = plant(tmp_path / "cwd")
    vdps = os.path.join(os.path.dirname(sys.executable), "vdps")
    r = subprocess.run([vdps, "replay", str(drive), "--jobs", "2", "--json", "s.json",
                        "-o", "out.mcap"], cwd=cwd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert markers(cwd) == []
    assert json.loads((cwd / "s.json").read_text())["jobs"] == 2
