"""CAN adapters: interface strings, python-can's virtual bus as a live source, every log
format python-can writes read back, bad input counted and never fatal."""

import tempfile
import threading
import time

import can
import numpy as np
import pytest

from vdps_hil.adapters.base import AdapterError, EndOfInput
from vdps_hil.adapters.can_adapter import CanAdapter, CanFileAdapter, parse_can_spec
from vdps_hil.bus.raw import RawCan
from vdps_hil.bus.samples import Sample
from vdps_hil.bus.subscription import Subscription
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_encode import encode_steer, encode_wheel_speeds


def test_parse_can_spec():
    assert parse_can_spec("socketcan:can0") == ("socketcan", "can0", {})
    assert parse_can_spec("pcan:PCAN_USBBUS1,bitrate=500000,fd=false") == \
        ("pcan", "PCAN_USBBUS1", {"bitrate": 500000, "fd": False})
    assert parse_can_spec("slcan:/dev/ttyACM0@115200") == ("slcan", "/dev/ttyACM0@115200", {})
    assert parse_can_spec("virtual:hil,receive_own_messages=true")[2] == \
        {"receive_own_messages": True}


@pytest.mark.parametrize("spec,needle", [
    ("can0", "INTERFACE:CHANNEL"),
    ("nosuchbus:x", "unknown CAN interface 'nosuchbus'"),
    ("socketcan:", "has no channel"),
    ("pcan:X,bitrate", "not key=value"),
])
def test_bad_spec_is_one_line(spec, needle):
    with pytest.raises(AdapterError) as e:
        CanAdapter("b", spec)
    assert needle in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("spec", ["slcan:/dev/ttyDOES_NOT_EXIST,sleep_after_open=0",
                                  "socketcan:vdps_missing0"])
def test_unopenable_device_is_one_line_adapter_error(spec):
    a = CanAdapter("b", spec)
    with pytest.raises(AdapterError) as e:
        a.open()
    assert str(e.value).startswith("CAN ") and "\n" not in str(e.value)


def _pump(adapter, n_expected, timeout=5.0):
    t_end = time.monotonic() + timeout
    while adapter.health.records < n_expected and time.monotonic() < t_end:
        adapter.poll(0.05)


def test_virtual_bus_live_decoding_and_counted_rejects(rng):
    chan = f"t_{rng.integers(1 << 30)}"
    a = CanAdapter("vdps", f"virtual:{chan}", decoder=VdpsCanDecoder())
    sub = a.subscribe(Subscription())
    a.open()
    tx = can.Bus(interface="virtual", channel=chan)
    try:
        good = list(encode_wheel_speeds([10.0, 11.0, 12.0, 13.0], 0))
        frames = good + [
            can.Message(arbitration_id=0x555, data=b"\x01\x02", is_extended_id=False),
            can.Message(arbitration_id=0x100, data=b"\x00\x01\x02", is_extended_id=False),
            can.Message(arbitration_id=0x100, is_remote_frame=True, dlc=5, is_extended_id=False),
            can.Message(arbitration_id=0x101, data=bytes(good[1].data[:4]) + b"\x01", is_fd=True,
                        is_extended_id=False),  # right ID, length and counter, but CAN FD
        ] + list(encode_wheel_speeds([20.0, 21.0, 22.0, 23.0], 1))
        for m in frames:
            tx.send(m)
        _pump(a, len(frames))
    finally:
        tx.shutdown()
        a.close()
    ev = sub.drain()
    raws = [e for e in ev if isinstance(e, RawCan)]
    samples = [e for e in ev if isinstance(e, Sample)]
    assert len(raws) == len(frames)  # raw always, rejects included
    assert [s.fields.get("wheel_speed_radps_1", s.fields.get("wheel_speed_radps_3"))
            for s in samples] == pytest.approx([10.0, 12.0, 20.0, 22.0])
    c = a.health.all_counters()
    assert c["unknown_id"] == 1 and c["dlc_mismatch"] == 1
    assert c["remote_frame"] == 1 and c["fd_frame"] == 1
    assert a.health.error_total() == 3  # DLC mismatch, remote, FD; unknown IDs are not errors
    # one host clock: raw t_ns increase, device time stamps kept
    assert all(r.device_time_ns for r in raws)
    assert [r.t_ns for r in raws] == sorted(r.t_ns for r in raws)


