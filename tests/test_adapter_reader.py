"""adapters.reader.ThreadReader on python-can's virtual bus and a read function: frames
stamped as they are read, the device lost and given back, a full queue counted, the end of an
input reported."""

import threading
import time

import can

from vdps_hil.adapters.base import DeviceLost, EndOfInput
from vdps_hil.adapters.reader import DATA, ERROR, LOST, OVERFLOW, ThreadReader


def test_frames_of_a_virtual_bus_are_stamped_when_read(rng):
    chan = f"tr_{rng.integers(1 << 30)}"
    rx = can.Bus(interface="virtual", channel=chan)
    tx = can.Bus(interface="virtual", channel=chan)

    def read(timeout_s):
        m = rx.recv(timeout_s)
        return [] if m is None else [(None, m)]

    rd = ThreadReader("v", read, time.monotonic_ns)
    try:
        t0 = time.monotonic_ns()
        for k in range(200):
            tx.send(can.Message(arbitration_id=0x100 + k % 3, data=bytes([k % 256])))
        t_end = time.monotonic() + 5
        got = []
        while len(got) < 200 and time.monotonic() < t_end:
            got += rd.take()
            time.sleep(0.01)
    finally:
        rd.stop()
        rx.shutdown()
        tx.shutdown()
    assert [r[0] for r in got] == [DATA] * 200
    assert [r[2].data[0] for r in got] == [k % 256 for k in range(200)]
    times = [r[1] for r in got]
    assert times == sorted(times) and times[0] >= t0


def test_lost_device_waits_for_give_and_errors_are_reported():
    calls = {"n": 0}

    def read(timeout_s):
        calls["n"] += 1
        if calls["n"] == 2:
            raise DeviceLost("unplugged")
        if calls["n"] == 3:
            raise OSError("EIO once")
        time.sleep(0.001)
        return [(123, b"x")]

    rd = ThreadReader("d", read, time.monotonic_ns, lost=(DeviceLost,), poll_s=0.01)
    time.sleep(0.2)
    recs = rd.take()
    assert recs[0] == (DATA, 123, b"x") and recs[1][0] == LOST and recs[1][2] == "unplugged"
    assert len(recs) == 2 and calls["n"] == 2  # nothing read while the device is lost
    rd.give()
    time.sleep(0.1)
    recs = rd.stop()
    assert recs[0][0] == ERROR and recs[1][0] == DATA


def test_full_queue_drops_and_counts_and_end_of_input_ends_the_thread():
    n = {"k": 0}
    gate = threading.Event()

    def read(timeout_s):
        n["k"] += 1
        if n["k"] > 10:
            gate.set()
            raise EndOfInput()
        return [(n["k"], b"abc")] * 100

    rd = ThreadReader("f", read, time.monotonic_ns, end=(EndOfInput,), max_items=250)
    assert gate.wait(5)
    time.sleep(0.05)
    assert not rd.alive
    recs = rd.stop()
    data = [r for r in recs if r[0] == DATA]
    over = [r for r in recs if r[0] == OVERFLOW]
    assert len(data) == 200 and sum(r[2][0] for r in over) == 800
    assert recs[-1][0] in (LOST, OVERFLOW)
