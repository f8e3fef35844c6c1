"""Tests of vdps_hil.app.can_monitor and ``vdps monitor``: on a recording the table holds each
message's frame count, period and the last decoded values (checked against cantools' decoding
of the last frame read with the mcap library); ``--id``/``--signal`` filter; on python-can's
virtual bus, through a real pseudo-terminal, the screen shows the values sent, with the ones
that change in reverse video and a constant one not; bad input is one line, exit status 2."""

from __future__ import annotations

import json
import re

import cantools
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from terminal import run_on_pty, run_piped
from vdps_hil.app.can_monitor import HOME, REVERSE, CanMonitor, parse_ids
from vdps_hil.codecs.can_dbc import DEFAULT_DBC_PATH
from vdps_hil.cli.main import cli
from vdps_hil.sim.drive import Drive

_ESC = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    path = tmp_path_factory.mktemp("monitor") / "paper.mcap"
    Drive("paper", seed=7, duration_s=2.0).run(path)
    return path


def _last_frames(path) -> dict[int, tuple[int, bytes]]:
    """{frame ID: (count, last payload)} of /raw/can/vdps read with the mcap library."""
    out: dict[int, tuple[int, bytes]] = {}
    with open(path, "rb") as f:
        for _, _, msg in make_reader(f).iter_messages(topics=["/raw/can/vdps"]):
            d = json.loads(msg.data)
            n = out.get(d["arbitration_id"], (0, b""))[0]
            out[d["arbitration_id"]] = (n + 1, bytes.fromhex(d["data_hex"]))
    return out


def _table(text: str) -> dict[str, dict[str, list[str]]]:
    """{message name: {"": its header's words, signal: its line's words}} of a printed table."""
    out: dict[str, dict[str, list[str]]] = {}
    current = None
    for line in text.splitlines():
        words = line.split()
        if len(words) > 2 and words[1].startswith("0x"):
            current = out.setdefault(words[2], {"": words})
        elif current is not None and words:
            current[words[0]] = words
    return out


def test_recording_table_is_the_decoded_last_frames(drive):
    r = run_piped("monitor", drive, "--once", timeout=120)
    assert r.returncode == 0, r.stderr
    assert "\x1b" not in r.stdout  # not a terminal: plain text
    table = _table(r.stdout)
    db = cantools.database.load_file(DEFAULT_DBC_PATH)
    frames = _last_frames(drive)
    for fid, (count, data) in frames.items():
        m = db.get_message_by_frame_id(fid)
        head = table[m.name][""]
        assert int(head[head.index("frames") - 1]) == count
        for sig, v in m.decode(data, decode_choices=False).items():
            assert float(table[m.name][sig][1]) == pytest.approx(v, rel=1e-5, abs=1e-9), sig
    ws = table["VDPS_WheelSpeedFront"][""]
    assert 1900 < frames[0x100][0] < 2100 and float(ws[ws.index("ms") - 1]) == pytest.approx(1.0, abs=0.05)


def test_id_and_signal_filters(drive):
    r = CliRunner().invoke(cli, ["monitor", str(drive), "--once", "--id", "0x130,VDPS_WheelSpeedRear"])
    assert r.exit_code == 0, r.output
    assert "VDPS_SteerAngle" in r.output and "VDPS_WheelSpeedRear" in r.output
    assert "VDPS_WheelSpeedFront" not in r.output and "VDPS_Suspension" not in r.output
    r = CliRunner().invoke(cli, ["monitor", str(drive), "--once", "--signal", "WHEEL_SPEED*_1"])
    assert r.exit_code == 0, r.output
    assert "wheel_speed_radps_1" in r.output and "VDPS_WheelSpeedFront" in r.output
    assert "wheel_speed_radps_2" not in r.output and "VDPS_SteerAngle" not in r.output
    assert parse_ids(["0x100, 257", "VDPS_Warning"]) == ({0x100, 257}, {"VDPS_Warning"})


def test_changes_are_counted_and_unknown_ids_shown_as_hex():
    db = cantools.database.load_file(DEFAULT_DBC_PATH)
    mon = CanMonitor({"vdps": None})
    for i, v in enumerate((1.0, 1.0, 2.0)):
        data = db.get_message_by_name("VDPS_SteerAngle").encode({"steer_wheel_angle_rad": v, "seq_counter": 0,
                                                                 "e2e_crc": 0})
        mon.feed("x", i * 10_000_000, 0x130, False, data)
    st, = mon.messages.values()
    assert st.name is None and st.count == 3 and st.signals["data"].changes == 1  # no DBC for bus x: hex
    assert st.period_ms() == pytest.approx(10.0)


_SENDER = r"""
import sys, threading, time
import can
from vdps_hil.codecs.can_encode import encode_steer, encode_wheel_speed_front
from vdps_hil.cli.main import main

def send():
    bus = can.Bus(interface="virtual", channel="monitor-test")
    for i in range(100000):
        ang = (i % 1000) * 0.001
        bus.send(encode_steer(ang, i))
        bus.send(encode_wheel_speed_front(12.34, 5.0, 7))
        bus.send(can.Message(arbitration_id=0x7FF, is_extended_id=False, data=bytes([0xAB, 0xCD])))
        time.sleep(0.01)

threading.Thread(target=send, daemon=True).start()
time.sleep(0.3)
sys.exit(main(sys.argv[1:]))
"""


