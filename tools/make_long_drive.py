#!/usr/bin/env python3
"""Write a long simulated drive at the Table 1 sensor rates (for the batch memory figure; not
run in CI).

Usage: .venv/bin/python tools/make_long_drive.py [-o long-drive.mcap] [--duration 3600]
       [--scenario paper] [--profile table1-susp1k] [--seed 0]

Default: one hour of the paper's scenario (25 m/s, 1 Hz sine steering and torques) with the
project's default sensor profile ``table1-susp1k`` (Table 1: GNSS 5 Hz, IMU and tachometers
1 kHz, with the suspension at 1 kHz instead of the printed 1 Hz; the heavier of the two, so
the memory figure is an upper bound; ``--profile table1`` for the rates as printed). The drive
is written block by block (``sim.drive``), so this tool itself needs little memory; it prints
the file size, message counts and the time it took.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vdps_hil.sim.drive import Drive  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", default="long-drive.mcap")
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated seconds")
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--profile", default="table1-susp1k")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    t0 = time.perf_counter()
    s = Drive(args.scenario, profile=args.profile, seed=args.seed, duration_s=args.duration).run(args.output)
    wall = time.perf_counter() - t0
    size = os.path.getsize(args.output)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"{args.output}: {s.duration_s:.0f} s of '{args.scenario}' with profile {args.profile}, "
          f"seed {args.seed}; {size / 2**20:.0f} MiB, {sum(s.messages.values())} messages "
          f"in {wall:.0f} s ({s.duration_s / wall:.1f}x real time), writer peak RSS {peak:.0f} MiB")
    for topic, n in sorted(s.messages.items()):
        print(f"  {topic:<20} {n:>10}  ({n / s.duration_s:.0f}/s)")


if __name__ == "__main__":
    main()
