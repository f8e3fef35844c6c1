"""``vdps info``: topics, counts, rates, duration, gaps, per-source health (decode counters)
and the catalogue fields of a recording; truncated and non-MCAP files."""

import json

import can

from live_devices import vdps

from vdps_hil.bus.samples import Sample
from vdps_hil.cli.info_cmd import summarize
from vdps_hil.record.importer import CanSource, SerialSource, import_logs
from vdps_hil.record.writer import RecordingWriter


def make(tmp_path, real_data):
    from vdps_hil.codecs.can_encode import encode_steer

    log = tmp_path / "v.log"
    with can.Logger(log) as w:
        for k in range(300):  # 100 Hz steering, a 1 s hole after 1 s, an unknown ID
            if 100 <= k < 200:
                continue
            m = encode_steer(0.1, k % 256)
            m.timestamp = 1000.0 + k * 0.01
            m.channel = "can0"
            w.on_message_received(m)
        w.on_message_received(can.Message(timestamp=1003.5, arbitration_id=0x7FF, data=b"\1",
                                          is_extended_id=False, channel="can0"))
    out = tmp_path / "r.mcap"
    import_logs(out, [CanSource("vdps", str(log))],
                [SerialSource("gnss", str(real_data / "gpsd_oxts_rst39" / "rst39.nmea"))])
    return out


def test_summary_of_an_import(tmp_path, real_data):
    doc = summarize(make(tmp_path, real_data))
    steer = doc["topics"]["/decoded/can.vdps/steer"]
    assert steer["count"] == 200 and steer["gaps"] == 1
    assert abs(steer["max_gap_s"] - 1.01) < 1e-6
    assert abs(steer["median_period_s"] - 0.01) < 1e-9
    assert doc["topics"]["/raw/can/vdps"]["count"] == 201
    assert doc["topics"]["/decoded/gnss/gnss_att"]["rate_hz"] > 20
    h = doc["health"]["can.vdps"]
    assert h["counters"]["unknown_id"] == 1  # counted, visible, not an error
    assert h["kinds"]["steer"]["timeouts"] == 1  # the hole, seen as a timeout at import
    assert doc["health"]["gnss"]["counters"]["comments"] == 6
    assert doc["fields"]["steer_wheel_angle_rad"] == {"can.vdps/steer": 200}
    assert doc["fields"]["gnss_roll_rad"] == {"gnss/gnss_att": 100}
    assert doc["fields_not_in_catalogue"] == []
    assert not doc["truncated"]


def test_cli_text_json_and_errors(tmp_path, real_data):
    out = make(tmp_path, real_data)
    p = vdps("info", out, "--json", tmp_path / "i.json")
    assert p.returncode == 0, p.stderr
    assert "/decoded/can.vdps/steer" in p.stdout and "unknown_id 1" in p.stdout
    assert "catalogue fields provided:" in p.stdout
    doc = json.loads((tmp_path / "i.json").read_text())
    lost = doc["health"]["can.vdps"]["loss"]  # the 1 s hole: frames the counters say are missing
    assert lost["sequence"] == doc["health"]["can.vdps"]["counters"]["lost_frames"] > 0
    assert f"lost: os ?, reader 0, seq counters {lost['sequence']}; decoding skipped 0" in p.stdout
    assert doc["topics"]["/decoded/can.vdps/steer"]["count"] == 200
    junk = tmp_path / "j.mcap"
    junk.write_bytes(b"garbage")
    p = vdps("info", junk)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1


def test_truncated_file_is_read_and_flagged(tmp_path):
    p = tmp_path / "t.mcap"
    w = RecordingWriter(p)
    for i in range(500):
        w.write_sample(Sample(t_ns=i * 10_000_000, source="imu", kind="imu",
                              fields={"seq_counter": float(i)}, wall_time_ns=1 + i))
        if i % 100 == 99:
            w.flush()
    w._stream.flush()  # the process "dies" here: no summary, no footer
    doc = summarize(p)
    assert doc["truncated"]
    assert doc["topics"]["/decoded/imu/imu"]["count"] == 500