def test_fuzz_random_frames_interleaved_every_valid_decoded(rng):
    """Random IDs, lengths and bytes between valid frames through the live path: no crash,
    every valid frame decoded."""
    chan = f"f_{rng.integers(1 << 30)}"
    a = CanAdapter("vdps", f"virtual:{chan}", decoder=VdpsCanDecoder())
    sub = a.subscribe(Subscription(raw=False))
    a.open()
    tx = can.Bus(interface="virtual", channel=chan)
    sent = []
    n = 0
    try:
        for k in range(400):
            for _ in range(int(rng.integers(0, 4))):
                aid = int(rng.choice([0x100, 0x101, 0x110, 0x120, 0x130, 0x80,
                                      int(rng.integers(0, 0x800))]))
                data = bytes(rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8))
                if aid in (0x100, 0x101, 0x110, 0x120, 0x130, 0x80):
                    aid = 0x7F0  # random payloads on real IDs would count as valid frames
                tx.send(can.Message(arbitration_id=aid, data=data, is_extended_id=False))
                n += 1
            x = float(rng.uniform(-12, 12))
            tx.send(encode_steer(x, k % 256))
            sent.append(x)
            n += 1
        _pump(a, n)
    finally:
        tx.shutdown()
        a.close()
    got = [s.fields["steer_wheel_angle_rad"] for s in sub.drain() if s.kind == "steer"]
    assert got == pytest.approx(sent, abs=0.0005 + 1e-12)
    assert a.health.all_counters()["unknown_id"] > 0
    assert "decoder_exceptions" not in a.health.counters


def test_send_is_recorded_as_tx(rng):
    chan = f"s_{rng.integers(1 << 30)}"
    a = CanAdapter("hil", f"virtual:{chan}")
    sub = a.subscribe()
    a.open()
    try:
        a.send(can.Message(arbitration_id=0x80, data=bytes(8), is_extended_id=False))
    finally:
        a.close()
    [ev] = sub.drain()
    assert ev.direction == "tx" and a.health.counters["sent"] == 1


def _frames(rng, n=200):
    out = []
    t0 = 1_700_000_000.0
    for i in range(n):
        ext = bool(i % 7 == 0)
        aid = int(rng.integers(0, 0x1FFFFFFF if ext else 0x7FF))
        data = bytes(rng.integers(0, 256, 8, dtype=np.uint8))
        out.append(can.Message(timestamp=t0 + i * 0.001, arbitration_id=aid, data=data,
                               is_extended_id=ext, channel=0))
    return out


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".log", ".trc", ".csv", ".mf4"])
def test_every_python_can_format_reads_back(tmp_path, rng, suffix):
    frames = _frames(rng)
    path = tmp_path / f"x{suffix}"
    with can.Logger(path) as w:
        for m in frames:
            w.on_message_received(m)
    a = CanFileAdapter("b", path)
    sub = a.subscribe(raw=True, samples=False)
    a.open()
    while True:
        try:
            a.poll(0.0)
        except EndOfInput:
            break
    got = [e.msg for e in sub.drain()]
    assert len(got) == len(frames)
    for m, g in zip(frames, got):
        assert (g.arbitration_id, bytes(g.data), g.is_extended_id) == \
            (m.arbitration_id, bytes(m.data), m.is_extended_id)
    t = np.array([e for e in (int(round(g.timestamp * 1e9)) for g in got)])
    assert np.all(np.diff(t) > 0)


