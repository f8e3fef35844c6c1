"""Serial adapter on real pseudo-terminals: chunked reads, a device that disappears and comes
back (reconnect, outage counted), one-line errors for bad ports."""

import os
import pty
import time
import tty

import pytest

from vdps_hil.adapters.base import AdapterError, EndOfInput
from vdps_hil.adapters.serial_adapter import SerialAdapter, SerialFileAdapter, parse_port_spec
from vdps_hil.bus.raw import RawSerial


class Pty:
    """A pseudo-terminal whose slave is reachable through a stable symlink (like a udev
    /dev/serial/by-id/ name), so it can vanish and come back under the same name."""

    def __init__(self, link):
        self.link = link
        self.master = self.slave = None
        self.up()

    def up(self):
        self.master, self.slave = pty.openpty()
        tty.setraw(self.slave)
        if os.path.lexists(self.link):
            os.unlink(self.link)
        os.symlink(os.ttyname(self.slave), self.link)

    def down(self):
        os.close(self.master)
        os.close(self.slave)
        os.unlink(self.link)

    def write(self, data):
        os.write(self.master, data)


def pump(a, until, timeout=3.0):
    t_end = time.monotonic() + timeout
    while not until() and time.monotonic() < t_end:
        a.poll(0.02)


def test_parse_port_spec():
    assert parse_port_spec("/dev/ttyUSB0@921600") == ("/dev/ttyUSB0", 921600)
    assert parse_port_spec("COM4") == ("COM4", 115200)
    assert parse_port_spec("socket://127.0.0.1:5000@9600") == ("socket://127.0.0.1:5000", 9600)
    for bad in ("", "/dev/x@fast", "/dev/x@0", "@9600"):
        with pytest.raises(AdapterError):
            parse_port_spec(bad)


def test_bad_port_is_one_line(tmp_path):
    a = SerialAdapter("gnss", str(tmp_path / "no_such_tty"), 115200)
    with pytest.raises(AdapterError) as e:
        a.open()
    assert "cannot open" in str(e.value) and "\n" not in str(e.value)


def test_reads_what_is_waiting_in_chunks(tmp_path):
    p = Pty(str(tmp_path / "dev"))
    a = SerialAdapter("dev", p.link, 115200)
    sub = a.subscribe(samples=False)
    a.open()
    try:
        blob = bytes(range(256)) * 40  # 10 kB written at once
        p.write(blob)
        pump(a, lambda: a.health.bytes >= len(blob))
    finally:
        a.close()
        p.down()
    chunks = [e for e in sub.drain() if isinstance(e, RawSerial)]
    assert b"".join(c.data for c in chunks) == blob
    assert len(chunks) < len(blob) / 100  # chunks, not a read per byte
    assert all(c.baud == 115200 for c in chunks)


def test_device_vanishes_and_returns_reconnects_and_counts_outage(tmp_path):
    p = Pty(str(tmp_path / "gnss"))
    a = SerialAdapter("gnss", p.link, 115200, reconnect_s=0.05)
    sub = a.subscribe(samples=False)
    a.open()
    try:
        p.write(b"before\r\n")
        pump(a, lambda: a.health.bytes >= 8)
        p.down()  # unplugged
        pump(a, lambda: a.health.state == "lost")
        assert a.health.state == "lost"
        t_lost = time.monotonic()
        while time.monotonic() - t_lost < 0.3:
            a.poll(0.02)  # retries fail while it is away
        p.up()  # plugged back in (new pty, same name)
        pump(a, lambda: a.health.state == "open")
        p.write(b"after\r\n")
        pump(a, lambda: a.health.bytes >= 15)
    finally:
        a.close()
        p.down()
    c = a.health.counters
    assert c["outages"] == 1 and c["reconnects"] == 1
    assert a.health.outage_ns / 1e9 >= 0.3
    assert b"".join(e.data for e in sub.drain()) == b"before\r\nafter\r\n"


def test_a_port_has_one_reader_and_a_reconnect_cannot_steal_another_s(tmp_path):
    """A device path is opened exclusively: a second adapter on the same pty is refused in one
    line, and an adapter reconnecting by path to a pty now held by another reader stays lost
    instead of sharing (and halving) its bytes; once the holder closes, it reconnects."""
    p = Pty(str(tmp_path / "imu"))
    first = SerialAdapter("imu", p.link, 921600)
    second = SerialAdapter("imu2", p.link, 921600, reconnect_s=0.02)
    first.open()
    try:
        with pytest.raises(AdapterError) as e:
            second.open()
        assert "cannot open" in str(e.value) and "lock" in str(e.value) and "\n" not in str(e.value)
        second.health.state = "lost"  # as after an outage: retrying by path
        t_end = time.monotonic() + 0.3
        while time.monotonic() < t_end:
            second.poll(0.01)
        p.write(b"only for the first\r\n")
        pump(first, lambda: first.health.bytes >= 20)
        assert first.health.bytes == 20 and second.health.bytes == 0 and second.health.state == "lost"
        first.close()
        pump(second, lambda: second.health.state == "open")
        assert second.health.state == "open"
        shared = SerialAdapter("imu3", p.link, 921600, serial_kwargs={"exclusive": False})
        shared.open()  # asked for: no lock taken
        shared.close()
    finally:
        first.close()
        second.close()
        p.down()


def test_file_adapter_stamps_by_wire_time(tmp_path):
    f = tmp_path / "cap.bin"
    f.write_bytes(b"x" * 10_000)
    a = SerialFileAdapter("imu", f, 100_000, chunk=1000, t0_ns=5)
    sub = a.subscribe(samples=False)
    a.open()
    while True:
        try:
            a.poll(0.0)
        except EndOfInput:
            break
    chunks = sub.drain()
    assert len(chunks) == 10
    # 1000 bytes at 100 kbit/s, 10 bits per byte: 0.1 s per chunk, stamped at its end
    assert [c.t_ns for c in chunks] == [5 + (k + 1) * 100_000_000 for k in range(10)]


def test_uart_loss_counters_are_read_into_the_health():
    """A real UART (8250 driver): the OS's own loss counters are known; on a pty they are not."""
    if not os.path.exists("/dev/ttyS0"):
        pytest.skip("no UART device node here")
    a = SerialAdapter("gps", "/dev/ttyS0", 9600)
    try:
        a.open()
    except AdapterError as e:
        pytest.skip(f"UART not usable: {e}")
    try:
        a.check_os_counters()
        a.check_os_counters()
        assert a.health.os_counters == "yes"
        assert a.status()["loss"]["os"] == 0 and "(os 0," in a.status_line()
    finally:
        a.close()
    m, s = pty.openpty()
    b = SerialAdapter("gnss", os.ttyname(s), 115200)
    b.open()
    try:
        b.check_os_counters()
        assert b.health.os_counters.startswith("unavailable") and "(os ?," in b.status_line()
    finally:
        b.close()
        os.close(m)
        os.close(s)
