#!/usr/bin/env python3
"""Decode cost per chassis frame, layout 1 (dbc/vdps_v1.dbc) vs layout 2 (dbc/vdps.dbc, E2E CRC),
side by side in one run: 1 s of Table 1 traffic with the suspension at 1 kHz, best of 5.

    .venv/bin/python tools/bench_can_layout.py
"""
import time
from vdps_hil.codecs.can_dbc import LEGACY_DBC_PATHS, load_dbc
from vdps_hil.codecs.can_decode import VdpsCanDecoder
from vdps_hil.codecs.can_encode import encode_fields

def frames(dbc):
    out = []
    for k in range(1000):
        for name, spec in dbc.messages.items():
            if not spec.is_sensor or (spec.cycle_time_ms == 10 and k % 10):
                continue
            m = encode_fields(name, {f: 0.5 for f in spec.field_names}, k, dbc=dbc)
            out.append((k * 1_000_000, m.arbitration_id, bytes(m.data)))
    return out

res = {}
for label, path in (("layout1", LEGACY_DBC_PATHS[0]), ("layout2", None)):
    fr = frames(load_dbc(path))
    best = 1e9
    for _ in range(5):
        dec = VdpsCanDecoder(path)
        t0 = time.perf_counter()
        for t, a, d in fr:
            dec.decode_frame(t, a, d, False)
        best = min(best, time.perf_counter() - t0)
    res[label] = best / len(fr) * 1e6
    print(f"{label}: {len(fr)} frames per simulated second, {res[label]:.2f} us per frame")
print(f"ratio layout2/layout1: {res['layout2'] / res['layout1']:.2f}")
