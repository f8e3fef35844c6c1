"""Tests of vdps_hil.record.streams: the per-source decoders of the /raw/ records."""

from __future__ import annotations

import io
import json

from hypothesis import given, settings
from hypothesis import strategies as st

from vdps_hil.record import schemas as S
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.writer import RecordingWriter


class _Recorder:
    """Stands in for a CAN decoder: keeps what it is asked to decode."""

    def __init__(self):
        self.calls = []
        self.counters = {}

    def decode(self, t_ns, arbitration_id, data, is_extended_id=False, **flags):
        self.calls.append((t_ns, arbitration_id, bytes(data), bool(is_extended_id), flags))
        return []


@settings(max_examples=80, deadline=None)
@given(ext=st.booleans(), ident=st.integers(0, 0x1FFFFFFF), data=st.binary(max_size=8),
       remote=st.booleans(), error=st.booleans())
def test_fast_raw_can_path_reads_what_json_reads(ext, ident, data, remote, error):
    """The regex fast path over the writer's raw CAN documents gives the decoder exactly what the
    JSON path gives it, for any classic frame (remote/error frames take the JSON path; a remote
    frame reaches the decoder flagged, which counts it; an error frame is malformed)."""
    from vdps_hil.record.streams import CanStream

    ident = ident if ext else ident & 0x7FF
    doc = S.raw_can_doc(5, ident, data, is_extended_id=ext, is_remote_frame=remote, is_error_frame=error)
    buf = io.BytesIO()
    with RecordingWriter(buf) as w:
        w.write_can("vdps", 5, doc)
    buf.seek(0)
    (rec,) = list(RecordingReader(buf).iter_records())
    fast, slow = CanStream("vdps", _Recorder(), {}), CanStream("vdps", _Recorder(), {})
    fast.feed_raw(rec.t_ns, rec.data)
    slow.feed(rec.t_ns, json.loads(rec.data))
    assert fast.dec.calls == slow.dec.calls and fast.malformed == slow.malformed
    assert (fast.dec.calls == []) == error
    assert all(c[4] == ({"is_remote_frame": True} if remote else {}) for c in fast.dec.calls)


def test_feed_many_gives_what_feed_raw_gives_on_odd_documents():
    """The bulk path of a CAN stream (``feed_many``) against ``feed_raw`` record by record on
    documents that leave the regex fast path: other key orders, odd hex, JSON that is no
    frame, error/remote/FD frames, string IDs, garbage bytes; the same samples and counters."""
    from vdps_hil.codecs.can_decode import VdpsCanDecoder
    from vdps_hil.codecs.can_encode import encode_steer
    from vdps_hil.record.streams import CanStream

    def doc(ctr, sort=False, **kw):
        d = S.raw_can_doc(5, 0x130, bytes(encode_steer(0.1, ctr).data))
        d.update(kw)
        return json.dumps(d, sort_keys=sort, separators=(",", ":")).encode()

    recs = []
    for k in range(60):
        recs.append((k * 10, doc(k)))  # the writer's form: the fast path
        odd = [doc(k, sort=True), doc(k, data_hex="abc"), b"[1, 2]", b"\xff\xfe", doc(k, is_error_frame=True),
               doc(k, is_remote_frame=True), doc(k, is_fd=True), doc(k, arbitration_id="304"), b'{"x": 1}',
               doc(k, arbitration_id=None), doc(k, data_hex=None)]
        recs.append((k * 10 + 5, odd[k % len(odd)]))
    a, b = CanStream("vdps", VdpsCanDecoder(), {}), CanStream("vdps", VdpsCanDecoder(), {})
    ref = [[s.to_json() for s in a.feed_raw(t, d)] for t, d in recs]
    ts, datas = [t for t, _ in recs], [d for _, d in recs]
    got = [[] if s is None else [s.to_json()] for s in b.feed_many(ts[:37], datas[:37]) + b.feed_many(ts[37:], datas[37:])]
    assert got == ref and a.counters() == b.counters() and a.rejected() == b.rejected()
    assert a.counters()["raw_malformed"] > 0 and a.counters()["bus"]["fd_frame"] > 0
