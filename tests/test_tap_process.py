"""TapProcess (vdps_hil.app.tap_process): ``vdps log --pipeline``'s estimator in a process of its
own at a lower priority writes, through the logger's writer, exactly what the same tap writes in
the logger's process; a child that fails is one line, never the recording."""

import os
import time

import pytest

from vdps_hil.app.pipeline_tap import PipelineTap
from vdps_hil.app.tap_process import TAP_NICE, TapProcess
from vdps_hil.model.params import load_vehicle
from vdps_hil.record.decode import decode_recording
from vdps_hil.record.input_order import INPUT_ORDER_METADATA
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.writer import RecordingWriter
from vdps_hil.sim.drive import Drive


def _est(path):
    with RecordingReader(str(path)) as r:
        msgs = {t: [(m.t_ns, m.data) for m in r.iter_records(topics=[t])]
                for t in ("/est/state", "/est/can/vdps")}
        return msgs, INPUT_ORDER_METADATA in r.metadata()


def test_the_process_writes_what_the_tap_writes_in_process_at_a_lower_priority(tmp_path):
    rec = tmp_path / "drive.mcap"
    Drive("paper", seed=5, duration_s=2.0).run(str(rec))
    samples = list(decode_recording(str(rec)))
    with RecordingWriter(str(tmp_path / "here.mcap")) as w:
        here = PipelineTap(load_vehicle("sedan-model", expect_kind="model"), w, probe_s=1.0)
        for k in range(0, len(samples), 50):
            here(samples[k:k + 50])
        here.finish()
    with RecordingWriter(str(tmp_path / "child.mcap")) as w:
        tp = TapProcess("sedan-model", None, w, probe_s=1.0)
        for k in range(0, len(samples), 50):
            tp(samples[k:k + 50])
        t_end = time.monotonic() + 120
        while tp._batches == 0 and time.monotonic() < t_end:
            time.sleep(0.05)
        nice_child = os.getpriority(os.PRIO_PROCESS, tp.proc.pid)
        session_child = os.getsid(tp.proc.pid)
        tp.finish()
    assert nice_child == min(19, os.getpriority(os.PRIO_PROCESS, 0) + TAP_NICE)
    assert session_child == tp.proc.pid != os.getsid(0)  # a scheduling group of its own
    want, want_order = _est(tmp_path / "here.mcap")
    got, got_order = _est(tmp_path / "child.mcap")
    assert len(want["/est/state"]) > 5 and len(want["/est/can/vdps"]) > 20
    assert got == want  # every /est/ message, byte for byte, in order
    assert want_order and got_order
    s = tp.summary()
    assert s["input_order_recorded"] and s["error"] is None and s["samples"] == len(samples)
    assert s["estimates"] == here.estimates and s["warning_frames"] == here.frames


def test_a_failing_child_is_one_line_and_writes_nothing(tmp_path):
    with RecordingWriter(str(tmp_path / "x.mcap")) as w:
        tp = TapProcess(str(tmp_path / "no_such_vehicle.toml"), None, w)
        t_end = time.monotonic() + 120
        while tp.error is None and time.monotonic() < t_end:
            time.sleep(0.05)
        assert tp.error.startswith("pipeline process: ") and "\n" not in tp.error
        with pytest.raises(RuntimeError, match="pipeline process"):
            tp([])
        with pytest.raises(RuntimeError, match="pipeline process"):
            tp.finish()
    assert not tp.summary()["input_order_recorded"]
    got, order = _est(tmp_path / "x.mcap")
    assert got == {"/est/state": [], "/est/can/vdps": []} and not order


def test_at_the_end_it_skips_what_it_has_not_fed_and_records_the_order_of_what_it_fed(tmp_path):
    """``wind_down`` (the recording ended; here with no time to catch up): the samples not yet
    fed are skipped and counted, the input order is that of the samples fed (a prefix)."""
    rec = tmp_path / "drive.mcap"
    Drive("paper", seed=6, duration_s=1.5).run(str(rec))
    samples = list(decode_recording(str(rec)))
    half = len(samples) // 2
    with RecordingWriter(str(tmp_path / "child.mcap")) as w:
        tp = TapProcess("sedan-model", None, w, probe_s=0.5, wind_down_s=0.0)
        tp(samples[:half])
        t_end = time.monotonic() + 120
        while tp._batches < 1 and time.monotonic() < t_end:
            time.sleep(0.02)
        tp.wind_down()
        tp._hurry.join(30)  # SIGUSR1 sent
        for k in range(half, len(samples), 50):
            tp(samples[k:k + 50])
        tp.finish()
    s = tp.summary()
    assert s["samples"] == half and s["input_unfed"] == len(samples) - half
    assert s["input_order_recorded"]
    with RecordingReader(str(tmp_path / "child.mcap")) as r:
        assert int(r.metadata()[INPUT_ORDER_METADATA]["count"]) == half
