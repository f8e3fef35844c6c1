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


def test_the_tap_waits_for_an_imu_that_starts_late_and_sizes_as_the_replay(tmp_path):
    """The live tap holds samples until the probe window of ``sample_stats`` ends, which waits
    for a late IMU (``pipeline.configure.ProbeWindow``): GNSS from 0 s, the IMU from 5 s. At 4 s it
    still holds and says no IMU sample has come; after 8 s it is running, sized from the rates
    ``sample_stats`` measures on the same samples."""
    from vdps_hil.bus.samples import Sample
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.pipeline.configure import sample_stats
    from vdps_hil.record.writer import RecordingWriter

    stream = []
    for i in range(1000):  # 10 s: GNSS at 4 Hz from 0 s, a 6-axis IMU at 100 Hz from 5 s
        t = i * 10_000_000
        if i % 25 == 0:
            stream.append(Sample(t, "gnss", "gnss_pos", {"gnss_lat_deg": 40.0, "gnss_lon_deg": -105.0,
                                                         "gnss_alt_m": 1600.0}))
        if i >= 500:
            stream.append(Sample(t, "imu", "imu", {"specific_force_mps2_x": 0.0, "specific_force_mps2_y": 0.0,
                                                    "specific_force_mps2_z": 9.81, "angular_rate_radps_x": 0.0,
                                                    "angular_rate_radps_y": 0.0, "angular_rate_radps_z": 0.0}))
    with RecordingWriter(str(tmp_path / "live.mcap")) as w:
        tap = PipelineTap(load_vehicle("sedan-model", expect_kind="model"), w)
        for smp in stream:
            tap([smp])
            if smp.t_ns == 4_000_000_000:
                assert tap.system is None and "no IMU sample yet" in tap.status_line()
        assert tap.system is not None and tap.error is None
        _, rates, _ = sample_stats(iter(stream))
        assert tap.settings["probe_rates_hz"] == rates and rates["imu"] > 99.0
        tap.finish()


def test_a_parameter_file_s_unsettled_problems_gate_the_live_warning_as_in_a_replay(tmp_path):
    """``vdps log --pipeline --params``: the tap's system takes the file's values and the
    problems it had not settled (``start_unsettled``), and gates the warning on those the policy
    names (pipeline.node's rule, as ``vdps replay`` and ``vdps bench``)."""
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.record.decode import decode_recording
    from vdps_hil.record.writer import RecordingWriter
    from vdps_hil.sim.drive import Drive

    rec = tmp_path / "p.mcap"
    Drive("paper", profile="table1", seed=2, duration_s=3.5).run(str(rec))
    samples = list(decode_recording(str(rec)))
    veh = load_vehicle("sedan-model", expect_kind="model")
    for unsettled, gated in ((("cornering", "inertia"), ("cornering",)), (("inertia",), ())):
        with RecordingWriter(str(tmp_path / f"{len(gated)}.mcap")) as w:
            tap = PipelineTap(veh, w, veh.params, start_unsettled=unsettled, record_order=False)
            for smp in samples:
                tap([smp])
            assert tap.system is not None and tap.system.config.start_params == veh.params
            assert tap.system.require_converged == gated
            tap.finish()
