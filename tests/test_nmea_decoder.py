"""Tests of codecs.nmea.decoder: samples and counters of NmeaDecoder, sign overrides, the real OxTS
file through the line framer, and fuzzing with garbage and mutated sentences.
"""

from __future__ import annotations

import numpy as np
import pytest

from vdps_hil.codecs.framing import LineFramer, transmission_time_ns
from vdps_hil.codecs.nmea.attitude import format_attitude, format_hdt, format_ths
from vdps_hil.codecs.nmea.decoder import NmeaDecoder
from vdps_hil.codecs.nmea.parse import parse_sentence
from vdps_hil.codecs.nmea.position import format_rmc
from vdps_hil.codecs.nmea.sentence import REJECT_REASONS, nmea_checksum
from vdps_hil.conventions import AttitudeSign

from nmea_checks import OXTS, angle_tol_rad, mutate, valid_sentences


def test_sign_override_flips_the_printed_pitch():
    line = format_attitude("HPR", utc_time_s=1.0, yaw_rad=0.1, pitch_rad=0.05)
    flipped = AttitudeSign("HPR", -1.0, 1.0, False, "test: receiver configured nose-down")
    dec = NmeaDecoder("gnss", sign_overrides={"HPR": flipped})
    s = dec.feed_line(0, line)[0]
    assert s.fields["gnss_pitch_rad"] == pytest.approx(-0.05, abs=angle_tol_rad(2))
    with pytest.raises(ValueError):
        NmeaDecoder("gnss", sign_overrides={"XYZ": flipped})


def test_receiver_invalid_flags_give_invalid_samples():
    dec = NmeaDecoder("gnss")
    no_fix = b"$GPGGA,123519.00,,,,,0,00,99.9,,,,,,*"
    no_fix += b"%02X\r\n" % nmea_checksum(no_fix[1:-1])
    s = dec.feed_line(1, no_fix)
    assert len(s) == 1 and s[0].valid is False and s[0].fields["gnss_fix_quality"] == 0.0
    s = dec.feed_line(2, format_rmc(1.0, 1.0, 2.0, 3.0, 0.1, status="V"))
    assert s[0].valid is False
    s = dec.feed_line(3, format_ths(0.3, mode="V"))
    assert s[0].valid is False
    assert dec.counters["invalid_samples"] == 3


def test_garbage_before_dollar_is_skipped_and_counted():
    line = format_hdt(0.7)
    dec = NmeaDecoder("gnss")
    out = dec.feed_line(5, b"\x00\xff#junk" + line)
    assert len(out) == 1
    assert out[0].fields["gnss_yaw_rad"] == pytest.approx(0.7, abs=angle_tol_rad(2))
    assert dec.counters["garbage_prefix"] == 1


# ---------------------------------------------------------------------------------------------
# Golden: the real OxTS file
# ---------------------------------------------------------------------------------------------
def test_oxts_through_framer_and_decoder(real_data, rng):
    raw = (real_data / OXTS).read_bytes()
    cuts = np.sort(rng.choice(len(raw), size=60, replace=False))
    framer, dec = LineFramer(115200), NmeaDecoder("gnss")
    samples = []
    for a, b in zip([0, *cuts], [*cuts, len(raw)]):
        # each read returns when its last byte has arrived (continuous sending at 115200 baud)
        for t_line, line in framer.feed(transmission_time_ns(int(b), 115200), raw[a:b]):
            samples += dec.feed_line(t_line, line)
    c = dec.counters
    assert c["sentence_PASHR"] == 100 and c["sentence_GGA"] == 40
    assert c["sentence_RMC"] == 4 and c["sentence_HDT"] == 4
    assert c["unsupported"] == 4          # the four $GPZDA
    assert c["reject_no_start"] == 6      # the six '#' comment lines of the gpsd test file
    assert c["rejected"] == 6 and c["reject_internal_error"] == 0
    kinds = [s.kind for s in samples]
    assert kinds.count("gnss_att") == 104 and kinds.count("gnss_pos") == 40
    assert all(s.valid for s in samples)
    assert all(b.t_ns > a.t_ns for a, b in zip(samples, samples[1:]))
    # each line's time is the arrival of its own line end (+-1 ns of rounding), whatever the
    # chunking
    decoded_ends, start = [], 0
    for i, byte in enumerate(raw):
        if byte == 0x0A:
            if raw[start:i].startswith((b"$PASHR", b"$GPGGA", b"$GPRMC", b"$GPHDT")):
                decoded_ends.append(i)
            start = i + 1
    expected = [transmission_time_ns(e + 1, 115200) for e in decoded_ends]
    assert len(expected) == len(samples)
    assert max(abs(s.t_ns - e) for s, e in zip(samples, expected)) <= 1


# ---------------------------------------------------------------------------------------------
# Fuzz: garbage and mutated sentences interleaved with valid ones
# ---------------------------------------------------------------------------------------------
def test_fuzz_line_level(rng):
    valid = valid_sentences(rng, 300)
    items = [("valid", s) for s in valid]
    items += [("bad", mutate(rng, valid[int(rng.integers(len(valid)))])) for _ in range(600)]
    items += [("bad", rng.bytes(int(rng.integers(0, 120)))) for _ in range(300)]
    items += [("prefixed", rng.bytes(int(rng.integers(1, 40))).replace(b"$", b"").replace(b"!", b"")
               + valid[int(rng.integers(len(valid)))]) for _ in range(100)]
    order = rng.permutation(len(items))
    dec = NmeaDecoder("gnss")
    n_valid = 0
    for t, k in enumerate(order):
        tag, line = items[k]
        out = dec.feed_line(t, line)  # must never raise
        if tag == "bad":
            assert out == [], line
        else:
            n_valid += 1
            clean = line[max(line.rfind(b"$"), 0):]
            assert len(out) == 1 and out[0].fields == dict(parse_sentence(clean).fields)
            assert out[0].t_ns == t
    c = dec.counters
    assert c["samples"] == n_valid == 400
    assert c["rejected"] + c["unsupported"] == 900
    assert c["lines"] == c["samples"] + c["rejected"] + c["unsupported"]
    assert c["reject_internal_error"] == 0
    assert sum(c[f"reject_{r}"] for r in REJECT_REASONS if r != "unsupported") == c["rejected"]
    assert c["reject_bad_checksum"] > 100 and c["reject_missing_checksum"] > 50
    assert c["reject_not_ascii"] > 50


def test_fuzz_byte_stream_through_framer(rng):
    # Valid sentences with random garbage (any bytes, newlines included) between them, cut into
    # random chunks: every valid sentence comes out, in order, and nothing else does.
    valid = valid_sentences(rng, 400)
    stream = bytearray()
    for s in valid:
        if rng.random() < 0.5:
            stream += rng.bytes(int(rng.integers(1, 300)))
        if rng.random() < 0.2:
            stream += mutate(rng, s)
        stream += s
    stream = bytes(stream)
    cuts = np.sort(rng.choice(len(stream), size=len(stream) // 40, replace=False))
    framer, dec = LineFramer(115200, max_line_bytes=256), NmeaDecoder("gnss")
    got = []
    for k, (a, b) in enumerate(zip([0, *cuts], [*cuts, len(stream)])):
        for t_line, line in framer.feed(k * 1000, stream[a:b]):
            got += dec.feed_line(t_line, line)
    expected = [dict(parse_sentence(s).fields) for s in valid]
    assert [dict(s.fields) for s in got] == expected
    assert dec.counters["reject_internal_error"] == 0
    assert dec.counters["rejected"] > 0
