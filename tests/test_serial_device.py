"""Tests of hil.serial_device: serial ptys carry bytes to a pyserial reader; a full wire drops
whole messages and counts them; the send log finds the send time of any frame or byte."""

from __future__ import annotations

import os
import time

import numpy as np
import serial

from vdps_hil.hil.serial_device import PtySerialDevice, SendLog


def test_serial_pty_carries_bytes_and_logs_their_send_times():
    dev = PtySerialDevice("imu")
    try:
        ser = serial.serial_for_url(dev.port, baudrate=921600, timeout=0.2)
        chunks = [bytes([k]) * (10 + k) for k in range(20)]
        for c in chunks:
            assert dev.write(c)
        want = b"".join(chunks)
        got = b""
        t_end = time.monotonic() + 5.0
        while len(got) < len(want) and time.monotonic() < t_end:
            got += ser.read(len(want) - len(got))
        assert got == want and dev.bytes_in == len(want) and dev.log.total == len(want)
        cum, t = dev.log.arrays()
        assert cum[-1] == len(want) and np.all(np.diff(t) >= 0)
        ser.close()
    finally:
        dev.close()


def test_a_full_wire_drops_whole_messages_and_counts_them():
    """Nobody reads: the pty (some 20-30 KB) and the 4 KiB device FIFO fill, then every further
    message is dropped whole; what was accepted is exactly what a late reader gets."""
    dev = PtySerialDevice("imu", fifo_bytes=4096)
    try:
        msg = bytes(range(47))
        accepted = sum(dev.write(msg) for _ in range(2000))  # 94 KB offered
        assert dev.dropped == 2000 - accepted > 0
        assert dev.pending_bytes <= 4096  # the device FIFO never holds more than its size
        fd = os.open(dev.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        got = b""
        t_end = time.monotonic() + 5.0
        while len(got) < accepted * 47 and time.monotonic() < t_end:
            dev.pump()
            try:
                got += os.read(fd, 65536)
            except BlockingIOError:
                time.sleep(0.01)
        os.close(fd)
        assert got == msg * accepted  # whole messages only, in order
    finally:
        dev.close()


def test_send_log_finds_the_send_time_of_any_item():
    log = SendLog()
    log.add(3, 100)  # items 0..2 at t=100
    log.add(0, 150)  # nothing: not logged
    log.add(2, 200)  # items 3, 4
    log.add(5, 300)  # items 5..9
    assert log.time_of([0, 2, 3, 4, 5, 9, 10, -1]).tolist() == [100, 100, 200, 200, 300, 300, -1, -1]
    assert log.total == 10


def test_closing_twice_never_closes_a_descriptor_the_process_reused():
    """The second close closes nothing: the numbers of the pty's ends are free after the first and
    the next file opened takes them (here a pipe), which a second os.close would cut."""
    import os

    dev = PtySerialDevice("imu")
    dev.close()
    r, w = os.pipe()
    try:
        dev.close()
        assert dev.read(0.01) == b""
        os.write(w, b"x")
        assert os.read(r, 1) == b"x"  # both ends still open
    finally:
        os.close(r)
        os.close(w)
