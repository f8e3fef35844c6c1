"""RecordingSink: the bulk CAN path (one write_can_frames per block, records built with numpy)
writes the file the per-frame reference path (one write_can per frame) writes, byte for byte."""

import pytest

from vdps_hil.record import schemas as S
from vdps_hil.record.writer import RecordingWriter
from vdps_hil.sim.drive import Drive
from vdps_hil.sim.sinks import RecordingSink


def _drive_file(path, bulk: bool, faults) -> bytes:
    writer = RecordingWriter(path, metadata={"source": "vdps sim"}, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
    session = Drive("paper", seed=1, duration_s=1.2, faults=faults).start(RecordingSink(writer, bulk=bulk))
    while session.advance():
        pass
    writer.close()
    return path.read_bytes()


@pytest.mark.parametrize("faults", [(), ("clock_jump:device=can,t_s=0.6,jump_s=-0.2", "dropped_frames:fraction=0.3,t_s=0.2,duration_s=0.5")])
def test_bulk_can_path_writes_the_reference_file(tmp_path, faults):
    """A 1.2 s drive of scenario paper (seed 1), plain and with CAN time stamps jumping back and
    frames dropped: the same file bytes (records, indexes, chunks) with both paths."""
    bulk = _drive_file(tmp_path / "bulk.mcap", True, faults)
    ref = _drive_file(tmp_path / "ref.mcap", False, faults)
    assert len(bulk) > 100_000 and bulk == ref
