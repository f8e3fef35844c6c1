"""adapters.fdreader: a reader process on a real pseudo-terminal -- every byte arrives in
order with its read time; a parent that takes nothing does not stop the reader; a full buffer
drops whole reads and says how many; a hang-up is reported and a new descriptor resumes it."""

import os
import pty
import socket
import time
import tty

from vdps_hil.adapters.fdreader import DATA, LOST, OVERFLOW, FdReader


def _pty():
    m, s = pty.openpty()
    tty.setraw(s)
    tty.setraw(m)
    return m, s


def _collect(rd, want_bytes, timeout_s=10.0):
    got, events = bytearray(), []
    t_end = time.monotonic() + timeout_s
    while len(got) < want_bytes and time.monotonic() < t_end:
        for kind, t, body in rd.take():
            if kind == DATA:
                got += body
            else:
                events.append((kind, body))
        time.sleep(0.01)
    return bytes(got), events


def test_bytes_arrive_in_order_with_read_times_while_the_parent_takes_nothing(rng):
    m, s = _pty()
    rd = FdReader("t")
    try:
        rd.give(s)
        blob = rng.integers(0, 256, 200_000, dtype="uint8").tobytes()
        t0 = time.monotonic_ns()
        # 200 kB is ten times what a pty holds: written while this process never reads, it
        # only fits because the reader process drains the pty into its own buffer
        os.set_blocking(m, False)
        k, t_end = 0, time.monotonic() + 20
        while k < len(blob) and time.monotonic() < t_end:
            try:
                k += os.write(m, blob[k:k + 1000])
            except BlockingIOError:
                time.sleep(0.001)
        assert k == len(blob), "the pty stayed full: nothing drained it"
        t1 = time.monotonic_ns()
        recs = rd.stop()
    finally:
        os.close(m)
        os.close(s)
    data = b"".join(b for kind, _, b in recs if kind == DATA)
    times = [t for kind, t, _ in recs if kind == DATA]
    assert data == blob
    assert all(t0 <= t <= t1 + 1_000_000_000 for t in times) and times == sorted(times)
    assert not [r for r in recs if r[0] != DATA]


def test_full_buffer_drops_whole_reads_and_counts_them():
    m, s = _pty()
    rd = FdReader("t", max_buffer_bytes=3000)
    try:
        rd.give(s)
        total = 0
        # the parent takes nothing until the end: the socket's buffer and then the reader's
        # 3000 bytes fill up, after which whole reads are dropped
        rd.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        for _ in range(400):
            os.write(m, b"x" * 1000)
            total += 1000
            time.sleep(0.002)
        time.sleep(0.2)
        t0 = time.monotonic()
        recs = rd.stop()
        stop_s = time.monotonic() - t0
    finally:
        os.close(m)
        os.close(s)
    kept = sum(len(b) for kind, _, b in recs if kind == DATA)
    drops = [b for kind, _, b in recs if kind == OVERFLOW]
    assert drops, "the buffer never overflowed"
    # every byte kept or counted dropped (the context says how the reader ended if not)
    assert kept + sum(b for _, b in drops) == total, (
        drops, [r for r in recs if r[0] == LOST], rd.proc.returncode, round(stop_s, 3))
    assert sum(n for n, _ in drops) >= 1


def test_hang_up_is_reported_and_a_new_descriptor_resumes_reading():
    m, s = _pty()
    rd = FdReader("t")
    try:
        rd.give(s)
        os.write(m, b"before")
        got, _ = _collect(rd, 6)
        assert got == b"before"
        os.close(m)  # the device goes away: the slave side hangs up
        t_end = time.monotonic() + 5
        events = []
        while not events and time.monotonic() < t_end:
            events = [r for r in rd.take() if r[0] == LOST]
            time.sleep(0.01)
        assert events and "hang-up" in events[0][2]
        os.close(s)
        m, s = _pty()
        rd.give(s)
        os.write(m, b"after")
        got, ev = _collect(rd, 5)
        assert got == b"after" and not ev
    finally:
        rd.stop()
        os.close(m)
        os.close(s)


def test_reader_ends_when_the_parent_goes_away():
    m, s = _pty()
    rd = FdReader("t")
    rd.give(s)
    rd.sock.close()  # as if the parent died
    rd.proc.wait(5)
    assert rd.proc.returncode == 0
    os.close(m)
    os.close(s)


def test_bytes_still_arriving_at_quit_are_read_before_the_reader_exits():
    """At quit the reader drains the device until it has been quiet for DRAIN_QUIET_S (0.1 s):
    bytes that reach it 20 ms after the quit (still on their way through the terminal layer
    when it came) are kept, not lost with the process."""
    import threading

    m, s = _pty()
    rd = FdReader("t")
    try:
        rd.give(s)
        os.write(m, b"a" * 500)
        _collect(rd, 500)
        late = threading.Timer(0.02, os.write, (m, b"b" * 700))
        late.start()
        recs = rd.stop()
        late.join()
    finally:
        os.close(m)
        os.close(s)
    got = b"".join(b for kind, _, b in recs if kind == DATA)
    assert got == b"b" * 700
