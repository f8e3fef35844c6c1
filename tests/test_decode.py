"""Tests of vdps_hil.record.decode: /raw/ topics -> bus samples in t_ns order, device clocks."""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest

from vdps_hil.codecs.nmea.position import format_gga
from vdps_hil.record import schemas as S
from vdps_hil.record.decode import DecodeError, copy_raw_topics, decode_recording, raw_copier
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.writer import RecordingWriter
from vdps_hil.bus.samples import Sample
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.profiles import load_profile

MS = 1_000_000
ZERO = load_profile("table1-susp1k").zero_noise()


def _drive(tmp_path, name="d.mcap", faults=(), duration_s=2.0, profile=ZERO, seed=1):
    p = tmp_path / name
    Drive("paper", profile=profile, seed=seed, duration_s=duration_s, faults=list(faults)).run(p)
    return p


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    return _drive(tmp_path_factory.mktemp("dec"))


def _steer(counter: int) -> bytes:
    """A valid VDPS_SteerAngle payload (0 rad) with ``counter``."""
    from vdps_hil.codecs.can_encode import encode_steer

    return bytes(encode_steer(0.0, counter).data)


def _imu_time_errors(samples):
    """t_ns - measurement instant (packet k is sampled at k ms in the simulator) [ns]."""
    return [s.t_ns - int(s.fields["seq_counter"]) * MS for s in samples if s.kind == "imu"]


def test_decodes_every_raw_topic_in_time_order_without_rejects(drive):
    d = decode_recording(drive)
    samples = list(d)
    kinds = {}
    for s in samples:
        kinds[(s.source, s.kind)] = kinds.get((s.source, s.kind), 0) + 1
    # 2 s: 2001 samples of each 1 kHz sensor (wheel speeds in two frames), 201 at 100 Hz, 11 GNSS epochs
    assert kinds == {("can.vdps", "wheel_speed"): 4002, ("can.vdps", "suspension"): 2001,
                     ("can.vdps", "wheel_torque"): 201, ("can.vdps", "steer"): 201, ("imu", "imu"): 2001,
                     ("gnss", "gnss_pos"): 11, ("gnss", "gnss_vel"): 11, ("gnss", "gnss_att"): 11}
    t = [s.t_ns for s in samples]
    assert t == sorted(t)
    assert d.rejected() == {"can.vdps": 0, "serial.imu": 0, "serial.gnss": 0}
    c = d.counters
    assert c["reader"]["late"] == 0 and c["reader"]["undecoded"] == {}
    assert c["serial.imu"]["samples"] == 2001 and c["clock.imu"]["observations"] == 2001


def test_device_clocks_remove_the_read_chunk_quantisation(drive):
    """Packets arrive in 5 ms read chunks: the receive-time rule is off by up to ~2 ms; the
    SampleTimeFine alignment gives the sampling instant exactly (zero-noise simulator, the
    device time is on the 100 us tick grid and the last packet of a chunk is not queued).
    GNSS sentences are stamped at their UTC epoch (5 Hz grid, no latency in the profile)."""
    raw = _imu_time_errors(decode_recording(drive, device_time=False))
    assert max(raw) - min(raw) > 1 * MS  # the quantisation this removes
    aligned = list(decode_recording(drive))
    assert set(_imu_time_errors(aligned)) == {0}
    gnss = [s.t_ns for s in aligned if s.source == "gnss"]
    assert all(t % (200 * MS) == 0 for t in gnss)
    rule = [s.t_ns for s in decode_recording(drive, device_time=False) if s.source == "gnss"]
    assert min(r - t for r, t in zip(rule, gnss)) > 5 * MS  # line ends arrive after the epoch