def test_virtual_bus_on_a_terminal_highlights_what_changes():
    code, raw = run_on_pty("monitor", "virtual:monitor-test", "--duration", "2", code=_SENDER, timeout=120,
                           cols=110, rows=40)
    assert code == 0, raw
    frames = raw.split(HOME)
    assert len(frames) >= 5  # redrawn while it ran (10 per second)
    last = frames[-1]
    lines = {(_ESC.sub("", ln).split() or [""])[0]: ln for ln in last.split("\r\n")}
    screen = {k: _ESC.sub("", ln).split() for k, ln in lines.items()}
    assert screen["wheel_speed_radps_1"][1:3] == ["12.34", "rad/s"] and screen["wheel_speed_radps_1"][-1] == "0"
    assert REVERSE not in lines["wheel_speed_radps_1"]  # constant: never highlighted
    assert REVERSE in lines["steer_wheel_angle_rad"] and REVERSE in lines["seq_counter"]
    assert 0.0 <= float(screen["steer_wheel_angle_rad"][1]) < 1.0 and int(screen["steer_wheel_angle_rad"][-1]) > 50
    assert screen["data"][1:3] == ["AB", "CD"]  # 0x7FF is not in the DBC: its payload
    assert any("(not in the DBC)" in ln for ln in lines.values())


@pytest.mark.parametrize("args", [["nosuch:chan"], ["missing.mcap"], ["virtual:x", "--once"],
                                  ["virtual:x", "--dbc", "missing.dbc"], ["virtual:x", "--id", "a b"]])
def test_bad_input_is_one_line(args, tmp_path):
    r = run_piped("monitor", *args, "--duration", "0.1", timeout=60, cwd=tmp_path) if args[-1] != "--once" else \
        run_piped("monitor", *args, timeout=60, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith("vdps: error:"), r.stderr


def test_real_rav4_import_is_decoded_with_the_recorded_dbc(real_data, tmp_path):
    """The comma2k19 RAV4 drive imported with its signal map and Toyota DBC: ``vdps monitor`` finds
    the DBC from the recording's metadata (no --dbc), counts every 0xAA frame of the candump log,
    and shows the last one's wheel speeds as cantools decodes that line."""
    seg = real_data / "comma2k19_rav4_2018-08-02_seg40"
    dbc = seg / "toyota_new_mc_pt_generated.dbc"
    r = run_piped("import", "--can", f"pt={seg / 'rav4_seg40.candump.log'}@can0", "--signalmap", "toyota_rav4_2017",
                  "--dbc", f"pt={dbc}", "-o", tmp_path / "rav4.mcap", timeout=300)
    assert r.returncode == 0, r.stderr
    lines = [ln.split()[2] for ln in (seg / "rav4_seg40.candump.log").read_text().splitlines()
             if ln.split()[1:2] == ["can0"] and ln.split()[2].startswith("0AA#")]
    r = run_piped("monitor", tmp_path / "rav4.mcap", "--once", "--id", "0xAA", timeout=300)
    assert r.returncode == 0, r.stderr
    table = _table(r.stdout)
    assert list(table) == ["WHEEL_SPEEDS"] and int(table["WHEEL_SPEEDS"][""][3]) == len(lines) > 1000
    want = cantools.database.load_file(dbc, strict=False).get_message_by_frame_id(0xAA).decode(
        bytes.fromhex(lines[-1].split("#")[1]), decode_choices=False)
    for sig in ("WHEEL_SPEED_FL", "WHEEL_SPEED_FR", "WHEEL_SPEED_RR", "WHEEL_SPEED_RL"):
        assert float(table["WHEEL_SPEEDS"][sig][1]) == pytest.approx(want[sig], rel=1e-5), sig
        assert table["WHEEL_SPEEDS"][sig][2] == "km/h"


def test_recording_on_a_terminal_is_played_at_its_pace(drive):
    """At ``--speed 1`` the 2 s drive is redrawn as it plays: the frame counts of the screens grow
    over about 2 s of redraws, not all at once; the last screen holds every frame."""
    code, raw = run_on_pty("monitor", drive, "--speed", "1", timeout=120, cols=110, rows=40)
    assert code == 0, raw
    counts = [int(m.group(1)) for m in re.finditer(r"frames (\d+), shown", raw)]
    assert len(counts) >= 10 and counts == sorted(counts)  # 10 redraws a second
    total = sum(n for n, _ in _last_frames(drive).values())
    assert counts[-1] == total and sum(0 < c < total for c in counts) >= 5


def test_candump_lines_on_stdin(drive, tmp_path):
    """``candump -L can0 | vdps monitor -``: the drive's frames as candump lines (python-can's
    writer) through a real pipe give the same table as the recording; the end of input ends it."""
    import can

    from vdps_hil.record.reader import RecordingReader

    with RecordingReader(drive) as r, can.CanutilsLogWriter(tmp_path / "dump.log", channel="can0") as w:
        for _, m in r.iter_raw_can("vdps"):
            w.on_message_received(m)
    with open(tmp_path / "dump.log", "rb") as f:
        r = run_piped("monitor", "-", "--once", stdin=f, timeout=120)
    assert r.returncode == 0, r.stderr
    piped, recorded = _table(r.stdout), _table(run_piped("monitor", drive, "--once", timeout=120).stdout)
    assert set(piped) == set(recorded) and len(piped) >= 5
    for name, sigs in recorded.items():
        assert piped[name][""][3] == sigs[""][3]  # frame counts
        assert {k: v[1] for k, v in piped[name].items() if k} == {k: v[1] for k, v in sigs.items() if k}
