"""IMU adapters: MTi packets with garbage through a pseudo-terminal and from a capture file;
every valid packet decoded, counter gaps counted as drops."""

import os
import pty
import time
import tty

import numpy as np
import pytest

from vdps_hil.adapters.base import EndOfInput
from vdps_hil.adapters.imu_adapter import ImuAdapter, ImuFileAdapter, ImuProtocol
from vdps_hil.codecs.imu_mtdata2 import encode_imu_packet


def packets(rng, n, skip=()):
    out, truth = [], []
    for k in range(n):
        if k in skip:
            continue
        f = rng.normal(0, 1, 3) + [0, 0, 9.81]
        w = rng.normal(0, 0.1, 3)
        out.append(encode_imu_packet(k * 1_000_000, f, w, k))
        truth.append((k, f, w))
    return out, truth


def test_protocol_fuzz_garbage_between_packets(rng):
    pk, truth = packets(rng, 500)
    stream = b""
    for p in pk:
        if rng.random() < 0.3:
            junk = rng.integers(0, 256, int(rng.integers(1, 60)), dtype=np.uint8).tobytes()
            stream += junk
        stream += p
    proto = ImuProtocol("imu")
    out = []
    i = 0
    while i < len(stream):
        n = int(rng.integers(1, 300))
        out += proto.feed(i, stream[i:i + n])
        i += n
    out += proto.flush()
    seqs = [int(s.fields["seq_counter"]) for s in out]
    assert seqs == list(range(500))
    for s, (_, f, w) in zip(out, truth):
        assert [s.fields[f"specific_force_mps2_{a}"] for a in "xyz"] == pytest.approx(f, rel=1e-6)
    assert proto.counters["garbage_bytes"] > 0


def test_live_pty_counts_lost_packets_as_drops(rng):
    m, s = pty.openpty()
    tty.setraw(s)
    a = ImuAdapter("imu", os.ttyname(s))
    sub = a.subscribe(raw=False)
    a.open()
    try:
        pk, _ = packets(rng, 200, skip={50, 51, 120})
        os.write(m, b"".join(pk))
        t_end = time.monotonic() + 3
        while a.health.samples < 197 and time.monotonic() < t_end:
            a.poll(0.02)
    finally:
        a.close()
        os.close(m)
        os.close(s)
    got = sub.drain()
    assert len(got) == 197
    assert a.health.drops == 3  # the packet counter says three are missing
    assert [x.t_ns for x in got] == sorted(x.t_ns for x in got)


def test_capture_file(tmp_path, rng):
    pk, _ = packets(rng, 300)
    f = tmp_path / "imu.bin"
    f.write_bytes(b"".join(pk))
    a = ImuFileAdapter("imu", f, chunk=1000)
    sub = a.subscribe(raw=False)
    a.open()
    while True:
        try:
            a.poll(0.0)
        except EndOfInput:
            break
    got = sub.drain()
    assert len(got) == 300 and a.health.error_total() == 0
