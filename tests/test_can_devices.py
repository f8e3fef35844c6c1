"""Tests of hil.can_devices: every CAN device side delivers frames, in order and unchanged, to the
project's CanAdapter opened with the interface string it names (virtual bus, slcan on a pty,
socketcand on 127.0.0.1) and hands back what the pipeline sends; the TCP server listens on
127.0.0.1 only."""

from __future__ import annotations

import os
import socket
import threading
import time

import can
import numpy as np
import pytest

from vdps_hil.adapters.base import Subscription
from vdps_hil.adapters.can_adapter import CanAdapter
from vdps_hil.hil.can_devices import ExternalCanDevice, SlcanPtyDevice, SocketcandServer, VirtualCanDevice
from vdps_hil.hil.transports import listening_sockets


def _frames(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    ids = rng.integers(0x100, 0x140, n).tolist()
    dlcs = rng.integers(0, 9, n).tolist()
    data = rng.integers(0, 256, (n, 8)).astype(np.uint8)
    return ids, dlcs, data


def _receive(dev, n: int, timeout_s: float = 10.0):
    """Open the pipeline's CanAdapter on the device's spec, send n frames, collect them; then
    send one frame from the pipeline and collect it on the device side."""
    stop = threading.Event()
    back: list = []

    def serve():  # the device side answers the adapter (slcan "O") and collects its sends
        while not stop.is_set():
            back.extend(m for _, m in dev.poll(0.01))

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    ad = CanAdapter("vdps", dev.pipeline_spec, batch=16)
    sub = ad.subscribe(Subscription("t", samples=False))
    ad.open()
    reader = threading.Thread(target=ad.run, args=(stop, 0.01), daemon=True)
    reader.start()
    if isinstance(dev, SocketcandServer):
        assert dev.wait_client(10.0)
    ids, dlcs, data = _frames(n)
    sent = 0
    for k in range(0, n, 7):  # in bursts, as the bench sends the frames of one instant
        sent += dev.send_frames(ids[k:k + 7], dlcs[k:k + 7], data[k:k + 7])
        dev.pump()
    got = []
    t_end = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < t_end:
        got += [e for e in sub.drain() if e.direction == "rx"]
        time.sleep(0.005)
    ad.send(can.Message(arbitration_id=0x080, data=bytes(range(8)), is_extended_id=False))
    t_end = time.monotonic() + 5.0
    while not back and time.monotonic() < t_end:
        time.sleep(0.005)
    stop.set()
    reader.join(5.0)
    th.join(5.0)
    return sent, (ids, dlcs, data), got, back


@pytest.mark.parametrize("make", [VirtualCanDevice, SlcanPtyDevice, SocketcandServer],
                         ids=["virtual", "pty", "tcp"])
def test_can_device_sides_deliver_frames_in_order_and_take_the_pipelines_sends(make):
    dev = make()
    dev.open()
    try:
        n = 500
        sent, (ids, dlcs, data), got, back = _receive(dev, n)
        assert sent == n and dev.log.total == n and dev.dropped == 0
        assert len(got) == n
        for k, ev in enumerate(got):
            m = ev.msg
            assert (m.arbitration_id, m.dlc, bytes(m.data)) == (ids[k], dlcs[k], bytes(data[k, :dlcs[k]]))
        assert len(back) == 1 and back[0].arbitration_id == 0x080 and bytes(back[0].data) == bytes(range(8))
    finally:
        dev.close()


def test_slcan_device_answers_commands_and_counts_bad_ones():
    dev = SlcanPtyDevice()
    try:
        fd = os.open(dev.dev.port, os.O_RDWR | os.O_NOCTTY)
        os.write(fd, b"S8\rO\rt0803AABBCC\rtXYZ\rT000001001FF\r")
        t_end = time.monotonic() + 5.0
        frames = []
        while len(frames) < 2 and time.monotonic() < t_end:
            frames += [m for _, m in dev.poll(0.05)]
        assert [(m.arbitration_id, bytes(m.data), m.is_extended_id) for m in frames] == \
            [(0x080, b"\xaa\xbb\xcc", False), (0x100, b"\xff", True)]
        assert dev.bad_commands == 1
        time.sleep(0.05)
        answer = os.read(fd, 100)
        assert answer == b"\r\rz\r\x07z\r"  # OK, OK, transmitted, error, transmitted
        os.close(fd)
    finally:
        dev.close()


def test_tcp_server_listens_on_loopback_only():
    srv = SocketcandServer()
    try:
        mine = listening_sockets()
        assert ("127.0.0.1", srv.port) in mine
        assert all(addr == "127.0.0.1" for addr, _ in mine), mine
        with pytest.raises(OSError):  # not reachable on another address of the host
            other = socket.gethostbyname(socket.gethostname())
            if other.startswith("127."):
                raise OSError("no other address to try")
            socket.create_connection((other, srv.port), timeout=1.0)
    finally:
        srv.close()


def test_external_spec_with_a_virtual_interface_string_runs_through_python_can():
    dev = ExternalCanDevice("virtual:hil-ext-test")
    dev.open()
    try:
        assert dev.in_process
        sent, (ids, dlcs, data), got, back = _receive(dev, 50)
        assert len(got) == 50 and [e.msg.arbitration_id for e in got] == ids
        assert len(back) == 1
    finally:
        dev.close()


@pytest.mark.parametrize("make", [VirtualCanDevice, SocketcandServer], ids=["virtual", "tcp"])
def test_frames_carry_their_time_on_the_bus_as_time_stamp(make):
    """The stamp given to send_frames (the frame's scheduled time on the simulated bus) reaches
    the receiver, as a hardware time stamp does; slcan has no stamp to carry."""
    dev = make()
    dev.open()
    try:
        stop = threading.Event()
        threading.Thread(target=lambda: [dev.poll(0.01) for _ in iter(stop.is_set, True)], daemon=True).start()
        rx = can.Bus(interface=dev.pipeline_spec.split(":")[0], channel=dev.pipeline_spec.split(":")[1].split(",")[0],
                     **({"host": "127.0.0.1", "port": dev.port} if isinstance(dev, SocketcandServer) else {}))
        if isinstance(dev, SocketcandServer):
            assert dev.wait_client(10.0)
        stamps = [1_700_000_000.000123 + 0.001 * k for k in range(5)]
        ids, dlcs, data = _frames(5)
        dev.send_frames(ids, dlcs, data, stamps)
        dev.pump()
        got = [rx.recv(2.0) for _ in range(5)]
        rx.shutdown()
        stop.set()
        assert [m.timestamp for m in got] == pytest.approx(stamps, abs=2e-6)
    finally:
        dev.close()


def test_tcp_server_waits_after_its_client_has_gone():
    """A socket at end of stream is readable for ever: once the pipeline's client closed, each
    poll waits its timeout instead of returning at once (the bench's receiver thread polled
    46,000 times per simulated second there)."""
    srv = SocketcandServer()
    try:
        bus = can.Bus(interface="socketcand", channel="vdps", host="127.0.0.1", port=srv.port)
        assert srv.wait_client(10.0)
        bus.send(can.Message(arbitration_id=0x080, data=b"\x01\x02", is_extended_id=False))
        got = []
        t_end = time.monotonic() + 5.0
        while not got and time.monotonic() < t_end:
            got += srv.poll(0.01)
        assert [m.arbitration_id for _, m in got] == [0x080]
        bus.shutdown()
        polls, t0 = 0, time.monotonic()
        while time.monotonic() - t0 < 0.2:
            assert srv.poll(0.02) == []
            polls += 1
        assert polls <= 11  # 0.2 s of 20 ms waits (a busy loop makes thousands)
    finally:
        srv.close()
