"""Import of real logs into the recording layout: RAV4 candump with its DBC, the OxTS NMEA
file, both CANedge MF4 files with gnss.dbc; what goes in comes out of the MCAP."""

import json
import math

import can
import numpy as np
import pytest

from vdps_hil.record.importer import (CanSource, ImportError_, SerialSource, import_logs,
                                      parse_can_source, parse_serial_source)
from vdps_hil.record.reader import RecordingReader

RAV4 = "comma2k19_rav4_2018-08-02_seg40"


def test_source_specs(tmp_path):
    assert parse_can_source("pt=x.log@can0") == CanSource("pt", "x.log", "can0")
    assert parse_can_source("pt=x.log") == CanSource("pt", "x.log", None)
    weird = tmp_path / "a@b.log"
    weird.write_text("")
    assert parse_can_source(f"pt={weird}") == CanSource("pt", str(weird), None)
    assert parse_serial_source("imu=cap.bin@921600") == SerialSource("imu", "cap.bin", 921600)
    for bad in ("x.log", "=x.log", "bad name=x.log"):
        with pytest.raises(ImportError_):
            parse_can_source(bad)
    with pytest.raises(ImportError_, match="baud"):
        parse_serial_source("gnss=x.nmea@fast")


def test_rav4_import_round_trip(tmp_path, real_data):
    folder = real_data / RAV4
    out = tmp_path / "rav4.mcap"
    rep = import_logs(out, [CanSource("pt", str(folder / "rav4_seg40.candump.log"))],
                      signalmap="toyota_rav4_2017",
                      dbc={"*": str(folder / "toyota_new_mc_pt_generated.dbc")})
    st = rep["sources"]["can.pt"]
    assert st["counters"]["undecodable"] == 0 and st["counters"]["dlc_mismatch"] == 0
    assert st["counters"]["other_channel"] == 45000 and rep["write_errors"] == 0
    with RecordingReader(out) as r:
        topics = r.topics()
        assert topics["/raw/can/pt"].count == 53800  # the powertrain bus
        assert topics["/raw/can/pt.can1"].count == 45000  # the radar bus, apart, raw only
        md = r.metadata()
        rec = md["vdps.recording"]
        assert rec["hash.dbc.pt"] == "sha256:8e105af632534fe57404b9966997802fb48edd97b71cc508" \
                                     "dc2d458d0bdfea74"
        assert rec["hash.signalmap"].startswith("sha256:")
        assert json.loads(rec["decoding"])["pt"]["dbc_strict"] is False
        ws = [s for s in r.iter_samples() if s.kind == "wheel_speed"]
        # raw frames are the file's frames, bit for bit, with the file's time stamps
        first = next(iter(r.iter_raw_can("pt")))[1]
    src = next(m for m in can.LogReader(folder / "rav4_seg40.candump.log") if m.channel == "can0")
    assert bytes(first.data) == bytes(src.data) and first.timestamp == pytest.approx(src.timestamp)
    comma = np.load(folder / "processed_log" / "CAN" / "wheel_speed" / "value")
    ours = np.array([[s.fields[f"wheel_speed_radps_{i}"] * 0.35 for i in (1, 2, 4, 3)]
                     for s in ws])
    assert np.max(np.abs(ours - comma)) <= 0.01 / 3.6 / 2 + 1e-9


def test_oxts_import_gives_100_attitude_samples(tmp_path, real_data):
    out = tmp_path / "oxts.mcap"
    rep = import_logs(out, serial=[SerialSource("gnss", str(real_data / "gpsd_oxts_rst39" /
                                                            "rst39.nmea"))])
    assert rep["sources"]["gnss"]["counters"]["rejected"] == 0
    with RecordingReader(out) as r:
        att = [s for s in r.iter_samples() if s.kind == "gnss_att"]
        fixes = list(r.iter_messages("/gnss/fix"))
    with_roll = [s for s in att if math.isfinite(s.get("gnss_roll_rad"))]
    assert len(with_roll) == 100
    assert len(fixes) == 40  # every GGA also as a foxglove.LocationFix
    assert fixes[0][2]["latitude"] == pytest.approx(42 + 5.733715 / 60, abs=1e-9)


@pytest.mark.parametrize("name,n_imu", [("gnss1.MF4", 1669), ("gnss2.MF4", 1859)])
def test_canedge_mf4_imports_with_its_dbc(tmp_path, real_data, name, n_imu):
    folder = real_data / "css_canedge_gnss_imu_mf4"
    out = tmp_path / "c.mcap"
    rep = import_logs(out, [CanSource("gnss", str(folder / name))],
                      signalmap="canedge_gnss_imu", dbc={"gnss": str(folder / "gnss.dbc")})
    c = rep["sources"]["can.gnss"]["counters"]
    assert c["undecodable"] == 0 and c["dlc_mismatch"] == 0
    with RecordingReader(out) as r:
        kinds = {}
        for s in r.iter_samples():
            kinds[s.kind] = kinds.get(s.kind, 0) + 1
        assert r.topics()["/gnss/fix"].count == kinds["gnss_pos"]
    assert kinds["imu"] == n_imu and kinds["gnss_att"] == kinds["gnss_pos"] > 150


def test_errors_before_anything_is_written(tmp_path, real_data):
    out = tmp_path / "x.mcap"
    with pytest.raises(ImportError_, match="no such file"):
        import_logs(out, [CanSource("pt", str(tmp_path / "none.log"))])
    log = real_data / RAV4 / "rav4_seg40.candump.log"
    with pytest.raises(ImportError_, match="no --signalmap"):
        import_logs(out, [CanSource("pt", str(log))], dbc={"*": str(log)})
    with pytest.raises(ImportError_, match="cannot load"):
        import_logs(out, [CanSource("pt", str(log))], signalmap="toyota_rav4_2017",
                    dbc={"*": str(log)})  # a candump log is not a DBC
    with pytest.raises(ImportError_, match="nothing to import"):
        import_logs(out)
    assert not out.exists()


def test_vdps_bus_decodes_by_default_and_imu_capture(tmp_path, rng):
    from vdps_hil.codecs.can_encode import encode_wheel_speeds
    from vdps_hil.codecs.imu_mtdata2 import encode_imu_packet

    log = tmp_path / "v.asc"
    with can.Logger(log) as w:
        for k in range(100):
            for m in encode_wheel_speeds([10.0, 10.0, 10.0, 10.0], k % 256):
                m.timestamp = 1_700_000_000 + k * 0.001
                w.on_message_received(m)
    cap = tmp_path / "imu.bin"
    cap.write_bytes(b"".join(encode_imu_packet(k * 1_000_000, [0, 0, 9.81], [0, 0, 0.1], k)
                             for k in range(500)))
    out = tmp_path / "v.mcap"
    rep = import_logs(out, [CanSource("vdps", str(log))], [SerialSource("imu", str(cap))])
    assert rep["sources"]["can.vdps"]["samples"] == 200
    assert rep["sources"]["imu"]["samples"] == 500
    assert rep["decoding"]["vdps"]["codec"] == "vdps"
