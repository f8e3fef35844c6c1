"""Tests of codecs.framing: the receive-time rule (exact arithmetic) and the line framer."""

from __future__ import annotations

from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.codecs.framing import (
    BITS_PER_BYTE_8N1, LineFramer, message_time_ns, transmission_time_ns,
)

BAUDS = (9600, 38400, 115200, 460800, 921600)


def exact_ns(n_bytes: int, baud: int) -> Fraction:
    """Wire time of n bytes in ns as an exact rational (10 bits per byte, 8N1)."""
    return Fraction(n_bytes * BITS_PER_BYTE_8N1 * 1_000_000_000, baud)


def round_half_up(x: Fraction) -> int:
    return (x.numerator * 2 + x.denominator) // (2 * x.denominator)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(n=st.integers(0, 10_000_000), baud=st.sampled_from(BAUDS))
def test_transmission_time_is_exact_rational_rounded(n, baud):
    # nearest integer nanosecond of n * 10 / baud seconds, never off by more than 0.5 ns
    t = transmission_time_ns(n, baud)
    assert t == round_half_up(exact_ns(n, baud))
    assert abs(Fraction(t) - exact_ns(n, baud)) <= Fraction(1, 2)


def test_known_byte_times():
    # one byte at 115200 baud = 10/115200 s = 86805.5(5) ns; 1000 bytes at 9600 baud = 1.0416 s
    assert transmission_time_ns(1, 115200) == 86806
    assert transmission_time_ns(1000, 9600) == 1_041_666_667
    assert message_time_ns(5_000_000_000, 0, 921600) == 5_000_000_000


def test_bad_arguments_raise():
    with pytest.raises(ValueError):
        transmission_time_ns(1, 0)
    with pytest.raises(ValueError):
        transmission_time_ns(-1, 9600)
    with pytest.raises(ValueError):
        LineFramer(0)


def test_lines_in_one_chunk_get_chunk_time_minus_bytes_after():
    baud = 115200
    chunk = b"$AAA*00\r\n$BB*11\r\npartial"
    t_chunk = 10_000_000_000
    fr = LineFramer(baud)
    out = fr.feed(t_chunk, chunk)
    assert [line for _, line in out] == [b"$AAA*00", b"$BB*11"]
    # bytes after the first '\n' (index 8): len 24 - 1 - 8 = 15; after the second (index 16): 7
    assert out[0][0] == t_chunk - round_half_up(exact_ns(15, baud))
    assert out[1][0] == t_chunk - round_half_up(exact_ns(7, baud))
    assert fr.pending_bytes == len(b"partial")


def test_line_split_across_chunks_takes_time_of_chunk_holding_its_end():
    baud = 9600
    fr = LineFramer(baud)
    assert fr.feed(1_000, b"$GPHDT,1") == []
    out = fr.feed(2_000_000_000, b"2.5,T*00\r\nXY")
    assert out == [(2_000_000_000 - round_half_up(exact_ns(2, baud)), b"$GPHDT,12.5,T*00")]


def test_empty_lines_and_bare_lf():
    fr = LineFramer(921600)
    out = fr.feed(0, b"\r\n\n$A\n$B\r\n")
    assert [line for _, line in out] == [b"$A", b"$B"]
    assert fr.counters["empty_lines"] == 2
    assert fr.counters["lines"] == 2


@settings(max_examples=60, deadline=None, derandomize=True)
@given(lines=st.lists(st.binary(min_size=1, max_size=60).filter(lambda b: b"\n" not in b
                                                                and not b.endswith(b"\r")),
                      min_size=1, max_size=20),
       cuts=st.lists(st.integers(0, 2000), max_size=30),
       baud=st.sampled_from(BAUDS))
def test_any_chunking_gives_same_lines_and_exact_times(lines, cuts, baud):
    # A device sends the lines back to back; the host reads at arbitrary byte boundaries and
    # stamps each read with the arrival time of its last byte. The rule must give each line the
    # arrival time of its '\n' byte (to the nearest ns), whatever the chunking.
    stream = b"".join(line + b"\r\n" for line in lines)
    t0 = Fraction(123_456_789)
    arrival = [t0 + exact_ns(k + 1, baud) for k in range(len(stream))]  # byte k fully received
    bounds = sorted({0, len(stream), *[c % (len(stream) + 1) for c in cuts]})
    fr = LineFramer(baud, max_line_bytes=4096)
    got = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if a == b:
            continue
        t_chunk = round_half_up(arrival[b - 1])
        got += fr.feed(t_chunk, stream[a:b])
    assert [line for _, line in got] == lines
    nl_positions = [i for i, byte in enumerate(stream) if byte == 0x0A]
    for (t_line, _), pos in zip(got, nl_positions):
        # the chunk time carries <= 0.5 ns rounding, the wire time another <= 0.5 ns
        assert abs(Fraction(t_line) - arrival[pos]) <= 1


def test_overlong_garbage_is_dropped_and_counted_not_accumulated():
    fr = LineFramer(115200, max_line_bytes=100)
    for k in range(50):
        assert fr.feed(k, b"\x00\x01garbage" * 20) == []
        assert fr.pending_bytes <= 100
    assert fr.counters["overflows"] >= 50
    assert fr.counters["overflow_dropped_bytes"] >= 50 * 180 - 100
    out = fr.feed(99, b"\r\n$GPHDT,1.0,T*00\r\n")
    assert out[-1][1] == b"$GPHDT,1.0,T*00"


def test_sentence_after_overlong_garbage_without_newline_is_kept():
    # garbage with no line end, then a sentence: the tail from the last '$' survives the guard
    fr = LineFramer(115200, max_line_bytes=64)
    sentence = b"$GPHDT,25.50,T*37"
    out = fr.feed(0, b"x" * 500)
    out += fr.feed(1, b"y" * 300 + sentence + b"\r\n")
    assert [line for _, line in out] == [sentence]
    assert fr.counters["overflows"] >= 1


def test_flush_returns_partial_line():
    fr = LineFramer(9600)
    fr.feed(0, b"$GPGGA,12")
    assert fr.flush() == b"$GPGGA,12"
    assert fr.pending_bytes == 0
