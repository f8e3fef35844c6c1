"""Recorder (vdps_hil.record.recorder): adapter events into writer calls, refused writes counted."""

import can

from vdps_hil.record.recorder import Recorder
from vdps_hil.record.writer import RecordingWriter


def test_recorder_counts_refused_writes(tmp_path):
    from vdps_hil.bus.raw import RawCan

    w = RecordingWriter(tmp_path / "r.mcap")
    rec = Recorder(w)
    bad = can.Message(arbitration_id=0x800, data=b"", is_extended_id=False, check=False)
    rec.write(RawCan(1, 1, "can.x", bad))  # an 11-bit ID out of range
    rec.write("not an event")
    w.close()
    assert rec.write_errors == 2 and rec.written == 0 and len(rec.problems) == 2
