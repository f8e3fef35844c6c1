"""Tests of vdps_hil.record.recorded_decoding: the signal map and DBC a recording names are found
again by path and content hash (where they were, next to the recording, beside the signal map),
never a file of the same name with other content; a missing one is a one-line error naming it;
the person's options win; a recording without a signal map decodes as before.

On a real recording: the first 3000 frames of the comma2k19 RAV4 candump log imported with the
opendbc DBC and the shipped toyota_rav4_2017 signal map."""

from __future__ import annotations

import itertools
import shutil

import pytest

from vdps_hil.record.decode import decode_recording
from vdps_hil.record.importer import CanSource, import_logs
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.recorded_decoding import RecordedDecodingError, find_recorded_decoding

SEG = "comma2k19_rav4_2018-08-02_seg40"
DBC = "toyota_new_mc_pt_generated.dbc"


@pytest.fixture(scope="module")
def rav4(tmp_path_factory, request):
    real = request.getfixturevalue("real_data_dir")
    d = tmp_path_factory.mktemp("recdec")
    log = d / "pt.log"
    with open(real / SEG / "rav4_seg40.candump.log", "rb") as src:
        log.write_bytes(b"".join(itertools.islice(src, 3000)))
    dbc_dir = d / "dbcs"
    dbc_dir.mkdir()
    shutil.copy(real / SEG / DBC, dbc_dir / DBC)
    rec = d / "rav4.mcap"
    import_logs(rec, [CanSource("pt", str(log), "can0")], signalmap="toyota_rav4_2017",
                dbc={"*": str(dbc_dir / DBC)})
    return rec, dbc_dir / DBC


@pytest.fixture(scope="module")
def real_data_dir():
    from conftest import REAL_DATA

    if not REAL_DATA.is_dir():
        pytest.skip(f"real data not present: {REAL_DATA}")
    return REAL_DATA


def _find(rec, **kw):
    with RecordingReader(rec) as r:
        return find_recorded_decoding(r, rec, **kw)


def _undecoded(rec, rd):
    dec = decode_recording(rec, dbc=rd.dbc, signalmap=rd.signalmap)
    n = sum(1 for _ in dec)
    return n, dec.counters["reader"]["undecoded"], dec.counters.get("can.pt", {})


def test_found_at_the_recorded_paths_and_decodes_every_frame(rav4):
    rec, dbc = rav4
    rd = _find(rec)
    assert rd.source == "recording"
    assert rd.dbc == str(dbc) and rd.signalmap.endswith("toyota_rav4_2017.toml")
    n, undecoded, can = _undecoded(rec, rd)
    with RecordingReader(rec) as r:
        frames = r.topics()["/raw/can/pt"].count  # the can0 lines of the 3000
    assert undecoded == {} and can["frames"] == frames > 1000 and n > 0


def test_moved_dbc_is_found_next_to_the_recording(rav4, tmp_path):
    rec, dbc = rav4
    here = tmp_path / "copy.mcap"
    shutil.copy(rec, here)
    shutil.copy(dbc, tmp_path / DBC)
    moved = dbc.with_suffix(".moved")
    dbc.rename(moved)
    try:
        rd = _find(here)
        assert rd.dbc == str(tmp_path / DBC)
        assert _undecoded(here, rd)[1] == {}
    finally:
        moved.rename(dbc)


def test_same_name_other_content_is_refused_and_missing_is_one_line(rav4, tmp_path):
    rec, dbc = rav4
    here = tmp_path / "copy.mcap"
    shutil.copy(rec, here)
    moved = dbc.with_suffix(".moved")
    dbc.rename(moved)
    try:
        (tmp_path / DBC).write_bytes(moved.read_bytes() + b"\n")  # edited since: another hash
        with pytest.raises(RecordedDecodingError) as e:
            _find(here)
        msg = str(e.value)
        assert "\n" not in msg and "has other content" in msg and "--dbc" in msg and DBC in msg
        (tmp_path / DBC).unlink()
        with pytest.raises(RecordedDecodingError) as e:
            _find(here)
        msg = str(e.value)
        assert "\n" not in msg and "not found" in msg and DBC in msg and "bus pt" in msg and "--dbc FILE" in msg
    finally:
        moved.rename(dbc)


def test_the_options_win(rav4):
    rec, dbc = rav4
    rd = _find(rec, signalmap="toyota_rav4_2017", dbc=str(dbc))
    assert (rd.source, rd.signalmap, rd.dbc) == ("options", "toyota_rav4_2017", str(dbc))


def test_recording_without_a_signal_map_decodes_as_before(tmp_path):
    from vdps_hil.sim.drive import Drive

    p = tmp_path / "sim.mcap"
    Drive("paper", seed=3, duration_s=0.3).run(p)
    rd = _find(p)
    assert (rd.source, rd.signalmap, rd.dbc) == ("default", None, None)
