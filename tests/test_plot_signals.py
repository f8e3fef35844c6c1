"""Tests of vdps_hil.app.plot_signals and ``vdps plot``: TOPIC.KEY signals read the values a
replay output holds (checked against the mcap library's reading), bare field names are decoded
from the /raw/ topics (the wheel speeds the DBC carries, 1 kHz), PNG and HTML are written, a
missing signal or a wrong output type is one line with exit status 2."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from replayed_drive import replayed_drive

from vdps_hil.app.plot_signals import PlotError, collect_series
from vdps_hil.cli.main import cli


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    return replayed_drive(tmp_path_factory.mktemp("plot"), seed=5)


def test_topic_keys_are_the_recorded_values(drive):
    got = collect_series(drive / "out.mcap", ["/est/state.phi_v_rad", "/est/tf.translation.x"])
    want: dict[str, list] = {"/est/state": [], "/est/tf": []}
    with open(drive / "out.mcap", "rb") as f:
        for _, ch, msg in make_reader(f).iter_messages(topics=list(want)):
            doc = json.loads(msg.data)
            want[ch.topic].append(doc["values"]["phi_v_rad"] if ch.topic == "/est/state" else doc["translation"]["x"])
    assert sorted(got["/est/state.phi_v_rad"][1]) == sorted(want["/est/state"])
    assert sorted(got["/est/tf.translation.x"][1]) == sorted(want["/est/tf"])
    t = got["/est/state.phi_v_rad"][0]
    assert t == sorted(t) and 1.9 < t[-1] - t[0] < 2.1  # seconds, the 2 s drive


def test_bare_names_are_decoded_from_the_raw_topics(drive):
    (t, v), = collect_series(drive / "paper.mcap", ["wheel_speed_radps_1"]).values()
    assert 1900 < len(v) < 2100  # 1 kHz for 2 s (dbc/vdps.dbc, 0x100)
    assert 70 < min(v) and max(v) < 90  # 25 m/s on a ~0.31 m wheel: about 80 rad/s
    with pytest.raises(PlotError, match="not found"):
        collect_series(drive / "paper.mcap", ["no_such_field"])
    with pytest.raises(PlotError, match="no such topic"):
        collect_series(drive / "paper.mcap", ["/est/nothing.x"])


def test_vdps_plot_png_and_html(drive, tmp_path):
    r = CliRunner().invoke(cli, ["plot", str(drive / "out.mcap"), "/est/state.phi_v_rad", "steer_wheel_angle_rad",
                                 "-o", str(tmp_path / "a.png")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "a.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = CliRunner().invoke(cli, ["plot", str(drive / "out.mcap"), "/est/ident.values.mass_kg",
                                 "-o", str(tmp_path / "a.html")])
    assert r.exit_code == 0, r.output
    html = (tmp_path / "a.html").read_text()
    assert html.startswith("<!DOCTYPE html>") and "<svg" in html and "<script" not in html
    for args in (["/est/state.phi_v_rad", "-o", str(tmp_path / "a.pdf")], ["nope", "-o", str(tmp_path / "b.png")]):
        r = CliRunner().invoke(cli, ["plot", str(drive / "out.mcap"), *args])
        assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output
