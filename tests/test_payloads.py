"""Message payloads encoded apart from the writer: the direct estimate encoding equals
json.dumps of the cleaned document, and write_estimate writes what write_json writes."""

import io
import json
import math

from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from vdps_hil.record import schemas as S
from vdps_hil.record.writer import RecordingWriter


def test_write_estimate_payload_equals_the_generic_json_path(tmp_path):
    """write_estimate's single cleaning pass writes the bytes write_json(estimate_doc) writes,
    for floats, NaN/inf, numpy scalars, ints and bools."""
    import numpy as np

    vals = {"a": 0.1, "b": math.nan, "c": -math.inf, "d": np.float64(2.5), "e": 3, "f": True, "g": -0.0}
    sig = {"a": 1e-300, "b": np.float32(0.5), "c": math.inf}
    payloads = []
    for fast in (True, False):
        buf = io.BytesIO()
        with RecordingWriter(buf, sim_epoch_ns=S.DEFAULT_SIM_EPOCH_NS) as w:
            if fast:
                w.write_estimate("/est/x", 9, vals, sig)
            else:
                w.write_json("/est/x", S.ESTIMATE, 9, S.estimate_doc(9, vals, sig))
        buf.seek(0)
        payloads.append([m.data for _, _, m in make_reader(buf).iter_messages()])
    assert payloads[0] == payloads[1] and len(payloads[0]) == 1


@settings(max_examples=300, deadline=None)
@given(vals=st.dictionaries(st.text(max_size=8), st.floats(allow_nan=True, allow_infinity=True), max_size=8),
       sig=st.none() | st.dictionaries(st.sampled_from(["a", 'b"', "é", "x_g_m"]), st.floats(), max_size=4),
       t_ns=st.integers(0, 2**62))
def test_direct_estimate_encoding_equals_json_dumps(vals, sig, t_ns):
    """The direct encoding of float-only estimates is byte-identical to json.dumps of the
    cleaned document (any keys, NaN/inf, -0.0, subnormals)."""
    from vdps_hil.record.payloads import _clean_flat, _float_object

    doc = {"t_ns": t_ns, "values": _clean_flat(vals)}
    if sig is not None:
        doc["sigmas"] = _clean_flat(sig)
    ref = json.dumps(doc, separators=(",", ":"), allow_nan=False)
    v, s = _float_object(vals), "" if sig is None else _float_object(sig)
    got = f'{{"t_ns":{t_ns},"values":{v}' + (f',"sigmas":{s}}}' if sig is not None else "}")
    assert got == ref


@settings(max_examples=200, deadline=None)
@given(t=st.integers(0, S.MAX_TIME_NS), w=st.integers(0, S.MAX_TIME_NS), valid=st.sampled_from([True, False, 1]),
       name=st.text(min_size=1, max_size=6),
       fields=st.dictionaries(st.text(max_size=5), st.floats(allow_nan=True, allow_infinity=True)
                              | st.integers(-5, 5) | st.booleans(), max_size=5))
def test_sample_payload_equals_json_dumps_of_to_json(t, w, valid, name, fields):
    """The direct encoding of a bus sample (floats written as float.__repr__, non-finite -> null,
    any other value or a non-bool ``valid`` through json.dumps) = json.dumps(Sample.to_json())."""
    from vdps_hil.bus.samples import Sample
    from vdps_hil.record.payloads import sample_payload

    s = Sample(t, name, name[::-1], fields, w, valid)
    assert sample_payload(s) == json.dumps(s.to_json(), separators=(",", ":"), allow_nan=False).encode()


def test_raw_can_rows_equal_write_can_payloads():
    """raw_can_rows (numpy, per (ID, DLC, digits of t_ns) group) gives, row by row, the bytes
    write_can writes for each frame (raw_can_payload of a python-can Message), zero padding
    after them; times from 0 to the int64 limit (every number of digits)."""
    import can
    import numpy as np

    from vdps_hil.record.payloads import raw_can_payload, raw_can_rows

    rng = np.random.default_rng(3)
    t = np.concatenate([np.array([0, 1, 9, 10, 99, 100, 10**18 - 1, 10**18, S.MAX_TIME_NS], np.int64),
                        (10 ** rng.uniform(0, 18.9, 3000)).astype(np.int64)])
    aid, dlc = rng.integers(0, 0x800, t.size), rng.integers(0, 9, t.size)
    data = rng.integers(0, 256, (t.size, 8), dtype=np.uint8)
    rows, lengths = raw_can_rows(t, aid, dlc, data)
    for k in range(t.size):
        msg = can.Message(arbitration_id=int(aid[k]), is_extended_id=False, dlc=int(dlc[k]),
                          data=bytes(data[k, :dlc[k]]))
        assert rows[k, :lengths[k]].tobytes() == raw_can_payload(int(t[k]), msg)
        assert not rows[k, lengths[k]:].any()


def test_raw_can_rows_refuse_frames_write_can_refuses():
    import numpy as np
    import pytest

    from vdps_hil.record.payloads import raw_can_rows

    d = np.zeros((1, 8), np.uint8)
    for t, aid, dlc in ((-1, 1, 8), (0, 0x800, 8), (0, -1, 8), (0, 1, 9), (0, 1, -1)):
        with pytest.raises(ValueError):
            raw_can_rows(np.array([t]), np.array([aid]), np.array([dlc]), d)
    assert raw_can_rows(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros((0, 8), np.uint8))[1].size == 0


@settings(max_examples=300, deadline=None)
@given(vals=st.dictionaries(st.text(max_size=6), st.floats(allow_nan=True, allow_infinity=True) | st.integers()
                            | st.booleans() | st.none() | st.text(max_size=3) | st.lists(st.floats(), max_size=2),
                            max_size=8),
       t_ns=st.integers(0, S.MAX_TIME_NS))
def test_truth_payload_equals_the_generic_json_path(vals, t_ns):
    """truth_payload (json.dumps of the flat snapshot as it is) = json_payload of truth_doc for
    any flat or nested values, NaN/inf included."""
    from vdps_hil.record.payloads import json_payload, truth_payload

    assert truth_payload("/truth/state", t_ns, vals) == json_payload("/truth/state", S.TRUTH, t_ns,
                                                                     S.truth_doc(t_ns, vals))


@settings(max_examples=300, deadline=None)
@given(vals=st.dictionaries(st.text(max_size=6), st.floats(allow_nan=False, allow_infinity=False)
                            | st.integers(-2**70, 2**70), max_size=12)
       | st.dictionaries(st.text(max_size=6), st.floats(), max_size=4),
       t_ns=st.integers(0, S.MAX_TIME_NS))
def test_direct_truth_encoding_equals_the_generic_json_path(vals, t_ns):
    """The direct encoding of flat snapshots (finite floats and ints written as repr after cached
    key heads; NaN/inf, huge ints through the general path) = json_payload of truth_doc, for any
    keys (quotes, non-ASCII), twice in a row (the cache of key heads)."""
    from vdps_hil.record.payloads import json_payload, truth_payload

    ref = json_payload("/truth/state", S.TRUTH, t_ns, S.truth_doc(t_ns, vals))
    assert truth_payload("/truth/state", t_ns, vals) == ref == truth_payload("/truth/state", t_ns, vals)
