"""RecordingWriter: channels, time stamps, chunking/compression and metadata, checked with the
mcap library's own readers (not ours)."""

import io
import json
import math

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from vdps_hil import __version__
from vdps_hil.bus.samples import Sample
from vdps_hil.record import schemas as S
from vdps_hil.record.payloads import estimate_payload, json_payload
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.writer import RecordingWriter

from copy_messages import copy_messages

EPOCH = S.DEFAULT_SIM_EPOCH_NS


def _mcap_messages(source):
    """(topic, schema name, log_time, publish_time, sequence, doc) via mcap + plain json."""
    f = open(source, "rb") if not isinstance(source, (bytes, bytearray)) else io.BytesIO(source)
    with f:
        return [(ch.topic, sc.name, m.log_time, m.publish_time, m.sequence, json.loads(m.data))
                for sc, ch, m in make_reader(f).iter_messages(log_time_order=False)]


def _chunks(path):
    with open(path, "rb") as f:
        return [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]


def test_chunks_are_zstd_and_about_chunk_size(tmp_path, rng):
    path = tmp_path / "c.mcap"
    with RecordingWriter(path, sim_epoch_ns=EPOCH) as w:
        for i in range(6000):
            data = rng.integers(0, 256, 8, dtype="u1").tobytes()
            w.write_can("chassis", i * 1_000_000, {"arbitration_id": 0x100 + i % 4, "data": data})
    chunks = _chunks(path)
    assert len(chunks) >= 5
    assert {c.compression for c in chunks} == {"zstd"}
    one_msg = 400  # upper bound of one encoded raw CAN message record incl. index [bytes]
    for c in chunks[:-1]:  # every closed chunk is just over 64 KiB uncompressed
        assert 65536 < c.uncompressed_size <= 65536 + one_msg
        assert len(c.data) < c.uncompressed_size / 2  # JSON frames compress well


def test_time_stamps_log_time_wall_and_publish_time_t_ns(tmp_path):
    path = tmp_path / "t.mcap"
    with RecordingWriter(path, sim_epoch_ns=EPOCH) as w:
        w.write_can("a", 10, {"arbitration_id": 1, "data": b""})
        w.write_can("a", 20, {"arbitration_id": 1, "data": b""}, wall_time_ns=1_700_000_000 * 10**9)
        w.write_sample(Sample(30, "imu", "imu", {"angular_rate_radps_z": 0.5}, wall_time_ns=77))
        w.write_truth("state", 40, {"roll_rad": 0.01})
    msgs = _mcap_messages(path)
    assert [(m[2], m[3]) for m in msgs] == [(EPOCH + 10, 10), (1_700_000_000 * 10**9, 20),
                                            (77, 30), (EPOCH + 40, 40)]
    assert all(m[5]["t_ns"] == m[3] for m in msgs)


def test_live_writer_without_wall_time_uses_the_clock(tmp_path):
    import time
    path = tmp_path / "live.mcap"
    before = time.time_ns()
    with RecordingWriter(path) as w:
        w.write_serial("gnss", 5, b"$GPGGA\r\n", baud=115200, fmt="nmea")
        assert w.metadata["log_time"] == "wall_time_ns"
    (m,) = _mcap_messages(path)
    assert before <= m[2] <= time.time_ns()
    assert m[3] == 5


def test_channels_and_schemas_registered_once(tmp_path):
    path = tmp_path / "ch.mcap"
    with RecordingWriter(path, sim_epoch_ns=EPOCH) as w:
        for i in range(300):
            w.write_can("a", i, {"arbitration_id": 1, "data": b"\x00"})
            w.write_can("b", i, {"arbitration_id": 2, "data": b"\x00"})
            w.write_serial("imu", i, b"\xfa\x01", baud=921600, fmt="vn-binary")
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    topics = sorted(c.topic for c in summary.channels.values())
    assert topics == ["/raw/can/a", "/raw/can/b", "/raw/serial/imu"]
    assert sorted(s.name for s in summary.schemas.values()) == [S.RAW_CAN, S.RAW_SERIAL]
    assert {s.encoding for s in summary.schemas.values()} == {"jsonschema"}
    assert {c.message_encoding for c in summary.channels.values()} == {"json"}
    serial = next(c for c in summary.channels.values() if c.topic == "/raw/serial/imu")
    assert serial.metadata == {"device": "imu", "baud": "921600", "format": "vn-binary"}
    assert summary.statistics.message_count == 900
    seqs = [m[4] for m in _mcap_messages(path) if m[0] == "/raw/can/a"]
    assert seqs == list(range(300))