@pytest.mark.parametrize("spec,device,jump_ns", [
    ("clock_jump:device=imu,t_s=1.0,jump_s=-0.5", "imu", 500 * MS),
    ("clock_jump:device=imu,t_s=1.0,jump_s=0.3", "imu", -300 * MS),
    ("clock_jump:device=gnss,t_s=1.0,jump_s=2.0", "gnss", -2000 * MS),
])
def test_a_device_clock_step_is_confirmed_and_followed(tmp_path, spec, device, jump_ns):
    d = decode_recording(_drive(tmp_path, faults=[spec], duration_s=2.0))
    samples = list(d)
    assert set(_imu_time_errors(samples)) == {0}
    assert all(s.t_ns % (200 * MS) == 0 for s in samples if s.source == "gnss")
    clk = d.counters[f"clock.{device}"]
    assert clk["clock_jumps"] == 1 and clk["offset_ns"] == jump_ns and clk["outliers"] == 0
    assert d.counters["reader"]["late"] == 0


def test_serial_disconnect_loses_only_the_gap(tmp_path):
    d = decode_recording(_drive(tmp_path, faults=["serial_disconnect:device=imu,t_s=1.0,duration_s=0.3"]))
    imu = [s for s in d if s.kind == "imu"]
    assert set(_imu_time_errors(imu)) == {0}
    assert 2001 - 302 <= len(imu) <= 2001 - 299  # 0.3 s of packets (+- the ones cut in flight)
    assert d.counters["serial.imu"]["seq_gaps"] == 2001 - len(imu)


def test_reads_only_the_raw_topics(drive, tmp_path):
    """A copy with ONLY /raw/ topics decodes to the same samples; broken /truth/ and bogus
    /decoded/ topics next to /raw/ are never read (the reader would count them as rejected)."""
    only_raw = tmp_path / "raw.mcap"
    n = copy_raw_topics(drive, only_raw)
    with RecordingReader(only_raw) as r:
        assert all(t.startswith("/raw/") for t in r.topics())
        assert sum(i.count for i in r.topics().values()) == n
    poisoned = tmp_path / "poisoned.mcap"
    with RecordingReader(drive) as src, RecordingWriter(poisoned) as w:
        sink = raw_copier(src, w)
        for rec in src.iter_records(prefixes=("/raw/",)):
            sink(rec)
            if rec.topic == "/raw/serial/gnss":
                w._write("/truth/state", S.TRUTH, rec.t_ns, b"{not json", None)
                w.write_sample(Sample(rec.t_ns, "gnss", "gnss_pos", {"gnss_lat_deg": 1.0}))
    a = [s.to_json() for s in decode_recording(drive)]
    b = [s.to_json() for s in decode_recording(only_raw)]
    with RecordingReader(poisoned) as r:
        dec = decode_recording(r)
        c = [s.to_json() for s in dec]
        assert r.rejected == 0  # the broken /truth/ messages were never decoded
    assert a == b == c


def test_streaming_yields_before_the_whole_file_is_read(drive):
    seen = []
    d = decode_recording(drive, raw_sink=lambda rec: seen.append(rec.t_ns), reorder_window_s=0.2)
    first = next(iter(d))
    total = sum(1 for _ in RecordingReader(drive).iter_records(prefixes=("/raw/",)))
    assert first.t_ns == 0 and 0 < len(seen) < total / 5  # released one 0.2 s window into the 2 s drive
    assert seen[-1] - first.t_ns <= 0.21e9
    list(d)
    assert len(seen) == total


def _serial_recording(chunks, fmt="nmea", device="gnss", can=()):
    buf = io.BytesIO()
    with RecordingWriter(buf, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS) as w:
        for t, data in chunks:
            w.write_serial(device, t, data, baud=115200, fmt=fmt)
        for t, doc in can:
            w.write_json("/raw/can/vdps", S.RAW_CAN, t, doc)
    buf.seek(0)
    return buf


