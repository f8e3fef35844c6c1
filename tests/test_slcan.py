"""adapters.slcan.SlcanLines: slcan receive lines of every frame kind parsed from byte chunks
cut anywhere; error replies, acknowledgements and malformed lines counted, never raised."""

from vdps_hil.adapters.health import SourceHealth
from vdps_hil.adapters.slcan import SlcanLines, slcan_line


def _frames(rng, n):
    out = []
    for _ in range(n):
        ext = bool(rng.random() < 0.3)
        aid = int(rng.integers(0, 1 << 29 if ext else 1 << 11))
        data = rng.integers(0, 256, int(rng.integers(0, 9)), dtype="uint8").tobytes()
        out.append((aid, data, ext))
    return out


def test_frames_survive_any_chunking(rng):
    frames = _frames(rng, 300)
    stream = b"".join(slcan_line(a, d, e) for a, d, e in frames)
    p = SlcanLines(SourceHealth("can.x", "can", "pty"))
    got, i = [], 0
    while i < len(stream):
        k = int(rng.integers(1, 60))
        got += p.feed(i, stream[i:i + k], 1.5)
        i += k
    assert [(m.arbitration_id, bytes(m.data), m.is_extended_id) for _, m in got] == frames
    assert all(m.timestamp == 1.5 and m.dlc == len(m.data) for _, m in got)


def test_remote_fd_frames_and_replies():
    h = SourceHealth("can.x", "can", "pty")
    p = SlcanLines(h)
    got = p.feed(7, b"r1234\rR000001002\rd123A" + b"11" * 16 + b"\rb0019" + b"22" * 12 +
                 b"\rz\rZ\r\r\x07", 0.0)
    kinds = [(m.arbitration_id, m.is_remote_frame, m.is_extended_id, m.is_fd,
              m.bitrate_switch, m.dlc) for _, m in got]
    assert kinds == [(0x123, True, False, False, False, 4), (0x100, True, True, False, False, 2),
                     (0x123, False, False, True, False, 16), (0x001, False, False, True, True, 12)]
    assert all(t == 7 for t, _ in got)
    assert h.counters == {"slcan_errors": 1}  # z/Z (acks) and empty replies are not errors


def test_malformed_lines_are_counted_and_the_rest_kept():
    h = SourceHealth("can.x", "can", "pty")
    p = SlcanLines(h)
    good = slcan_line(0x100, b"\x01\x02")
    got = p.feed(1, b"tZZZ8GARBAGE!!\r\xff\xfe\r" + good + b"t1009" + b"00" * 9 + b"\rt10031\r"
                 + b"q\r" + good, 0.0)
    assert len(got) == 2 and h.counters["bad_frames"] == 5
    assert "bad slcan line" in h.last_error


def test_partial_line_waits_and_reset_forgets_it():
    p = SlcanLines(SourceHealth("can.x", "can", "pty"))
    line = slcan_line(0x321, b"\xaa")
    assert p.feed(1, line[:5], 0.0) == []
    assert [m.arbitration_id for _, m in p.feed(2, line[5:], 0.0)] == [0x321]
    assert p.feed(3, line[:5], 0.0) == []
    p.reset()  # the device was lost: the half line is not glued to what comes next
    assert [m.arbitration_id for _, m in p.feed(4, line, 0.0)] == [0x321]
