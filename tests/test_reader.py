"""RecordingReader: round trips of every schema, t_ns merge across topics, topic selection,
metadata, broken files, and agreement with mcap's own reader."""

import io
import json
import math
from collections import defaultdict

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from vdps_hil.bus.samples import FIELDS, Sample
from vdps_hil.record import schemas as S
from vdps_hil.record.reader import RecordingError, RecordingReader, damage_note, scan_damage
from vdps_hil.record.writer import RecordingWriter

EPOCH = S.DEFAULT_SIM_EPOCH_NS
PROP = settings(max_examples=60, deadline=None)


def _roundtrip(write, **kw):
    """Write with ``write(w)`` into memory and return a reader over the bytes."""
    buf = io.BytesIO()
    with RecordingWriter(buf, sim_epoch_ns=EPOCH, **kw) as w:
        write(w)
    return RecordingReader(io.BytesIO(buf.getvalue()))


@st.composite
def can_messages(draw):
    ext, fd = draw(st.booleans()), draw(st.booleans())
    if fd:
        n = draw(st.sampled_from([0, 1, 5, 8, 12, 16, 20, 24, 32, 48, 64]))
        data, dlc = draw(st.binary(min_size=n, max_size=n)), n
    else:
        data = draw(st.binary(max_size=8))
        dlc = draw(st.one_of(st.just(len(data)), st.integers(0, 15)))  # remote/odd DLCs too
    return can.Message(arbitration_id=draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF)),
                       is_extended_id=ext, is_fd=fd, is_remote_frame=not fd and draw(st.booleans()),
                       is_error_frame=draw(st.booleans()), data=data, dlc=dlc,
                       is_rx=draw(st.booleans()), bitrate_switch=fd and draw(st.booleans()),
                       error_state_indicator=fd and draw(st.booleans()), check=False)


@PROP
@given(frames=st.lists(st.tuples(st.sampled_from(["chassis", "pt", "can.fd"]), can_messages()),
                       min_size=1, max_size=30),
       t0=st.integers(0, 2**62))
def test_raw_can_round_trip(frames, t0):
    r = _roundtrip(lambda w: [w.write_can(bus, t0 + i, m) for i, (bus, m) in enumerate(frames)])
    got = list(r.iter_raw_can())
    assert len(got) == len(frames)
    for i, ((bus, m), (gbus, g)) in enumerate(zip(frames, got)):
        assert gbus == bus == g.channel
        assert g.timestamp == (t0 + i) / 1e9
        for attr in ("arbitration_id", "is_extended_id", "is_fd", "is_remote_frame",
                     "is_error_frame", "dlc", "is_rx", "bitrate_switch", "error_state_indicator"):
            assert getattr(g, attr) == getattr(m, attr), attr
        assert bytes(g.data) == bytes(m.data)
    assert [b for b, _ in r.iter_raw_can(bus="pt")] == [b for b, _ in frames if b == "pt"]


@PROP
@given(chunks=st.lists(st.binary(max_size=300), min_size=1, max_size=20),
       baud=st.sampled_from([9600, 115200, 921600]))
def test_raw_serial_round_trip(chunks, baud):
    def write(w):
        for i, c in enumerate(chunks):
            w.write_serial("gnss" if i % 3 else "imu", 1000 * i, c, baud=baud, fmt="nmea")
    r = _roundtrip(write)
    assert list(r.iter_raw_serial()) == [("gnss" if i % 3 else "imu", 1000 * i, c)
                                         for i, c in enumerate(chunks)]
    assert [c for _, _, c in r.iter_raw_serial("imu")] == chunks[::3]
    assert r.serial_config("imu") == (baud, "nmea")


field_names = st.sampled_from(sorted(FIELDS))
field_values = st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.just(math.nan))


@PROP
@given(samples=st.lists(st.tuples(st.sampled_from(["gnss", "imu", "can.vdps"]),
                                  st.sampled_from(["gnss_pos", "imu", "wheel_speed"]),
                                  st.dictionaries(field_names, field_values, max_size=8),
                                  st.booleans(), st.integers(0, 2**62)),
                        min_size=1, max_size=15))
def test_samples_round_trip_with_nan_fields(samples):
    made = [Sample(10 * i, src, kind, fields, wall_time_ns=wall, valid=valid)
            for i, (src, kind, fields, valid, wall) in enumerate(samples)]
    r = _roundtrip(lambda w: [w.write_sample(s) for s in made])
    got = list(r.iter_samples())
    assert len(got) == len(made)
    for a, b in zip(made, got):
        assert (a.t_ns, a.source, a.kind, a.valid, a.wall_time_ns) == \
               (b.t_ns, b.source, b.kind, b.valid, b.wall_time_ns)
        assert a.fields.keys() == b.fields.keys()
        for k, v in a.fields.items():
            assert (math.isnan(v) and math.isnan(b.fields[k])) or v == b.fields[k]
    assert set(r.topics()) == {S.sample_topic(s.source, s.kind) for s in made}


@PROP
@given(values=st.dictionaries(st.sampled_from(["x_m", "y_m", "roll_rad", "ltr"]),
                              st.floats(allow_nan=False, allow_infinity=False), min_size=1),
       sig=st.floats(min_value=0, max_value=1e3))
