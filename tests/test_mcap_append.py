"""MessageAppender: the recording writer's own message records give the bytes of the mcap
library's add_message, checked with the mcap library's own readers (not ours)."""

from mcap.reader import make_reader

from vdps_hil.record import schemas as S
from vdps_hil.record.writer import RecordingWriter

from copy_messages import EPOCH, copy_messages


def test_fast_message_path_writes_the_same_file_as_the_mcap_library(tmp_path):
    """The writer's own add_message (``_fast_add_message``) and mcap's Writer.add_message give
    byte-identical files: same records, statistics, message indexes and chunk boundaries (small
    chunks so that many close; log times not monotonic across topics)."""
    import random

    rng = random.Random(7)
    msgs = []
    for k in range(3000):
        t = 1_000_000 * k + rng.randrange(-3_000_000, 3_000_000) + 10_000_000
        msgs.append((rng.choice(("a", "b", "c")), t, rng.randbytes(rng.randrange(0, 40))))
    files = []
    for fast in (True, False):
        p = tmp_path / f"{fast}.mcap"
        w = RecordingWriter(p, chunk_size=4096, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS)
        if not fast:
            w._add_message = w._mcap.add_message
        else:
            assert w._add_message != w._mcap.add_message  # the fast path is in use
        for dev, t, data in msgs:
            w.write_serial(dev, t, data)
        w.write_estimate("x", 5, {"v": 1.0})
        w.close()
        files.append(p.read_bytes())
    assert files[0] == files[1]
    with open(tmp_path / "True.mcap", "rb") as f:
        n = sum(1 for _ in make_reader(f).iter_messages())
    assert n == len(msgs) + 1


def test_copy_runs_write_the_same_file_as_one_library_call_per_message(tmp_path):
    """MessageAppender.add_run (one pack and write per run, cut at chunk boundaries) gives the
    bytes of the mcap library's add_message once per message: same records, statistics,
    message indexes and chunk boundaries."""
    msgs = copy_messages(5, 3000)

    def write(w, runs):
        copy = w.copier(lambda topic: (S.RAW_SERIAL, {}))
        for topic, t, log, data in msgs:
            copy((topic, t, log, 7, data))

    fast, library = _both_ways(tmp_path, 1500, write)
    assert fast == library


def _both_ways(tmp_path, chunk_size: int, write) -> list[bytes]:
    """The files ``write(writer, fast)`` gives with the writer's appender (fast True) and with
    the mcap library's add_message for each message (fast False)."""
    files = []
    for fast in (True, False):
        p = tmp_path / f"{fast}.mcap"
        w = RecordingWriter(p, chunk_size=chunk_size, sim_epoch_ns=EPOCH)
        if not fast:
            w._appender, w._add_message = None, w._mcap.add_message
        write(w, fast)
        w.close()
        files.append(p.read_bytes())
    return files


def test_can_frame_runs_write_the_same_file_as_one_library_call_per_message(tmp_path):
    """RecordingWriter.write_can_frames (records built with numpy, MessageAppender.add_rows, cut
    at chunk boundaries) gives the bytes of write_can once per frame through the mcap library's
    add_message: same records, statistics, message indexes and chunk boundaries (small chunks;
    runs of 1..400 frames between serial messages)."""
    import numpy as np

    rng = np.random.default_rng(11)
    blocks, t0 = [], 0
    for _ in range(40):
        n = int(rng.integers(1, 400))
        t = t0 + np.cumsum(rng.integers(0, 2_000_000, n))
        t0 = int(t[-1])
        blocks.append((t, rng.integers(0, 0x800, n), rng.integers(0, 9, n), rng.integers(0, 256, (n, 8), dtype=np.uint8)))

    def write(w, bulk):
        for t, aid, dlc, data in blocks:
            if bulk:
                w.write_can_frames("vdps", t, aid, dlc, data)
            else:
                for k in range(len(t)):
                    w.write_can("vdps", int(t[k]), {"arbitration_id": int(aid[k]), "dlc": int(dlc[k]),
                                                    "data": bytes(data[k, :dlc[k]])})
            w.write_serial("imu", t0, b"x")

    fast, library = _both_ways(tmp_path, 3000, write)
    assert fast == library
