"""PipelineTap (vdps_hil.app.pipeline_tap): ``vdps log --pipeline``'s consumer runs the paper's
Figure 2 node on the decoded samples in arrival order, sized from the first 3 s as replay sizes
it, records /est/ topics and the warning frames and reports the latest warning."""

from vdps_hil.app.pipeline_tap import PipelineTap
from vdps_hil.record.reader import RecordingReader


def test_pipeline_tap_runs_the_system_live_and_reports_the_warning(tmp_path):
    """``vdps log --pipeline``: the tap feeds decoded samples to VdpsSystem (the node replay
    runs), records /est/ topics and the warning frames, and shows the latest warning. Fed a
    simulated fishhook-suv drive in arrival order, it holds the first 3 s of data to size the
    system, then its frames (in data time) must carry a warning (level >= 2) more than 1 s
    before the point of no return (3.72 s), and decode without CRC rejects."""
    from vdps_hil.codecs.can_decode import VdpsCanDecoder
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.record.decode import decode_recording
    from vdps_hil.record.writer import RecordingWriter
    from vdps_hil.sim.drive import Drive

    rec = tmp_path / "fh.mcap"
    Drive("fishhook-suv", profile="table1-susp1k", seed=1).run(str(rec))
    out = tmp_path / "live.mcap"
    with RecordingWriter(str(out)) as w:
        tap = PipelineTap(load_vehicle("suv-model", expect_kind="model"), w)
        assert "sizing from the first 3 s" in tap.status_line()
        for smp in decode_recording(str(rec)):
            tap([smp])
        assert tap.settings["probe_rates_hz"]["suspension"] > 900  # the 1 kHz suspension, measured
        tap.finish()
    assert "warning level" in tap.status_line()
    # from the priors the frames say whether they are valid yet (in words)
    assert "valid" in tap.status_line()
    s = tap.summary()
    assert s["estimates"] > 100 and s["warning_frames"] > 50 and s["input_order_recorded"]
    assert tap._decoder.total_rejected == 0
    dec = VdpsCanDecoder(source="check")
    with RecordingReader(str(out)) as r:
        topics = r.topics()
        levels = [(t, smp.fields["warning_level"]) for _, t, doc in r.iter_messages(topics=["/est/can/vdps"])
                  for smp in dec.decode(t, doc["arbitration_id"], bytes.fromhex(doc["data_hex"]))]
    assert "/est/state" in topics
    first_warning_t = min(t for t, lvl in levels if lvl >= 2) / 1e9
    assert first_warning_t < 3.72 - 1.0
