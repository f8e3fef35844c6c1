"""python-can plugins for .mcap: direct use, and discovery through python-can's entry point
groups (a real distribution's metadata on sys.path, the same mechanism pyproject's
entry points use once installed)."""


import can
import numpy as np
import pytest

from vdps_hil.record.can_io import McapCanReader, McapCanWriter
from vdps_hil.record.reader import RecordingReader


def frames(rng, n=300):
    out = []
    for i in range(n):
        ext = i % 5 == 0
        out.append(can.Message(timestamp=1_700_000_000.0 + i * 0.001,
                               arbitration_id=int(rng.integers(0, 0x1FFFFFFF if ext else 0x7FF)),
                               is_extended_id=ext, channel="can0" if i % 2 else "can1",
                               data=bytes(rng.integers(0, 256, int(rng.integers(0, 9)),
                                                       dtype=np.uint8))))
    return out


def test_writer_reader_round_trip(tmp_path, rng):
    fr = frames(rng)
    p = tmp_path / "x.mcap"
    with McapCanWriter(p) as w:
        for m in fr:
            w.on_message_received(m)
        assert w.file_size() > 0
    with RecordingReader(p) as r:
        assert set(r.topics()) == {"/raw/can/can0", "/raw/can/can1"}
    got = list(McapCanReader(p))
    assert len(got) == len(fr)
    for a, b in zip(fr, got):
        assert b.equals(a, timestamp_delta=1e-6, check_channel=True)


def test_append_is_refused(tmp_path):
    with pytest.raises(ValueError, match="appended"):
        McapCanWriter(tmp_path / "x.mcap", append=True)


@pytest.fixture
def plugin_on_path(tmp_path, monkeypatch):
    """Metadata of an installed distribution declaring our entry points (exactly the lines
    proposed for pyproject.toml)."""
    site = tmp_path / "site"
    dist = site / "vdps_can_plugin_probe-0.0.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: vdps-can-plugin-probe\n"
                                   "Version: 0.0\n")
    (dist / "entry_points.txt").write_text(
        '[can.io.message_writer]\n.mcap = vdps_hil.record.can_io:McapCanWriter\n\n'
        '[can.io.message_reader]\n.mcap = vdps_hil.record.can_io:McapCanReader\n')
    monkeypatch.syspath_prepend(str(site))
    from can.io import logger, player

    monkeypatch.setattr(logger, "MESSAGE_WRITERS", dict(logger.MESSAGE_WRITERS))
    monkeypatch.setattr(player, "MESSAGE_READERS", dict(player.MESSAGE_READERS))
    yield


def test_python_can_logger_and_logreader_find_the_plugin(tmp_path, rng, plugin_on_path):
    fr = frames(rng, 50)
    p = tmp_path / "y.mcap"
    with can.Logger(p) as w:
        assert isinstance(w, McapCanWriter)
        for m in fr:
            w.on_message_received(m)
    got = list(can.LogReader(p))
    assert [(g.arbitration_id, bytes(g.data)) for g in got] == \
        [(m.arbitration_id, bytes(m.data)) for m in fr]
    # and python-can's converter: mcap -> asc -> frames unchanged
    asc = tmp_path / "y.asc"
    with can.Logger(asc) as w:
        for m in can.LogReader(p):
            w.on_message_received(m)
    back = list(can.LogReader(asc))
    assert [bytes(g.data) for g in back] == [bytes(m.data) for m in fr]


def test_mcap_reader_on_a_cut_file_reads_complete_chunks(tmp_path, rng):
    fr = frames(rng, 3000)
    p = tmp_path / "z.mcap"
    with McapCanWriter(p) as w:
        for i, m in enumerate(fr):
            w.on_message_received(m)
            if i % 500 == 499:
                w._writer.flush()
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.7)])
    got = list(McapCanReader(cut))
    assert 0 < len(got) < len(fr)
    assert [bytes(g.data) for g in got] == [bytes(m.data) for m in fr[:len(got)]]
