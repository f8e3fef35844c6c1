"""Tests of vdps_hil.adapters.candump_stream: candump -L lines written into a real pipe come out
of ``recv`` as the frames they describe (IDs, 29-bit, remote, data, the line's time), a line
that does not parse is one ValueError and reading goes on, and the end of the stream ends the
input only after every frame was received."""

from __future__ import annotations

import os
import time

import pytest

from vdps_hil.adapters.base import EndOfInput
from vdps_hil.adapters.candump_stream import CandumpStreamBus


def _recv_all(bus, n_max=100):
    got = []
    for _ in range(n_max):
        try:
            m = bus.recv(1.0)
        except ValueError as e:
            got.append(e)
            continue
        except EndOfInput:
            got.append("end")
            break
        got.append(m)
    return got


def test_lines_through_a_pipe_are_the_frames():
    r, w = os.pipe()
    bus = CandumpStreamBus(os.fdopen(r, "rb", buffering=0))
    os.write(w, b"(1436509052.249713) can0 100#2A366C2BBA\n(1436509052.25) can0 1ABCDEF0#R\n")
    first = bus.recv(5.0)
    assert first.arbitration_id == 0x100 and bytes(first.data) == bytes.fromhex("2A366C2BBA")
    assert first.timestamp == pytest.approx(1436509052.249713) and not first.is_extended_id
    second = bus.recv(5.0)
    assert second.arbitration_id == 0x1ABCDEF0 and second.is_extended_id and second.is_remote_frame
    assert bus.recv(0.2) is None  # nothing more yet: the stream is open, no end
    os.write(w, b"garbage line\n(2.0) can0 130#0A0B\xff\n(3.0) can0 130#0102 R\n")
    os.close(w)
    got = _recv_all(bus)
    kinds = [type(g).__name__ if not isinstance(g, str) else g for g in got if g is not None]
    assert kinds == ["ValueError", "ValueError", "Message", "end"], got
    assert "garbage line" in str(got[0]) and bus.lines_bad == 2  # the non-UTF-8 byte spoils its line only
    last = [g for g in got if hasattr(g, "arbitration_id")][0]
    assert last.arbitration_id == 0x130 and bytes(last.data) == b"\x01\x02" and last.timestamp == 3.0
    bus.shutdown()


def test_the_end_comes_after_the_last_frame_is_received():
    r, w = os.pipe()
    os.write(w, b"".join(b"(%d.0) can0 101#%02X\n" % (i, i) for i in range(50)))
    os.close(w)
    bus = CandumpStreamBus(os.fdopen(r, "rb", buffering=0))
    time.sleep(0.2)  # the reader thread has seen the end before anything is received
    got = _recv_all(bus)
    frames = [g for g in got if hasattr(g, "arbitration_id")]
    assert [bytes(f.data)[0] for f in frames] == list(range(50)) and got[-1] == "end"
    with pytest.raises(Exception, match="receive-only"):
        bus.send(frames[0])
    bus.shutdown()