def test_metadata_record_carries_provenance(tmp_path):
    path = tmp_path / "m.mcap"
    cfg = tmp_path / "bench.toml"
    cfg.write_bytes(b"[can]\nbus = 'vdps'\n")
    with RecordingWriter(path, metadata={"scenario": "fishhook", "seed": 3},
                         content_hashes={"config": cfg, "dbc.vdps": b"VERSION \"\"\n"}) as w:
        w.add_metadata("vdps.counters", {"drops": 0})
    with open(path, "rb") as f:
        md = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    rec = md[S.METADATA_NAME]
    assert rec["layout_version"] == S.LAYOUT_VERSION
    assert rec["tool_version"] == __version__
    assert rec["scenario"] == "fishhook" and rec["seed"] == "3"
    assert rec["hash.config"] == S.content_hash(cfg.read_bytes())
    assert rec["hash.dbc.vdps"] == S.content_hash(b"VERSION \"\"\n")
    assert md["vdps.counters"] == {"drops": "0"}
    with pytest.raises(ValueError):
        RecordingWriter(tmp_path / "x.mcap", metadata={"layout_version": "9"})


def test_topic_keeps_its_schema_and_serial_settings(tmp_path):
    with RecordingWriter(tmp_path / "s.mcap", sim_epoch_ns=EPOCH) as w:
        w.write_truth("/truth/state", 0, {"x_m": 0.0})
        with pytest.raises(ValueError):
            w.write_json("/truth/state", S.ESTIMATE, 1, {"values": {}})
        w.write_serial("gnss", 0, b"a", baud=115200, fmt="nmea")
        w.write_serial("gnss", 1, b"b")  # later chunks may omit the settings
        with pytest.raises(ValueError):
            w.write_serial("gnss", 2, b"c", baud=9600)
        with pytest.raises(KeyError):
            w.write_json("/x/y", "vdps.Unknown.v1", 0, {})
        with pytest.raises(ValueError):
            w.write_json("/x/y", S.TRUTH, 5, {"t_ns": 6, "values": {}})
        with pytest.raises(ValueError):
            w.write_truth("/est/x", 0, {})
        with pytest.raises(ValueError):
            w.write_estimate("/truth/x", 0, {})
        with pytest.raises(ValueError):
            w.write_can("bad bus", 0, {"arbitration_id": 1, "data": b""})
        with pytest.raises(TypeError):
            w.write_can("a", 1.0, {"arbitration_id": 1, "data": b""})


def test_time_going_backwards_is_counted_and_kept(tmp_path):
    path = tmp_path / "b.mcap"
    with RecordingWriter(path, sim_epoch_ns=EPOCH) as w:
        for t in (10, 20, 15, 30):
            w.write_serial("gnss", t, b"x")
        assert w.stats.time_backwards == {"/raw/serial/gnss": 1}
        assert w.stats.messages == {"/raw/serial/gnss": 4}
    assert [m[3] for m in _mcap_messages(path)] == [10, 20, 15, 30]


def test_truth_and_estimate_topics(tmp_path):
    path = tmp_path / "e.mcap"
    with RecordingWriter(path, sim_epoch_ns=EPOCH) as w:
        w.write_truth("events", 5, {"event": "wheel_lift", "wheel": 3})
        w.write_estimate("ekf", 6, {"roll_rad": 0.1, "mass_kg": math.nan}, {"roll_rad": 0.01})
    msgs = _mcap_messages(path)
    assert msgs[0][:2] == ("/truth/events", S.TRUTH)
    assert msgs[0][5] == {"t_ns": 5, "values": {"event": "wheel_lift", "wheel": 3}}
    assert msgs[1][:2] == ("/est/ekf", S.ESTIMATE)
    assert msgs[1][5] == {"t_ns": 6, "values": {"roll_rad": 0.1, "mass_kg": None},
                          "sigmas": {"roll_rad": 0.01}}


def test_location_fix_topic_and_skip_count(tmp_path):
    path = tmp_path / "g.mcap"
    fix = Sample(2_000_000_000, "gnss", "gnss_pos",
                 {"gnss_lat_deg": 24.8, "gnss_lon_deg": 121.0, "gnss_alt_m": 50.0,
                  "gnss_pos_sigma_h_m": 0.5, "gnss_pos_sigma_v_m": 1.0})
    with RecordingWriter(path, sim_epoch_ns=EPOCH) as w:
        assert w.write_location_fix(fix)
        assert not w.write_location_fix(Sample(3, "gnss", "gnss_pos", {"gnss_lat_deg": math.nan}))
        assert w.stats.location_fix_skipped == 1
    ((topic, schema, log_time, pub, _, doc),) = _mcap_messages(path)
    assert (topic, schema, pub) == ("/gnss/fix", "foxglove.LocationFix", fix.t_ns)
    stamp = doc["timestamp"]["sec"] * 10**9 + doc["timestamp"]["nsec"]
    assert stamp == log_time == EPOCH + fix.t_ns
    assert S.validate(doc, S.SCHEMAS[S.LOCATION_FIX]) == []
    assert "t_ns" not in doc  # Foxglove's schema has no t_ns; publish_time carries it