def test_truth_estimate_location_fix_round_trip(values, sig):
    fix = Sample(7, "gnss", "gnss_pos", {"gnss_lat_deg": 10.0, "gnss_lon_deg": 20.0,
                                         "gnss_pos_sigma_h_m": sig})

    def write(w):
        w.write_truth("state", 5, values)
        w.write_estimate("ekf", 6, values, {k: sig for k in values})
        w.write_location_fix(fix)
    msgs = list(_roundtrip(write).iter_messages())
    assert msgs[0] == ("/truth/state", 5, {"t_ns": 5, "values": values})
    assert msgs[1] == ("/est/ekf", 6, {"t_ns": 6, "values": values,
                                        "sigmas": {k: sig for k in values}})
    assert msgs[2] == ("/gnss/fix", 7, S.location_fix_doc(fix, stamp_ns=EPOCH + 7))


def _interleaved_recording(rng, n_sources=5, lag=40, wall_step_back=False):
    """Sources with their own rates and jitter, written in bursts of up to ``lag`` messages per
    source (as a logger with per-source queues does). Returns (bytes, expected (topic, t))."""
    streams = []
    for k in range(n_sources):
        dt = int(rng.integers(1_000_000, 20_000_000))
        n = int(rng.integers(50, 300))
        t = np.cumsum(rng.integers(dt // 2, dt * 3 // 2, n)) + int(rng.integers(0, dt))
        t[rng.random(n) < 0.1] -= dt // 2  # jitter; ties and equal times across sources
        streams.append((f"s{k}", [int(x) for x in np.maximum.accumulate(t)]))
    buf = io.BytesIO()
    pos = [0] * n_sources
    with RecordingWriter(buf, sim_epoch_ns=EPOCH, chunk_size=2048) as w:
        while any(pos[k] < len(s[1]) for k, s in enumerate(streams)):
            k = int(rng.integers(0, n_sources))
            name, ts = streams[k]
            burst = int(rng.integers(1, lag))
            for t in ts[pos[k]:pos[k] + burst]:
                wall = EPOCH + t - (10**12 if wall_step_back and k == 0 else 0)
                w.write_serial(name, t, name.encode(), wall_time_ns=wall)
            pos[k] += burst
    expected = sorted(((f"/raw/serial/{n}", t) for n, ts in streams for t in ts),
                      key=lambda x: x[1])
    return buf.getvalue(), expected


def test_merge_orders_by_t_ns_across_topics(rng):
    data, expected = _interleaved_recording(rng)
    r = RecordingReader(io.BytesIO(data))
    got = [(topic, t) for topic, t, _ in r.iter_messages()]
    assert [t for _, t in got] == sorted(t for _, t in got)
    assert sorted(got) == sorted(expected)
    # ties broken by file order: each topic's own sequence is kept
    per = defaultdict(list)
    for topic, t in got:
        per[topic].append(t)
    for topic, ts in per.items():
        assert ts == sorted(ts)


def test_order_is_t_ns_not_log_time_when_wall_clock_steps(rng):
    """One source's wall clock is 1000 s behind: mcap's log-time order puts it first, ours
    stays in measurement order."""
    data, expected = _interleaved_recording(rng, wall_step_back=True)
    ours = [t for _, t, _ in RecordingReader(io.BytesIO(data)).iter_messages()]
    assert ours == sorted(t for _, t in expected)
    theirs = [m.publish_time for _, _, m in make_reader(io.BytesIO(data)).iter_messages()]
    assert sorted(theirs) == ours and theirs != ours


def test_prefix_selection_never_reads_truth_chunks():
    """Truth written in chunks of its own and then destroyed: reading /raw/ does not notice."""
    buf = io.BytesIO()
    with RecordingWriter(buf, sim_epoch_ns=EPOCH, chunk_size=1024) as w:
        for i in range(200):
            w.write_serial("imu", i, b"\x01\x02")
        w.flush()
        truth_start = buf.tell()
        for i in range(200):
            w.write_truth("state", i, {"roll_rad": 0.001 * i})
        w.flush()
        truth_end = buf.tell()
        for i in range(200, 400):
            w.write_serial("imu", i, b"\x03")
    data = bytearray(buf.getvalue())
    data[truth_start + 100:truth_end - 100] = b"\xff" * (truth_end - truth_start - 200)
    r = RecordingReader(io.BytesIO(bytes(data)))
    raw = list(r.iter_messages(prefixes=("/raw/",)))
    assert [t for _, t, _ in raw] == list(range(400))
    assert r.problems == []
    everything = list(r.iter_messages())  # now truth chunks are read: damage noted, raw kept
    assert r.problems and all("unreadable" in p for p in r.problems)
    n_problems = len(r.problems)
    list(r.iter_messages())
    assert len(r.problems) == n_problems  # noted once, not once per pass
    assert sum(1 for m in everything if m[0].startswith("/raw/")) == 400
    assert not any(m[0].startswith(S.TRUTH_PREFIX) for m in r.iter_messages(prefixes="/raw/"))


def test_topics_metadata_and_selection():
    def write(w):
        w.write_can("a", 1, {"arbitration_id": 5, "data": b"\x01"})
        w.write_can("b", 2, {"arbitration_id": 6, "data": b"\x02"})
        w.write_truth("state", 3, {"x_m": 1.0})
        w.add_metadata("vdps.extra", {"k": "v"})
    r = _roundtrip(write, metadata={"run": "r1"}, content_hashes={"dbc": b"x"})
    assert r.topics() == {"/raw/can/a": (S.RAW_CAN, 1), "/raw/can/b": (S.RAW_CAN, 1),
                          "/truth/state": (S.TRUTH, 1)}
    md = r.metadata()
    assert md[S.METADATA_NAME]["run"] == "r1"
    assert md[S.METADATA_NAME]["hash.dbc"] == S.content_hash(b"x")
    assert md["vdps.extra"] == {"k": "v"}
    assert r.layout_version == S.LAYOUT_VERSION
    assert [m[0] for m in r.iter_messages(["/raw/can/b", "/truth/state"])] == \
        ["/raw/can/b", "/truth/state"]
    assert [m[0] for m in r.iter_messages(prefixes="/raw/can/")] == ["/raw/can/a", "/raw/can/b"]
    assert r.channel_metadata("/raw/can/a") == {"bus": "a"}
    assert list(r.iter_messages(prefixes="/nothing/")) == []


def test_independent_reader_sees_the_same_messages(tmp_path, rng):
    path = tmp_path / "all.mcap"
    with RecordingWriter(path, sim_epoch_ns=EPOCH, chunk_size=4096) as w:
        for i in range(400):
            t = i * 2_500_000
            w.write_can("chassis", t, can.Message(arbitration_id=0x100 + i % 3,
                                                   data=rng.integers(0, 256, 8, "u1").tobytes()))
            if i % 4 == 0:
                w.write_serial("gnss", t + 7, b"$GPGGA,1*00\r\n", baud=115200, fmt="nmea")
                s = Sample(t + 9, "gnss", "gnss_pos",
                           {"gnss_lat_deg": 24.0 + 1e-6 * i, "gnss_lon_deg": 121.0,
                            "gnss_alt_m": math.nan})
                w.write_sample(s)
                w.write_location_fix(s)
                w.write_truth("state", t + 3, {"roll_rad": 0.01 * i})
                w.write_estimate("ekf", t + 11, {"roll_rad": 0.01 * i}, {"roll_rad": 0.1})
    ours = list(RecordingReader(path).iter_messages())
    with open(path, "rb") as f:
        reader = make_reader(f)
        theirs = [(ch.topic, m.publish_time, json.loads(m.data), sc.name, sc.encoding,
                   ch.message_encoding, m.log_time)
                  for sc, ch, m in reader.iter_messages(log_time_order=True)]
    assert {x[3] for x in theirs} == {S.RAW_CAN, S.RAW_SERIAL, S.SAMPLE, S.LOCATION_FIX,
                                      S.TRUTH, S.ESTIMATE}
    assert {(x[4], x[5]) for x in theirs} == {("jsonschema", "json")}
    assert all(x[6] == EPOCH + x[1] for x in theirs)  # simulation: log_time = epoch + t_ns
    # same messages; with log_time = epoch + t_ns, also the same order
    assert [(a, b, c) for a, b, c, *_ in theirs] == ours


@pytest.mark.parametrize("content", [b"", b"garbage" * 50, b"\x89MCAP0\r\n" + bytes(range(256)) * 4,
                                     b"\x89MCAP0\r\n"])
def test_garbage_never_raises_anything_but_recording_error(tmp_path, content):
    p = tmp_path / "bad.mcap"
    p.write_bytes(content)
    try:
        r = RecordingReader(p)
    except RecordingError as e:
        assert "\n" not in str(e)
        return
    assert r.truncated and r.problems
    assert list(r.iter_messages()) == []


def test_damage_note_counts_problems_but_not_a_missing_summary_alone(tmp_path, rng):
    p = tmp_path / "d.mcap"
    with RecordingWriter(p, sim_epoch_ns=EPOCH) as w:
        for i in range(2000):
            w.write_can("vdps", i * 1_000_000, can.Message(arbitration_id=0x100 + i % 7, is_extended_id=False,
                                                           data=bytes(rng.integers(0, 256, 8).tolist())))
    good = p.read_bytes()
    assert scan_damage(p) == [] and damage_note([], p) == ""
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good[: len(good) * 2 // 3])  # no summary, and a record cut in half
    problems = scan_damage(cut)
    note = damage_note(problems, cut)
    assert problems and note.startswith(" (the recording is damaged: ") and f"`vdps info {cut}`" in note
    assert damage_note(["no summary (cut off by a crash?): read by scanning"], cut) == ""
    assert "2 problems" in damage_note(["a", "b"], cut)
    assert scan_damage(tmp_path / "nope.mcap") == []


def test_missing_file_is_one_line_error(tmp_path):
    with pytest.raises(RecordingError, match="cannot open"):
        RecordingReader(tmp_path / "nope.mcap")
