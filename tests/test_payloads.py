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
