"""The recorded input order (vdps_hil.record.input_order): what is noted is read back, sample
for sample, in the noted order, whatever the order within the file's time stamps; more than
256 topics; settings; a damaged record is an error, not a wrong order."""

import pytest

from vdps_hil.bus.samples import Sample
from vdps_hil.record.input_order import INPUT_ORDER_METADATA, InputOrder, read_input_order
from vdps_hil.record.reader import RecordingReader
from vdps_hil.record.writer import RecordingWriter


def _write(path, samples, settings=None, noted=None):
    order = InputOrder()
    with RecordingWriter(str(path)) as w:
        for s in samples:
            w.write_sample(s)
        for s in (samples if noted is None else noted):
            order.note(s)
        w.add_metadata(INPUT_ORDER_METADATA, order.metadata(**(settings or {})))


def test_order_is_read_back_exactly(tmp_path):
    # arrival order with time stamps going back across kinds (a measurement before the IMU)
    samples = [Sample(t, "can.vdps" if k == "steer" else "imu", k, {"x": float(i)})
               for i, (t, k) in enumerate([(5, "imu"), (3, "steer"), (6, "imu"), (4, "steer"), (7, "imu")])]
    _write(tmp_path / "a.mcap", samples, {"system": {"vehicle": "v", "rates": {"imu": 1000.0}}})
    with RecordingReader(str(tmp_path / "a.mcap")) as r:
        got, settings = read_input_order(r)
    assert [(s.t_ns, s.kind, s.fields["x"]) for s in got] == [(s.t_ns, s.kind, s.fields["x"]) for s in samples]
    assert settings == {"system": {"vehicle": "v", "rates": {"imu": 1000.0}}}


def test_more_than_256_topics_take_two_bytes(tmp_path):
    samples = [Sample(i, f"src{i % 300}", "imu", {"x": float(i)}) for i in range(700)]
    _write(tmp_path / "b.mcap", samples)
    with RecordingReader(str(tmp_path / "b.mcap")) as r:
        assert r.metadata()[INPUT_ORDER_METADATA]["index_bytes"] == "2"
        got, _ = read_input_order(r)
    assert [s.fields["x"] for s in got] == [float(i) for i in range(700)]


def test_more_noted_than_recorded_is_an_error(tmp_path):
    samples = [Sample(i, "imu", "imu", {"x": float(i)}) for i in range(3)]
    _write(tmp_path / "c.mcap", samples[:2], noted=samples)
    with RecordingReader(str(tmp_path / "c.mcap")) as r, pytest.raises(IndexError):
        read_input_order(r)