def test_channel_filter_and_other_channels_recorded_apart(real_data):
    path = real_data / "comma2k19_rav4_2018-08-02_seg40" / "rav4_seg40.candump.log"
    only = CanFileAdapter("pt", path, channels=["can0"])
    split = CanFileAdapter("pt", path, decode_channels=["can0"], decoder=VdpsCanDecoder())
    res = {}
    for a in (only, split):
        sub = a.subscribe(samples=False)
        a.open()
        while True:
            try:
                a.poll(0.0)
            except EndOfInput:
                break
        res[a] = {}
        for e in sub.drain():
            res[a][e.source] = res[a].get(e.source, 0) + 1
    assert res[only] == {"can.pt": 53800}
    assert res[split] == {"can.pt": 53800, "can.pt.can1": 45000}
    assert split.health.counters["other_channel"] == 45000


def test_missing_and_unknown_format_files(tmp_path):
    with pytest.raises(AdapterError, match="no such file"):
        CanFileAdapter("b", tmp_path / "nope.asc").open()
    p = tmp_path / "x.xyz"
    p.write_text("hello")
    with pytest.raises(AdapterError, match="readable:"):
        CanFileAdapter("b", p).open()


@pytest.mark.parametrize("damage", ["truncated", "cut_at_30_percent", "block_id"])
def test_a_damaged_real_mf4_is_one_line_and_nothing_else_on_the_terminal(tmp_path, real_data, monkeypatch, capfd,
                                                                          damage):
    """The CANedge log cut at 2 % (asammdf: "seek out of range"), or its first channel-group
    block's id broken (asammdf logs "Expected ##CG block" on its own console handler): either
    way asammdf's half-built reader raised in its __del__, which Python printed as "Exception
    ignored ... Traceback" after our one line. Now the one line is all (adapters.quiet_readers):
    nothing reaches the asammdf logger's handlers or Python's unraisable hook. Cut at 30 %, asammdf
    printed its own traceback (``print(format_exc())`` in ``_finalize``) on standard output: nothing
    reaches the terminal now."""
    import logging
    import sys

    data = (real_data / "css_canedge_gnss_imu_mf4" / "gnss1.MF4").read_bytes()
    if damage == "truncated":
        data = data[: len(data) // 50]
    elif damage == "cut_at_30_percent":
        data = data[: len(data) * 3 // 10]
    else:
        i = data.index(b"##CG")
        data = data[:i] + b"##CX" + data[i + 4:]
    path = tmp_path / "gnss1.MF4"
    path.write_bytes(data)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    unraisable, logged = [], []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: unraisable.append(repr(u.exc_value)))
    handler = logging.Handler()
    handler.emit = lambda record: logged.append(record.getMessage())
    lg = logging.getLogger("asammdf")
    lg.addHandler(handler)
    try:
        with pytest.raises(AdapterError) as ei:
            CanFileAdapter("gnss", path).open()
        import gc

        gc.collect()
    finally:
        lg.removeHandler(handler)
    msg = str(ei.value)
    assert msg.startswith(f"CAN log {path}: unreadable: ") and "\n" not in msg, msg
    assert unraisable == [] and logged == [], (unraisable, logged)
    assert lg.disabled is False  # as it was before
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out, err)
    assert sorted(p.name for p in scratch.iterdir()) == []  # no copy of the log left behind


def _read_all(a):
    sub = a.subscribe(samples=False)
    a.open()
    while True:
        try:
            a.poll(0.0)
        except EndOfInput:
            break
    return [e.msg for e in sub.drain()]


