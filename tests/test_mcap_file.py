"""McapIndex: a file without a valid summary (cut off, still being written, damaged) is scanned
and read as far as it goes; corrupt chunks are skipped (through RecordingReader)."""

import io

from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.record import schemas as S
from vdps_hil.record.reader import RecordingError, RecordingReader
from vdps_hil.record.writer import RecordingWriter

EPOCH = S.DEFAULT_SIM_EPOCH_NS


def test_truncated_files_give_the_complete_records_before_the_cut(tmp_path):
    full = io.BytesIO()
    with RecordingWriter(full, sim_epoch_ns=EPOCH, chunk_size=512) as w:
        for i in range(300):
            w.write_can("a", 10 * i, {"arbitration_id": i % 2048, "data": bytes([i % 256])})
            if i % 3 == 0:
                w.write_serial("gnss", 10 * i + 1, b"x" * (i % 7))
    data = full.getvalue()
    expected = list(RecordingReader(io.BytesIO(data)).iter_messages())
    n_before = 0
    for cut in list(range(0, 64)) + list(range(64, len(data), 97)) + [len(data) - 1]:
        try:
            r = RecordingReader(io.BytesIO(data[:cut]))
        except RecordingError as e:
            assert cut < 8 and "not an MCAP" in str(e)
            continue
        assert r.truncated and r.problems
        got = list(r.iter_messages())
        assert got == [m for m in expected if m in got]  # a subsequence, in order
        for topic in ("/raw/can/a", "/raw/serial/gnss"):  # each topic: a prefix of its stream
            mine = [m for m in got if m[0] == topic]
            assert mine == [m for m in expected if m[0] == topic][:len(mine)]
        assert len(got) >= n_before  # a longer file never yields less
        n_before = len(got)
    assert n_before > 0.9 * len(expected)


@settings(max_examples=40, deadline=None)
@given(flips=st.lists(st.tuples(st.integers(0, 10**9), st.integers(1, 255)), min_size=1,
                      max_size=6))
def test_corrupted_bytes_are_survived(flips):
    buf = io.BytesIO()
    with RecordingWriter(buf, sim_epoch_ns=EPOCH, chunk_size=256) as w:
        for i in range(120):
            w.write_serial("imu", i, bytes([i]) * 5)
    data = bytearray(buf.getvalue())
    for pos, x in flips:
        data[8 + pos % (len(data) - 8)] ^= x
    r = RecordingReader(io.BytesIO(bytes(data)))  # magic intact: never a RecordingError
    got = [(t, raw) for _, t, raw in r.iter_raw_serial()]
    # chunk CRCs: whatever is yielded is an original message, each at most once
    assert all(0 <= t < 120 and raw == bytes([t]) * 5 for t, raw in got)
    assert len({t for t, _ in got}) == len(got)
    if len(got) < 120:
        assert r.problems


def test_reading_a_file_still_being_written(tmp_path):
    path = tmp_path / "open.mcap"
    w = RecordingWriter(path, sim_epoch_ns=EPOCH, chunk_size=1024)
    for i in range(500):
        w.write_can("a", i, {"arbitration_id": 1, "data": b"\x00" * 8})
    r = RecordingReader(path)  # no footer yet: scanned
    n = sum(1 for _ in r.iter_raw_can())
    assert r.truncated and 400 < n < 500
    w.close()
    assert sum(1 for _ in RecordingReader(path).iter_raw_can()) == 500


def test_damaged_summary_falls_back_to_scanning_the_chunks():
    buf = io.BytesIO()
    with RecordingWriter(buf, sim_epoch_ns=EPOCH, chunk_size=512) as w:
        for i in range(100):
            w.write_serial("imu", i, b"abc")
        w.flush()
        summary_start = buf.tell() + 13  # after DataEnd (9 + 4 bytes): the summary section
    data = bytearray(buf.getvalue())
    topic_at = data.index(b"/raw/serial/imu", summary_start)
    data[topic_at + 12:topic_at + 15] = b"gps"  # summary now names another topic
    r = RecordingReader(io.BytesIO(bytes(data)))
    assert r.truncated and any("CRC" in p for p in r.problems)
    assert r.topics() == {"/raw/serial/imu": (S.RAW_SERIAL, 100)}
    assert [t for _, t, _ in r.iter_raw_serial()] == list(range(100))