def test_garbage_is_counted_and_good_data_around_it_is_kept():
    lines = [format_gga(1.0 + 0.2 * k, 48.0, 11.0, 500.0, fix_quality=4) for k in range(4)]
    chunks = [(1_200 * MS, lines[0]), (1_400 * MS, b"\x00\xff$GPGGA,garbage*00\r\n" + lines[1]),
              (1_600 * MS, lines[2][:20]), (1_650 * MS, lines[2][20:] + b"\xfe\xfe"), (1_800 * MS, lines[3])]
    good = {"t_ns": 0, "arbitration_id": 0x130, "is_extended_id": False, "is_fd": False, "is_remote_frame": False,
            "is_error_frame": False, "dlc": 4, "data_hex": _steer(0).hex(), "direction": "rx"}
    bad_len = dict(good, dlc=2, data_hex="0000")
    err = dict(good, is_error_frame=True)
    can = [(1_000 * MS, dict(good, t_ns=1_000 * MS)), (1_010 * MS, dict(bad_len, t_ns=1_010 * MS)),
           (1_020 * MS, dict(err, t_ns=1_020 * MS)), (1_030 * MS, dict(good, t_ns=1_030 * MS, data_hex=_steer(1).hex()))]
    d = decode_recording(_serial_recording(chunks, can=can))
    samples = list(d)
    gnss = [s for s in samples if s.kind == "gnss_pos"]
    assert len(gnss) == 4 and all(s.fields["gnss_lat_deg"] == pytest.approx(48.0) for s in gnss)
    # UTC epochs 1.0, 1.2, ... s on the host clock: the first line's start of transmission
    wire = round((len(lines[0]) * 10 / 115200) * 1e9)  # sentence incl. CR LF at 115200 Bd
    # (lines 3 and 4 arrive later than their epoch, so the offset leaks up by 100 ppm x 0.2 s)
    assert [s.t_ns for s in gnss] == pytest.approx([1_200 * MS - wire + k * 200 * MS for k in range(4)], abs=25_000)
    assert gnss[1].t_ns == 1_400 * MS - wire  # a line that ends its chunk resets the offset exactly
    assert len([s for s in samples if s.kind == "steer"]) == 2
    rej = d.rejected()
    assert rej["serial.gnss"] == 1  # the bad checksum line
    assert rej["can.vdps"] == 2  # dlc mismatch + error frame


def test_remote_and_fd_frames_with_a_valid_id_are_counted_rejects_not_samples():
    """Issue 20, finding 7: a remote frame was recorded but counted by no decoder counter; a CAN
    FD frame with a valid ID and length decoded as the classic message."""
    good = S.raw_can_doc(0, 0x130, _steer(0))
    remote = S.raw_can_doc(0, 0x130, b"", is_remote_frame=True, dlc=4)
    fd = S.raw_can_doc(0, 0x130, _steer(1), is_fd=True)
    frames = [(1_000 * MS, good), (1_010 * MS, remote), (1_020 * MS, fd),
              (1_030 * MS, dict(good, data_hex=_steer(2).hex()))]
    d = decode_recording(_serial_recording([], can=[(t, dict(f, t_ns=t)) for t, f in frames]))
    steer = [s for s in d if s.kind == "steer"]
    assert [s.fields["seq_counter"] for s in steer] == [0.0, 2.0]  # the FD frame's counter 1 unused
    bus = d.counters["can.vdps"]["bus"]
    assert bus["remote_frame"] == 1 and bus["fd_frame"] == 1
    assert d.rejected()["can.vdps"] == 2


def test_unknown_serial_format_and_undecoded_bus_are_counted_not_fatal():
    buf = io.BytesIO()
    with RecordingWriter(buf) as w:
        w.write_serial("lidar", 10, b"\x01\x02", baud=9600, fmt="velodyne")
        w.write_can("body", 20, {"arbitration_id": 0x10, "data": b"\x00"})
    buf.seek(0)
    d = decode_recording(buf)
    assert list(d) == []
    assert d.counters["reader"]["undecoded"] == {"/raw/serial/lidar": 1, "/raw/can/body": 1}
    assert d.decoding["serial.lidar"]["decoded"] is False and d.decoding["can.body"]["decoded"] is False


