"""Tests of hil.transports: ``--can`` values (names and python-can interface strings) and their
errors; the listening sockets of a process as /proc shows them."""

from __future__ import annotations

import socket

import pytest

from vdps_hil.adapters.base import AdapterError
from vdps_hil.hil.transports import listening_sockets, parse_transport


def test_listening_sockets_sees_a_socket_bound_to_every_interface():
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("0.0.0.0", 0))
    s.listen(1)
    try:
        assert ("0.0.0.0", s.getsockname()[1]) in listening_sockets()
    finally:
        s.close()


@pytest.mark.parametrize("spec, name, cross", [(None, "virtual", False), ("virtual", "virtual", False),
                                               ("pty", "pty", True), ("tcp", "tcp", True),
                                               ("socketcan:vcan0", "external", False),
                                               ("virtual:hil,receive_own_messages=false", "external", False)])
def test_parse_transport_names_and_interface_strings(spec, name, cross):
    t = parse_transport(spec)
    assert t.name == name and t.cross_process is cross


@pytest.mark.parametrize("spec, sim, words", [("nonsense", None, "is not INTERFACE:CHANNEL"),
                                              ("nosuchbus:0", None, "unknown CAN interface"),
                                              ("pty", "virtual:x", "--sim-can applies"),
                                              ("virtual:a", "bad", "is not INTERFACE:CHANNEL")])
def test_parse_transport_errors_are_one_line(spec, sim, words):
    with pytest.raises(AdapterError) as e:
        parse_transport(spec, sim)
    assert words in str(e.value) and "\n" not in str(e.value)
