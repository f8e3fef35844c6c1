"""Tests of vdps_hil.app.foxglove_layout: the shipped file is the SDK's rendering of
build_layout(); every series and indicator reads a topic and field that a real replay output
(paper drive, 2 s, read back with the mcap library) carries; the map and 3D panels name the
LocationFix and FrameTransform topics the view writes; the ten parameters each with a sigma."""

from __future__ import annotations

import json

import pytest
from mcap.reader import make_reader

from vdps_hil.app.foxglove_layout import LAYOUT_PATH, build_layout, layout_json, plotted_paths
from vdps_hil.estimation.observations import ObsKind
from vdps_hil.model.params import PARAM_NAMES
from vdps_hil.record import schemas as S
from vdps_hil.sim.drive import Drive


@pytest.fixture(scope="module")
def replay_fields(tmp_path_factory):
    """{topic: (schema name, set of 'values.x' / 'sigmas.x' / 'fields.x')} of a replay output."""
    from vdps_hil.app.replay import replay_file

    d = tmp_path_factory.mktemp("layout")
    Drive("paper", seed=5, duration_s=2.0).run(d / "paper.mcap")
    replay_file(d / "paper.mcap", output=d / "out.mcap")
    out: dict[str, tuple[str, set]] = {}
    with open(d / "out.mcap", "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            doc = json.loads(msg.data)
            name, keys = out.setdefault(channel.topic, (schema.name, set()))
            for part in ("values", "sigmas", "fields"):
                keys.update(f"{part}.{k}" for k in doc.get(part, {}))
    return out


def test_shipped_file_is_build_layout():
    assert LAYOUT_PATH.read_text() == layout_json(), "run .venv/bin/python tools/foxglove_layout.py"
    assert json.loads(LAYOUT_PATH.read_text()) == json.loads(build_layout().to_json())


def test_every_plotted_path_is_in_a_replay_output(replay_fields):
    paths = plotted_paths(json.loads(layout_json()))
    assert len(paths) > 40
    innovation_keys = set().union(*(k for t, (_, k) in replay_fields.items() if t.startswith("/est/innovation/")))
    for topic, field in paths:
        assert field, f"{topic}: not a topic.values/sigmas/fields.name path"
        if topic.startswith("/est/innovation/") and topic not in replay_fields:
            # a kind this drive did not update with: a real kind, with the fields every kind has
            assert topic.rsplit("/", 1)[1] in {k.value for k in ObsKind}
            assert field in innovation_keys
            continue
        assert topic in replay_fields, topic
        assert field in replay_fields[topic][1], (topic, field)


def test_parameters_with_sigmas_and_the_map_and_pose_topics(replay_fields):
    doc = json.loads(layout_json())
    paths = set(plotted_paths(doc))
    for n in PARAM_NAMES:
        assert ("/est/ident", f"values.{n}") in paths and ("/est/ident", f"sigmas.{n}") in paths
    text = json.dumps(doc)
    for topic, schema in ((S.GNSS_FIX_TOPIC, S.LOCATION_FIX), (S.EST_FIX_TOPIC, S.LOCATION_FIX),
                          (S.EST_TF_TOPIC, S.FRAME_TRANSFORM)):
        assert replay_fields[topic][0] == schema
    assert f'"followTopic": "{S.EST_FIX_TOPIC}"' in text and f'"followTf": "{S.VEHICLE_FRAME}"' in text
    assert f'"{S.GNSS_FIX_TOPIC}"' in text
