#!/usr/bin/env python3
"""Memory of the workbench diagnosis against the drive's length: peak RSS of
``vdps_hil.workbench.diagnosis.diagnose`` (what ``vdps diagnose`` runs) per recording, each in
a fresh process, and the growth per minute of drive between the shortest and the longest.

Usage:
  .venv/bin/python tools/bench_diagnose.py DRIVE.mcap [DRIVE.mcap ...] [--vehicle sedan-model]
                                           [--simulation] [--add NAME ...]

Each recording runs in its own child process (``--child``); the child reports its CPU time
(``time.process_time``), its peak resident set (``getrusage``) and the drive's duration. The
growth is (peak_long - peak_short) / (duration_long - duration_short) in MiB per minute: the
diagnosis streams the recording and stores the smooth velocity nuisance columns as bands, so
it must stay roughly constant as drives get longer (it grew with the drive's length before).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys


def child(path: str, vehicle: str, simulation: bool, add: list[str]) -> None:
    import resource
    import time

    from vdps_hil.model.params import load_vehicle
    from vdps_hil.workbench.diagnosis import diagnose

    c0 = time.process_time()
    d = diagnose(path, load_vehicle(vehicle, "model"), with_simulation=simulation, add=tuple(add))
    print(json.dumps({"path": path, "duration_s": d.table.duration_s, "cpu_s": time.process_time() - c0,
                      "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "recommendation": d.ranking.recommendation}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("drives", nargs="+")
    ap.add_argument("--vehicle", default="sedan-model")
    ap.add_argument("--simulation", action="store_true", help="also the simulation error (slow)")
    ap.add_argument("--add", action="append", default=[])
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        child(a.drives[0], a.vehicle, a.simulation, a.add)
        return 0
    rows = []
    for path in a.drives:
        cmd = [sys.executable, __file__, path, "--child", "--vehicle", a.vehicle]
        cmd += ["--simulation"] if a.simulation else []
        for n in a.add:
            cmd += ["--add", n]
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        r = json.loads(out.strip().splitlines()[-1])
        rows.append(r)
        print(f"{path}: {r['duration_s']:.0f} s of drive, CPU {r['cpu_s']:.0f} s, peak RSS {r['peak_rss_mib']:.0f} MiB, "
              f"recommendation {r['recommendation']}", flush=True)
    if len(rows) >= 2:
        rows.sort(key=lambda r: r["duration_s"])
        lo, hi = rows[0], rows[-1]
        span = (hi["duration_s"] - lo["duration_s"]) / 60.0
        if span > 0:
            print(f"growth {(hi['peak_rss_mib'] - lo['peak_rss_mib']) / span:.0f} MiB per minute of drive "
                  f"({lo['duration_s']:.0f} s -> {hi['duration_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
