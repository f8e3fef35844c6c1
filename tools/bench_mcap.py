"""Benchmark: MCAP recording write and read throughput for raw CAN frames.

Writes N raw CAN frames (default 1e5; python-can messages, 8 data bytes, a handful of
chassis IDs at 1 kHz each, as the bench produces them) with RecordingWriter, then reads them
back three ways: RecordingReader.iter_records (undecoded), iter_messages (JSON decoded),
iter_raw_can (python-can Message objects), and mcap's own reader for comparison.
Prints messages/s and MB/s (file bytes and JSON payload bytes per second).

    .venv/bin/python tools/bench_mcap.py [--n 100000] [--keep FILE] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import can
import numpy as np

from vdps_hil.record import DEFAULT_SIM_EPOCH_NS, RecordingReader, RecordingWriter


def _frames(n: int, seed: int = 0) -> list[tuple[int, can.Message]]:
    rng = np.random.default_rng(seed)
    ids = [0x100, 0x101, 0x110, 0x111, 0x120, 0x130, 0x140, 0x150]
    payload = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    out = []
    for i in range(n):
        t_ns = (i // len(ids)) * 1_000_000 + (i % len(ids)) * 100_000  # 1 kHz per ID
        out.append((t_ns, can.Message(arbitration_id=ids[i % len(ids)], is_extended_id=False,
                                      data=payload[i].tobytes())))
    return out


def _rate(n: int, nbytes: int, dt: float) -> dict:
    return {"messages_per_s": n / dt, "mb_per_s": nbytes / dt / 1e6, "seconds": dt}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="number of CAN frames")
    ap.add_argument("--keep", metavar="FILE", help="write the recording here and keep it")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    args = ap.parse_args(argv)

    frames = _frames(args.n)
    path = args.keep or os.path.join(tempfile.mkdtemp(prefix="vdps-bench-"), "bench.mcap")
    t0 = time.perf_counter()
    with RecordingWriter(path, sim_epoch_ns=DEFAULT_SIM_EPOCH_NS) as w:
        for t_ns, msg in frames:
            w.write_can("chassis", t_ns, msg)
    t_write = time.perf_counter() - t0
    size = os.path.getsize(path)

    results = {"n": args.n, "file_bytes": size}
    r = RecordingReader(path)
    t0 = time.perf_counter()
    payload = sum(len(rec.data) for rec in r.iter_records())
    t_records = time.perf_counter() - t0
    results["payload_bytes"] = payload
    results["write"] = _rate(args.n, size, t_write)
    results["write"]["payload_mb_per_s"] = payload / t_write / 1e6

    def timed(fn):
        t0 = time.perf_counter()
        n = sum(1 for _ in fn())
        dt = time.perf_counter() - t0
        assert n == args.n, (n, args.n)
        return {**_rate(n, size, dt), "payload_mb_per_s": payload / dt / 1e6}

    results["read_records"] = {**_rate(args.n, size, t_records),
                               "payload_mb_per_s": payload / t_records / 1e6}
    results["read_messages"] = timed(lambda: RecordingReader(path).iter_messages())
    results["read_raw_can"] = timed(lambda: RecordingReader(path).iter_raw_can())

    from mcap.reader import make_reader

    def mcap_own():
        with open(path, "rb") as f:
            for _, _, m in make_reader(f).iter_messages(log_time_order=True):
                yield json.loads(m.data)
    results["mcap_reader_json"] = timed(mcap_own)

    print(f"{args.n} raw CAN frames, file {size / 1e6:.2f} MB "
          f"({payload / 1e6:.2f} MB JSON, ratio {payload / size:.1f}x), zstd chunks of 64 KiB")
    for key in ("write", "read_records", "read_messages", "read_raw_can", "mcap_reader_json"):
        v = results[key]
        print(f"  {key:17s} {v['messages_per_s']:>10,.0f} msg/s  {v['mb_per_s']:6.2f} MB/s file"
              f"  {v['payload_mb_per_s']:6.2f} MB/s JSON  ({v['seconds']:.2f} s)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    if not args.keep:
        os.remove(path)
        os.rmdir(os.path.dirname(path))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