@pytest.mark.parametrize("suffix,garbage", [
    (".asc", b" 1.234567 1 zz7x Rx d 8 GG HH\n"),
    (".log", b"(1.0) can0 ZZZ#GG\n\xff\xfe\xfd not utf-8\n"),
    (".trc", b"  garbage 12 not a trc line\n"),
    (".csv", b"1.0,not,a,frame\n"),
])
def test_garbage_lines_are_counted_and_every_good_frame_read(tmp_path, rng, suffix, garbage):
    frames = _frames(rng, 300)
    path = tmp_path / f"x{suffix}"
    with can.Logger(path) as w:
        for m in frames:
            w.on_message_received(m)
    lines = path.read_bytes().splitlines(keepends=True)
    k = len(lines) // 2  # between two frame lines
    path.write_bytes(b"".join(lines[:k]) + garbage + b"".join(lines[k:]))
    a = CanFileAdapter("b", path)
    got = _read_all(a)
    assert [(g.arbitration_id, bytes(g.data)) for g in got] == \
        [(m.arbitration_id, bytes(m.data)) for m in frames]
    c = a.health.counters
    assert c["bad_lines"] == 1 and c.get("read_errors", 0) == 0
    assert c.get("non_utf8_lines", 0) == (1 if b"\xff" in garbage else 0)
    assert a.health.error_total() >= 1


def test_truncated_binary_log_keeps_the_frames_before(tmp_path, rng):
    frames = _frames(rng, 2000)
    path = tmp_path / "x.blf"
    with can.Logger(path) as w:
        for m in frames:
            w.on_message_received(m)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    got = _read_all(CanFileAdapter("b", path))
    assert 0 < len(got) < len(frames)
    assert [bytes(g.data) for g in got] == [bytes(m.data) for m in frames[:len(got)]]


def test_run_in_thread_until_stopped(rng):
    chan = f"r_{rng.integers(1 << 30)}"
    a = CanAdapter("vdps", f"virtual:{chan}", decoder=VdpsCanDecoder())
    sub = a.subscribe(raw=False)
    stop = threading.Event()
    a.open()
    th = threading.Thread(target=a.run, args=(stop, 0.01))
    th.start()
    tx = can.Bus(interface="virtual", channel=chan)
    try:
        for k in range(100):
            tx.send(encode_steer(0.01 * k, k))
        t_end = time.monotonic() + 5
        while a.health.samples < 100 and time.monotonic() < t_end:
            time.sleep(0.01)
    finally:
        stop.set()
        th.join(5)
        tx.shutdown()
    assert not th.is_alive() and a.health.state == "closed"
    assert len(sub.drain()) == 100 and a.health.all_counters()["lost_frames"] == 0


def _plug(link):
    """A pseudo-terminal (raw) named by the symlink ``link``, as a USB-CAN adapter plugged in
    (again) under the same name: (master, slave) descriptors."""
    import os
    import pty
    import tty

    m, s = pty.openpty()
    tty.setraw(s)
    if link.is_symlink():
        link.unlink()
    link.symlink_to(os.ttyname(s))
    return m, s


def test_slcan_adapter_on_a_pty_reconnects_after_unplug(tmp_path):
    """The slcan path end to end (our chunked reader), including a USB-CAN adapter that is
    unplugged and plugged back in under the same name."""
    import os

    from vdps_hil.adapters.can_adapter import slcan_line

    link = tmp_path / "ttyACM0"
    m, s = _plug(link)
    a = CanAdapter("vdps", f"slcan:{link},sleep_after_open=0", decoder=VdpsCanDecoder(),
                   reconnect_s=0.05)
    sub = a.subscribe(raw=False)
    a.open()
    try:
        os.write(m, b"".join(slcan_line(f.arbitration_id, bytes(f.data))
                             for k in range(50) for f in encode_wheel_speeds([5.0] * 4, k)))
        os.write(m, b"tZZZ8GARBAGE!!\r\xff\xfe\r")  # malformed lines: counted, not fatal
        _pump(a, 100)
        os.close(m)
        os.close(s)
        link.unlink()
        t_end = time.monotonic() + 3
        while a.health.state != "lost" and time.monotonic() < t_end:
            a.poll(0.02)
        assert a.health.state == "lost"
        m, s = _plug(link)
        t_end = time.monotonic() + 3
        while a.health.state != "open" and time.monotonic() < t_end:
            a.poll(0.02)
        os.write(m, b"".join(slcan_line(f.arbitration_id, bytes(f.data))
                             for f in encode_wheel_speeds([6.0] * 4, 50)))
        _pump(a, 102)
    finally:
        a.close()
        os.close(m)
        os.close(s)
    got = sub.drain()
    assert len(got) == 102 and got[-1].fields["wheel_speed_radps_3"] == pytest.approx(6.0)
    c = a.health.all_counters()
    assert c["outages"] == 1 and c["reconnects"] == 1
    assert c["bad_frames"] >= 1 and c["lost_frames"] == 0


