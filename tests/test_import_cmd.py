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
