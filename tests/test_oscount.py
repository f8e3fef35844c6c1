"""adapters.oscount: the serial driver's loss counters through TIOCGICOUNT on a real UART
device node (8250 driver, /dev/ttyS0) and their absence on a pseudo-terminal."""

import os
import pty

import pytest

from vdps_hil.adapters.health import SourceHealth
from vdps_hil.adapters.oscount import ICOUNT_FIELDS, OsCounters, serial_icount


def _uart():
    try:
        return os.open("/dev/ttyS0", os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as e:
        pytest.skip(f"no UART device node here: {e}")


def test_uart_driver_reports_its_counters():
    fd = _uart()
    try:
        c = serial_icount(fd)
    finally:
        os.close(fd)
    assert isinstance(c, dict) and set(c) == set(ICOUNT_FIELDS)
    assert all(isinstance(v, int) and v >= 0 for v in c.values())


def test_pty_has_none_and_the_health_says_why():
    m, s = pty.openpty()
    try:
        h = SourceHealth("gnss", "serial", "pty")
        OsCounters(h).update(s)
        assert h.os_counters.startswith("unavailable") and not h.counters
        assert isinstance(serial_icount(s), str)
    finally:
        os.close(m)
        os.close(s)


def test_counts_are_deltas_since_open():
    fd = _uart()
    try:
        h = SourceHealth("gps", "serial", "/dev/ttyS0")
        oc = OsCounters(h)
        oc.update(fd)
        oc.update(fd)
        assert h.os_counters == "yes"
        assert sum(h.counters.values()) == 0  # nothing arrived on an idle UART in between
    finally:
        os.close(fd)
