#!/usr/bin/env python3
"""Time and memory of the workbench diagnosis against the drive's length: wall time, CPU time
and peak RSS of ``vdps_hil.workbench.diagnosis.diagnose`` (what ``vdps diagnose`` runs, with the
simulation error) per recording, each in a fresh process, per minute of drive, and the growth
per minute of drive between the shortest and the longest.

Usage:
  .venv/bin/python tools/bench_diagnose.py DRIVE.mcap [DRIVE.mcap ...] [--vehicle sedan-model]
                                           [--no-simulation] [--add NAME ...]

Each recording runs in its own child process (``--child``); the child reports its wall time
(imports included, as a user waits for ``vdps diagnose``), its CPU time (``getrusage``), its
peak resident set (``getrusage``), the stage timings the diagnosis records and the drive's
duration. Growth: (peak_long - peak_short) / (duration_long - duration_short) in MiB per
minute (and the same for CPU); the peak of a process that only imports the workbench is printed
first (the part that does not grow with the drive). Drives: ``vdps sim paper --duration 30
--seed 3 -o d30.mcap`` (or ``tools/make_long_drive.py``); measure on a quiet machine, or say
what ran beside it.

Latest (2026-12-05, after the streams went single precision and field by field; load 3-12):
peak RSS 379 / 503 / 694 / 1333 MiB for 2 / 10 / 20 / 60 min drives, 16.6 MiB per minute from 10
to 60 min, the hour in 770 CPU s (README, "Memory and speed").

Before that (2026-12-05, ``nice -n 5``, 2-core machine at load 0.8-1.2; paper drives seed 3 of 30 s /
2 / 5 / 10 min; branch diagmem (row budget, ``workbench.fit_budget``) with this venv, then main
c4b63d3 in a detached worktree run the same way, back to back): diagmem peak RSS 304 / 381 / 502 /
608 MiB, CPU 9.4 / 35.4 / 76.3 / 130.3 s (ranking 1.9 / 7.4 / 14.9 / 15.3 s: fixed beyond 150 s of
drive), 21 MiB and 10.8 CPU s per minute of drive from 5 to 10 min; main 304 / 382 /
1207 MiB, CPU 9.3 / 34.9 / 139.1 s (ranking 1.7 / 7.4 / 64.6 s), 200 MiB per minute from 30 s to
5 min. Commands: ``nice -n 5 .venv/bin/python tools/bench_diagnose.py d30.mcap d120.mcap d300.mcap
d600.mcap`` in each tree (main's with ``PYTHONPATH`` set to its tree, before this tool inserted it).
Imports alone 217 MiB. The 30 s and 2 min drives' JSON are identical (timings aside). Then
diagmem ``d600.mcap d1200.mcap`` (load 1.0-1.4): 607 / 911 MiB, CPU 120.5 / 238.9 s (ranking 14.3 /
16.2 s, decode and estimator 81 / 179 s): 30.4 MiB and 11.8 CPU s per minute of drive from 10 to
20 min (issue 19's 20 MiB per minute not met: what grows is outside the ranking).

Earlier (2026-12-04, ``nice -n 5``, 2-core machine at load 4-5 beside other work; paper
drives seed 3 of 30 / 120 / 300 s; main ba5e4e3 then branch diagfast bcf0349 in one run):
main peak RSS 367 / 556 / 1094 MiB, CPU 13.5 / 40.5 / 148 s; diagfast 328 / 406 / 1038 MiB,
CPU 10.4 / 43.2 / 154.8 s (wall 16.4 / 58.8 / 236.7 s); imports alone 255 MiB. Growth 158 MiB
per minute of drive, not linear: the 5-minute drive's ranking (138 s) dominates.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

# the tree this tool is in, not the one the venv was installed from (the editable install of another
# worktree would otherwise be measured: the before/after figures of 2026-12-05 were first both this tree's)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def child(path: str, vehicle: str, simulation: bool, add: list[str]) -> None:
    import resource
    import time

    w0 = time.perf_counter()
    from vdps_hil.model.params import load_vehicle
    from vdps_hil.workbench.diagnosis import diagnose

    d = None  # path "-": the imports alone (the part of the peak that does not grow with the drive)
    if path != "-":
        d = diagnose(path, load_vehicle(vehicle, "model"), with_simulation=simulation, add=tuple(add))
    ru = resource.getrusage(resource.RUSAGE_SELF)
    print(json.dumps({"path": path, "duration_s": d.table.duration_s if d else 0.0,
                      "wall_s": time.perf_counter() - w0, "cpu_s": ru.ru_utime + ru.ru_stime,
                      "peak_rss_mib": ru.ru_maxrss / 1024, "stages_s": dict(d.timings) if d else {},
                      "recommendation": d.ranking.recommendation if d else None}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("drives", nargs="+")
    ap.add_argument("--vehicle", default="sedan-model")
    ap.add_argument("--no-simulation", action="store_true", help="skip the simulation error (vdps diagnose --no-simulation)")
    ap.add_argument("--add", action="append", default=[])
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        child(a.drives[0], a.vehicle, not a.no_simulation, a.add)
        return 0
    rows = []
    for path in ["-"] + a.drives:
        cmd = [sys.executable, __file__, path, "--child", "--vehicle", a.vehicle]
        cmd += ["--no-simulation"] if a.no_simulation else []
        for n in a.add:
            cmd += ["--add", n]
        r = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1])
        if path == "-":
            print(f"imports only: wall {r['wall_s']:.1f} s, peak RSS {r['peak_rss_mib']:.0f} MiB", flush=True)
            continue
        rows.append(r)
        per_min = 60.0 / max(r["duration_s"], 1e-9)
        stages = ", ".join(f"{k} {v:.1f}" for k, v in r["stages_s"].items())
        print(f"{path}: {r['duration_s']:.0f} s of drive: wall {r['wall_s']:.1f} s, CPU {r['cpu_s']:.1f} s "
              f"({r['cpu_s'] * per_min:.1f} s per minute of drive), peak RSS {r['peak_rss_mib']:.0f} MiB; "
              f"stages [s] {stages}; recommendation {r['recommendation']}", flush=True)
    if len(rows) >= 2:
        rows.sort(key=lambda r: r["duration_s"])
        lo, hi = rows[0], rows[-1]
        span = (hi["duration_s"] - lo["duration_s"]) / 60.0
        if span > 0:
            print(f"growth {(hi['peak_rss_mib'] - lo['peak_rss_mib']) / span:.1f} MiB and "
                  f"{(hi['cpu_s'] - lo['cpu_s']) / span:.1f} CPU s per minute of drive "
                  f"({lo['duration_s']:.0f} s -> {hi['duration_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