@st.composite
def messages(draw):
    ext, fd = draw(st.booleans()), draw(st.booleans())
    data = draw(st.binary(max_size=64 if fd else 8))
    return can.Message(arbitration_id=draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF)),
                       is_extended_id=ext, is_fd=fd, is_remote_frame=draw(st.booleans()),
                       is_error_frame=draw(st.booleans()), data=data,
                       dlc=draw(st.integers(0, 64)), is_rx=draw(st.booleans()),
                       bitrate_switch=fd and draw(st.booleans()),
                       error_state_indicator=fd and draw(st.booleans()), check=False)


@settings(max_examples=60, deadline=None)
@given(msg=messages(), t_ns=st.integers(0, S.MAX_TIME_NS))
def test_can_message_fast_path_equals_the_documented_doc(msg, t_ns):
    buf = io.BytesIO()
    with RecordingWriter(buf, sim_epoch_ns=0) as w:
        w.write_can("a", t_ns, msg)
    ((_, _, _, _, _, doc),) = _mcap_messages(buf.getvalue())
    expected = S.raw_can_doc(t_ns, msg.arbitration_id, msg.data, is_extended_id=msg.is_extended_id,
                             is_fd=msg.is_fd, is_remote_frame=msg.is_remote_frame,
                             is_error_frame=msg.is_error_frame, dlc=msg.dlc,
                             direction="rx" if msg.is_rx else "tx",
                             bitrate_switch=msg.bitrate_switch,
                             error_state_indicator=msg.error_state_indicator)
    assert doc == expected


def test_flush_makes_written_data_durable_before_close(tmp_path):
    from vdps_hil.record.reader import RecordingReader
    path = tmp_path / "live.mcap"
    w = RecordingWriter(path, sim_epoch_ns=EPOCH)
    for i in range(50):
        w.write_serial("imu", i, bytes([i]))
    w.flush()
    w.write_serial("imu", 50, b"unflushed")  # still in the open chunk
    snapshot = path.read_bytes()  # what a crash right now would leave
    w.close()
    (tmp_path / "crash.mcap").write_bytes(snapshot)
    r = RecordingReader(tmp_path / "crash.mcap")
    assert r.truncated
    assert [t for _, t, _ in r.iter_raw_serial()] == list(range(50))
    assert r.metadata()[S.METADATA_NAME]["layout_version"] == S.LAYOUT_VERSION


