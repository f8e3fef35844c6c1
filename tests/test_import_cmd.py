"""``vdps import`` on the command line: real logs, the JSON report, one-line errors."""

import json

from live_devices import vdps

from vdps_hil.record.reader import RecordingReader

RAV4 = "comma2k19_rav4_2018-08-02_seg40"


def test_rav4_powertrain_channel_only(tmp_path, real_data):
    f = real_data / RAV4
    out = tmp_path / "rav4.mcap"
    p = vdps("import", "--can", f"pt={f / 'rav4_seg40.candump.log'}@can0",
             "--signalmap", "toyota_rav4_2017", "--dbc", f / "toyota_new_mc_pt_generated.dbc",
             "--serial", f"gnss={real_data / 'gpsd_oxts_rst39' / 'rst39.nmea'}",
             "-o", out, "--json", tmp_path / "r.json")
    assert p.returncode == 0, p.stderr
    assert "can.pt: 53800 records" in p.stderr and "errors 0" in p.stderr
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["sources"]["can.pt"]["counters"]["undecodable"] == 0
    with RecordingReader(out) as r:
        assert set(t for t in r.topics() if t.startswith("/raw/")) == \
            {"/raw/can/pt", "/raw/serial/gnss"}


def test_one_line_errors(tmp_path, real_data):
    out = tmp_path / "x.mcap"
    log = real_data / RAV4 / "rav4_seg40.candump.log"
    cases = [
        ["--can", f"pt={tmp_path / 'missing.log'}"],
        ["--can", f"pt={log}", "--signalmap", tmp_path / "nomap.toml"],
        ["--serial", f"gnss={log}", "--format", "gnss=binary"],
        ["--can", f"{log}"],
        [],
    ]
    for args in cases:
        p = vdps("import", *args, "-o", out)
        assert p.returncode == 2, (args, p.stderr)
        assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr
    assert not out.exists()


def test_progress_bar_per_source_on_a_terminal_only(tmp_path, real_data):
    import re

    from terminal import run_on_pty, screen_text

    f = real_data / RAV4
    args = ("import", "--can", f"pt={f / 'rav4_seg40.candump.log'}@can0",
            "--serial", f"gnss={real_data / 'gpsd_oxts_rst39' / 'rst39.nmea'}", "-o", tmp_path / "a.mcap")
    code, raw = run_on_pty(*args)
    assert code == 0
    text = screen_text(raw)
    assert re.search(r"vdps import can\.pt: +\d+%\|", text) and "98800/98800" in text  # every line of the log
    assert re.search(r"vdps import gnss: 100%\|", text)
    piped = vdps(*args[:-1], tmp_path / "b.mcap")
    assert piped.returncode == 0 and "%|" not in piped.stderr


def test_candump_lines_on_standard_input(tmp_path):
    """``candump -L can0 | vdps import --can vdps=- ...``: dbc/vdps.dbc frames as candump -L lines
    on a real pipe are imported (every frame on /raw/can/vdps, in order, decoded with their rolling
    counters); two sources on standard input are one line, exit 2."""

    from vdps_hil.codecs.can_encode import encode_wheel_speed_front

    lines = []
    for k in range(200):  # 1 kHz front wheel speeds, counter k, 80.00 rad/s both wheels (0.01 rad/s)
        data = bytes(encode_wheel_speed_front(80.0, 80.0, k).data)
        lines.append(f"({1.0 + k * 1e-3:.6f}) can0 100#{data.hex().upper()}")
    text = "\n".join(lines) + "\n"
    out = tmp_path / "stdin.mcap"
    p = vdps("import", "--can", "vdps=-", "-o", out, "--quiet", input=text)
    assert p.returncode == 0, p.stderr
    with RecordingReader(out) as r:
        raw = [doc for _, _, doc in r.iter_messages(topics=["/raw/can/vdps"])]
        ws = [s for s in r.iter_samples() if s.kind == "wheel_speed"]
    assert [d["data_hex"] for d in raw] == [ln.split("#")[1].lower() for ln in lines]
    assert [int(s.fields["seq_counter"]) for s in ws] == [k % 16 for k in range(200)]
    assert all(abs(s.fields["wheel_speed_radps_1"] - 80.0) < 1e-9 for s in ws)
    p = vdps("import", "--can", "a=-", "--can", "b=-", "-o", tmp_path / "x.mcap", input="")
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1