def test_an_slcan_port_another_reader_holds_is_refused_and_not_read(tmp_path):
    """python-can opens an slcan port without a lock; the adapter takes the port's exclusive lock
    first (``slcan.lock_port``). A port an exclusive reader holds (an IMU on a pseudo-terminal
    whose number a bench's slcan bus had before) is refused in one line and none of its bytes
    are taken; while the slcan bus holds its port, an exclusive serial reader is refused."""
    import os

    from vdps_hil.adapters.serial_adapter import SerialAdapter

    link = tmp_path / "ttyIMU"
    m, s = _plug(link)
    holder = SerialAdapter("imu", str(link), 921600)
    holder.open()
    try:
        os.write(m, b"x" * 1000)
        a = CanAdapter("vdps", f"slcan:{link},sleep_after_open=0", reconnect_s=0.05)
        with pytest.raises(AdapterError, match="in use by another reader") as e:
            a.open()
        assert "\n" not in str(e.value)
        time.sleep(0.05)
        assert holder.ser.read(holder.ser.in_waiting) == b"x" * 1000  # every byte still the holder's
    finally:
        holder.close()
    a = CanAdapter("vdps", f"slcan:{link},sleep_after_open=0")
    a.open()
    try:
        with pytest.raises(AdapterError, match="cannot open"):
            SerialAdapter("imu2", str(link), 921600).open()
        a.close()
        after = SerialAdapter("imu3", str(link), 921600)  # the lock went with the bus
        after.open()
        after.close()
    finally:
        a.close()
        os.close(m)
        os.close(s)


def test_slcan_reader_process_parses_frames_and_reconnects(tmp_path):
    """The starvation-proof path: a reader process drains the slcan port, the adapter parses
    the lines it collects; an unplug is reported by the reader and the replugged port is
    handed to it again."""
    import os

    from vdps_hil.adapters.can_adapter import slcan_line

    link = tmp_path / "ttyACM1"
    def collect(until, timeout=5.0):
        got = []
        t_end = time.monotonic() + timeout
        while not until(got) and time.monotonic() < t_end:
            got += a.collect()
            time.sleep(0.01)
        return got

    m, s = _plug(link)
    a = CanAdapter("vdps", f"slcan:{link},sleep_after_open=0", decoder=VdpsCanDecoder(),
                   reconnect_s=0.05)
    a.open()
    a.start_reader()
    try:
        assert a.health.reader == "process"
        os.write(m, b"".join(slcan_line(f.arbitration_id, bytes(f.data))
                             for k in range(50) for f in encode_wheel_speeds([5.0] * 4, k)))
        got = collect(lambda g: len(g) >= 100)
        assert len(a.raw_events(got)) == 100 and len(a.decode_stamped(got)) == 100
        os.close(m)
        os.close(s)
        link.unlink()
        collect(lambda g: a.health.state == "lost")
        assert a.health.state == "lost"
        m, s = _plug(link)
        collect(lambda g: a.health.state == "open")
        os.write(m, b"".join(slcan_line(f.arbitration_id, bytes(f.data))
                             for f in encode_wheel_speeds([6.0] * 4, 50)))
        got = collect(lambda g: len([x for x in g if x[2] is not None and hasattr(x[2], "data")]) >= 2)
        samples = a.decode_stamped(got)
    finally:
        a.close()
        os.close(m)
        os.close(s)
    assert len(samples) == 2 and samples[-1].fields["wheel_speed_radps_3"] == pytest.approx(6.0)
    c = a.health.all_counters()
    assert c["outages"] == 1 and c["reconnects"] == 1 and c["lost_frames"] == 0