def test_close_is_idempotent_and_exceptions_still_close(tmp_path):
    path = tmp_path / "x.mcap"
    with pytest.raises(RuntimeError):
        with RecordingWriter(path, sim_epoch_ns=EPOCH) as w:
            w.write_serial("gnss", 1, b"x")
            raise RuntimeError("boom")
    assert w.closed
    w.close()
    with pytest.raises(ValueError):
        w.write_serial("gnss", 2, b"y")
    assert len(_mcap_messages(path)) == 1  # a complete, indexed file
    with open(path, "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == 1


def test_copied_messages_read_back_equal_with_valid_indexes_and_statistics(tmp_path):
    """Copies (queued, written in runs) next to direct writes: the mcap library reads the
    same messages through the summary's chunk and message indexes as _write gives, with the same
    statistics and per-topic sequence numbers; our reader agrees (small chunks so many close)."""
    msgs = copy_messages(3, 3000)
    paths = {}
    for how in ("copy", "write"):
        p = paths[how] = tmp_path / f"{how}.mcap"
        with RecordingWriter(p, chunk_size=2048, sim_epoch_ns=EPOCH) as w:
            copy = w.copier(lambda topic: (S.RAW_SERIAL, {"device": topic[-1], "baud": "", "format": ""}))
            for k, (topic, t, log, data) in enumerate(msgs):
                if how == "copy":
                    copy((topic, t, log, 0, data))
                else:
                    w._write(topic, S.RAW_SERIAL, t, data, log, {"device": topic[-1], "baud": "", "format": ""})
                if k % 97 == 0:
                    w.write_estimate("x", k, {"v": float(k)})
        assert w.stats.total == 3000 + 31 and not w.stats.time_backwards
    got = {}
    for how, p in paths.items():
        with open(p, "rb") as f:
            r = make_reader(f)
            summary = r.get_summary()
            assert summary.statistics.message_count == 3031
            counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
            got[how] = (counts, sorted((ch.topic, m.sequence, m.log_time, m.publish_time, m.data)
                                       for _, ch, m in r.iter_messages(log_time_order=True)))
        assert len(summary.chunk_indexes) > 20
    assert got["copy"] == got["write"]
    with RecordingReader(paths["copy"]) as r:
        mine = [(x.topic, x.t_ns, x.log_time_ns, x.data) for x in r.iter_records(prefixes="/raw/")]
    assert not r.problems and sorted(mine) == sorted(msgs)


def test_copy_keeps_per_topic_order_sequence_wrap_and_time_rules(tmp_path):
    """A direct write on a copied topic comes after the copies queued before it; sequence
    numbers wrap modulo 2^32 inside a run; log time 0 takes the writer's rule; backwards t_ns
    are counted; topics the channel function refuses are not copied; an out-of-range log time
    and a schema clash are errors at the call."""
    p = tmp_path / "c.mcap"
    a = "/raw/serial/a"
    with RecordingWriter(p, sim_epoch_ns=EPOCH) as w:
        copy = w.copier(lambda topic: (S.RAW_SERIAL, {}) if topic == a else None)
        copy((a, 1, 0, 9, b"1"))
        copy(("/raw/other", 1, 0, 9, b"x"))  # not copied
        w.flush()  # written: the next sequence number can be set
        w._channels[a].seq = 2**32 - 2
        for t, log, data in ((2, EPOCH + 7, b"2"), (3, EPOCH + 8, b"3"), (2, EPOCH + 9, b"4")):  # 4: backwards
            copy((a, t, log, 0, data))
        w._write(a, S.RAW_SERIAL, 5, b"5", None)
        with pytest.raises(ValueError, match="out of range"):
            copy((a, 6, 2**64 - 1, 0, b"6"))
        w.write_json("/raw/serial/b", S.TRUTH, 1, {"t_ns": 1})
        with pytest.raises(ValueError, match="already carries"):
            w.copier(lambda topic: (S.RAW_SERIAL, {}))(("/raw/serial/b", 2, 0, 0, b"7"))
    assert w.stats.messages == {a: 5, "/raw/serial/b": 1} and w.stats.time_backwards == {a: 1}
    with open(p, "rb") as f:
        got = [(m.data, m.sequence, m.log_time, m.publish_time) for _, ch, m in
               make_reader(f).iter_messages(log_time_order=False) if ch.topic == a]
    assert got == [(b"1", 0, EPOCH + 1, 1), (b"2", 2**32 - 2, EPOCH + 7, 2), (b"3", 2**32 - 1, EPOCH + 8, 3),
                   (b"4", 0, EPOCH + 9, 2), (b"5", 1, EPOCH + 5, 5)]


def test_messages_encoded_elsewhere_are_written_as_write_json_and_write_estimate_write_them(tmp_path):
    """``vdps replay --jobs 2`` encodes in one process (``json_payload``, ``estimate_payload``)
    and writes in the other (``write_encoded``): the same messages as the direct calls, incl.
    NaN -> null; ``write_encoded`` checks topic, schema, time and payload type."""
    vals = {"a": 1.5, "b": math.nan, "c": -0.0}
    sig = {"a": 0.25, "b": 1e-300, "c": math.inf}
    doc = S.raw_can_doc(1_000, 0x123, b"\x01\x02", direction="tx")
    with RecordingWriter(tmp_path / "direct.mcap", sim_epoch_ns=0) as w:
        w.write_estimate("state", 1_000, vals, sig)
        w.write_estimate("/est/plain", 2_000, {"x": 3.0})
        w.write_json("/est/can/vdps", S.RAW_CAN, 1_000, doc, channel_metadata={"bus": "vdps"})
    with RecordingWriter(tmp_path / "encoded.mcap", sim_epoch_ns=0) as w:
        w.write_encoded("/est/state", S.ESTIMATE, 1_000, estimate_payload(1_000, vals, sig))
        w.write_encoded("/est/plain", S.ESTIMATE, 2_000, estimate_payload(2_000, {"x": 3.0}))
        w.write_encoded("/est/can/vdps", S.RAW_CAN, 1_000, json_payload("/est/can/vdps", S.RAW_CAN, 1_000, doc),
                        channel_metadata={"bus": "vdps"})
        for bad, exc in (((("/est/x", S.ESTIMATE, 1, "text")), TypeError), ((("/est/x", "no.Such", 1, b"{}")), KeyError),
                         ((("no topic", S.ESTIMATE, 1, b"{}")), ValueError), ((("/est/x", S.ESTIMATE, -5, b"{}")), ValueError)):
            with pytest.raises(exc):
                w.write_encoded(*bad)
    a, b = _mcap_messages(tmp_path / "direct.mcap"), _mcap_messages(tmp_path / "encoded.mcap")
    assert a == b and len(a) == 3

    def data(path):
        with open(path, "rb") as f:
            return [(ch.metadata, m.data) for _, ch, m in make_reader(f).iter_messages(log_time_order=True)]

    assert data(tmp_path / "direct.mcap") == data(tmp_path / "encoded.mcap")  # byte for byte
    assert json.loads(estimate_payload(1_000, vals, sig))["values"]["b"] is None


def test_encoded_run_writes_what_write_encoded_writes(tmp_path):
    """write_encoded_run = write_encoded once per message (log and publish times, sequence numbers,
    time-order counts, statistics, channel metadata), with copied messages of the topic queued
    before it written first; a bad time anywhere in the run raises before anything is written."""
    ts = [5, 7, 6, 9, 9]  # one step back: counted
    payloads = [json_payload("/decoded/a/b", S.SAMPLE, t, Sample(t, "a", "b", {"x": t / 3}).to_json()) for t in ts]
    walls = [S.DEFAULT_SIM_EPOCH_NS + 2 * t for t in ts]
    walls[3] = 0  # none: the writer's rule (sim epoch + t_ns)
    md = {"source": "a", "kind": "b"}
    files, stats = [], []
    for run in (True, False):
        path = tmp_path / f"{run}.mcap"
        with RecordingWriter(path, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS) as w:
            w.write_encoded("/decoded/a/b", S.SAMPLE, 1, payloads[0], wall_time_ns=walls[0], channel_metadata=md)
            if run:
                w.write_encoded_run("/decoded/a/b", S.SAMPLE, ts, payloads, walls, md)
                with pytest.raises(ValueError):
                    w.write_encoded_run("/decoded/a/b", S.SAMPLE, [10, -1], payloads[:2], walls[:2], md)
                with pytest.raises(TypeError):
                    w.write_encoded_run("/decoded/a/b", S.SAMPLE, [10, 11], [payloads[0], "x"], walls[:2], md)
            else:
                for t, p, wt in zip(ts, payloads, walls):
                    w.write_encoded("/decoded/a/b", S.SAMPLE, t, p, wall_time_ns=wt, channel_metadata=md)
            stats.append((dict(w.stats.messages), dict(w.stats.time_backwards)))
        files.append(_mcap_messages(path))
    assert files[0] == files[1] and len(files[0]) == 6
    assert [m[2] - S.DEFAULT_SIM_EPOCH_NS for m in files[0]] == [10, 10, 14, 12, 9, 18]
    assert stats[0] == stats[1] == ({"/decoded/a/b": 6}, {"/decoded/a/b": 1})
    assert RecordingReader(tmp_path / "True.mcap").channel_metadata("/decoded/a/b") == md


def test_write_can_frames_in_the_uncommon_cases_writes_what_write_can_writes(tmp_path):
    """write_can_frames falls back to one message at a time (live log times, a mirror, times
    going back) and then writes the messages, statistics and time-order counts of write_can."""
    import numpy as np

    t = np.array([50, 40, 40, 60], np.int64)
    aid, dlc = np.array([1, 2, 3, 0x7FF]), np.array([8, 0, 3, 1])
    data = np.arange(32, dtype=np.uint8).reshape(4, 8)
    out = []
    for bulk in (True, False):
        for epoch in (EPOCH, None):
            buf, seen = io.BytesIO(), []
            w = RecordingWriter(buf, sim_epoch_ns=epoch)
            w.mirror = lambda *a: seen.append(a[:4])
            if bulk:
                w.write_can_frames("c", t, aid, dlc, data)
            else:
                for k in range(4):
                    w.write_can("c", int(t[k]), {"arbitration_id": int(aid[k]), "data": bytes(data[k, :dlc[k]])})
            stats = (dict(w.stats.messages), dict(w.stats.time_backwards))
            w.close()
            msgs = [m[:2] + m[3:] for m in _mcap_messages(buf.getvalue())]  # log time: live when no epoch
            out.append((epoch, msgs, seen, stats))
    assert out[:2] == out[2:]
    assert out[0][3] == ({"/raw/can/c": 4}, {"/raw/can/c": 2})