def test_bus_map_renames_a_recording_bus_to_a_signal_map_bus(tmp_path):
    buf = io.BytesIO()
    doc = {"arbitration_id": 0x130, "data": _steer(0)}
    with RecordingWriter(buf) as w:
        w.write_can("chassis", 5, doc)
    buf.seek(0)
    assert list(decode_recording(buf)) == []
    buf.seek(0)
    got = list(decode_recording(buf, signalmap="vdps", bus_map={"chassis": "vdps"}))
    assert [(s.source, s.kind) for s in got] == [("can.chassis", "steer")]


def test_bad_options_are_one_line_errors(tmp_path):
    with pytest.raises(DecodeError, match="--signalmap"):
        decode_recording(io.BytesIO(_serial_recording([]).getvalue()), dbc="x.dbc")
    with pytest.raises(DecodeError, match="signal map"):
        decode_recording(io.BytesIO(_serial_recording([]).getvalue()), signalmap=tmp_path / "none.toml")
    (tmp_path / "x.mcap").write_bytes(b"not an mcap")
    with pytest.raises(DecodeError, match="not an MCAP"):
        decode_recording(tmp_path / "x.mcap")


def test_a_layout_1_recording_decodes_with_the_dbc_it_names(tmp_path):
    """Issue 20: layout 2 of the chassis bus (E2E CRC in every sensor frame, two torque frames)
    must not orphan recordings made with layout 1. A drive simulated on dbc/vdps_v1.dbc names that
    DBC by hash and decodes with it: the same samples as a layout-2 drive, nothing rejected."""
    from vdps_hil.codecs.can_dbc import LEGACY_DBC_PATHS

    p = tmp_path / "v1.mcap"
    Drive("paper", profile=ZERO, seed=1, duration_s=1.0, dbc=LEGACY_DBC_PATHS[0]).run(p)
    d = decode_recording(p)
    kinds = {}
    for s in d:
        kinds[s.kind] = kinds.get(s.kind, 0) + 1
        if s.kind == "wheel_torque":
            assert all(f"wheel_torque_nm_{i}" in s.fields for i in range(1, 5))
    assert d.decoding["can.vdps"]["signalmap"] == "vdps_v1"
    assert d.rejected()["can.vdps"] == 0
    assert (kinds["wheel_speed"], kinds["wheel_torque"], kinds["steer"]) == (2002, 101, 101)


# ---------------------------------------------------------------------------------------------
# bulk CAN decoding (issue 19 item 2) against the per-frame reference
# ---------------------------------------------------------------------------------------------
def _decode_all(source, monkeypatch, per_frame=False, batch=None, **kw):
    """(sample keys, counters, rejected) of ``decode_recording``; ``per_frame``: every CAN record
    through ``CanStream.feed_raw`` one at a time (the reference); ``batch``: records per run."""
    from can_checks import sample_key
    from vdps_hil.record import decode as D
    from vdps_hil.record.streams import CanStream

    with monkeypatch.context() as m:
        if per_frame:
            m.setattr(CanStream, "bulk", False)  # every CAN record through feed_raw in the walk
            m.setattr(CanStream, "feed_many", None)  # (and never in bulk)
        if batch is not None:
            m.setattr(D, "BATCH_RECORDS", batch)
        if isinstance(source, io.BytesIO):
            source.seek(0)
        d = decode_recording(source, **kw)
        keys = [sample_key(s) for s in d]
        counters = d.counters
    for c in counters.values():
        if isinstance(c, dict) and "dbc" in c:
            c.pop("dbc")
    return keys, counters, d.rejected()


def _assert_bulk_equals_per_frame(source, monkeypatch, batches=(None, 1, 333), **kw):
    ref = _decode_all(source, monkeypatch, per_frame=True, **kw)
    for b in batches:
        got = _decode_all(source, monkeypatch, batch=b, **kw)
        assert got[0] == ref[0], f"batch {b}"
        assert got[1:] == ref[1:], f"batch {b}"
    return ref


