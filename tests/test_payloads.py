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