@pytest.mark.parametrize("profile,faults", [
    ("table1", ()), ("table1-susp1k", ()),
    ("table1-susp1k", ("dropped_frames:fraction=0.03", "clock_jump:device=can,t_s=1,jump_s=-0.2",
                       "serial_disconnect:device=imu,t_s=1.5,duration_s=0.2", "gyro_spike:t_s=0.5"))])
def test_bulk_can_decoding_equals_the_per_frame_path_on_drives(tmp_path, monkeypatch, profile, faults):
    p = _drive(tmp_path, faults=faults, duration_s=3.0, profile=profile, seed=5)
    keys, counters, _ = _assert_bulk_equals_per_frame(p, monkeypatch)
    assert len(keys) > 9_000
    if faults:
        assert sum(c["lost_frames"] for c in counters["can.vdps"].values() if isinstance(c, dict) and "lost_frames" in c) > 0


def test_bulk_can_decoding_equals_the_per_frame_path_on_malformed_frames(monkeypatch):
    rng = np.random.default_rng(3)
    good = S.raw_can_doc(0, 0x130, _steer(0))
    can, ctr = [], 0
    for k in range(3000):
        t = 1_000 * MS + k * MS
        ctr += int(rng.choice([1, 1, 1, 0, 3, 16]))
        doc = dict(good, t_ns=t, data_hex=_steer(ctr % 16).hex())
        r = rng.random()
        if r < 0.05:
            doc["data_hex"] = doc["data_hex"][:2] + f"{int(doc['data_hex'][2:4], 16) ^ 0x40:02x}" + doc["data_hex"][4:]
        elif r < 0.08:
            doc.update(dlc=2, data_hex=doc["data_hex"][:4])
        elif r < 0.09:
            doc["is_error_frame"] = True
        elif r < 0.10:
            doc["arbitration_id"] = int(rng.integers(0, 0x800))
        can.append((t, doc))
    chunks = [(1_000 * MS + k * 200 * MS, format_gga(1.0 + 0.2 * k, 48.0, 11.0, 500.0, fix_quality=4))
              for k in range(10)]
    buf = _serial_recording(chunks, can=can)
    _, counters, rejected = _assert_bulk_equals_per_frame(buf, monkeypatch, batches=(None, 1, 7, 64))
    steer = counters["can.vdps"]["VDPS_SteerAngle"]
    assert steer["crc_mismatch"] and steer["counter_repeat"] and steer["dlc_mismatch"] and steer["lost_frames"]
    assert counters["can.vdps"]["raw_malformed"] > 0 and rejected["can.vdps"] > 0


def test_bulk_walk_equals_the_per_frame_path_on_the_real_rav4_drive(tmp_path, monkeypatch):
    """The RAV4's own bus through its signal map (``SignalMapDecoder``: frame by frame, inside the
    batched walk) with the u-blox fixes: the same samples, order and counters."""
    from click.testing import CliRunner

    from conftest import REAL_DATA
    from vdps_hil.cli.main import cli

    seg = REAL_DATA / "comma2k19_rav4_2018-08-02_seg40"
    if not seg.is_dir():
        pytest.skip(f"real data not present: {seg}")
    out = tmp_path / "rav4.mcap"
    r = CliRunner().invoke(cli, ["import", "--can", f"pt={seg / 'rav4_seg40.candump.log'}@can0", "--signalmap",
                                 "toyota_rav4_2017", "--dbc", str(seg / "toyota_new_mc_pt_generated.dbc"),
                                 "-o", str(out)], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    keys, _, _ = _assert_bulk_equals_per_frame(out, monkeypatch, batches=(None, 100),
                                              signalmap="toyota_rav4_2017",
                                              dbc=str(seg / "toyota_new_mc_pt_generated.dbc"))
    assert len(keys) > 10_000
